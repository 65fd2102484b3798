// The cutsim binary as a user runs it: errors with file:line:col, exit
// codes, no output files on failure, and reproducible results.
#include <sys/mman.h>
#include <sys/prctl.h>
#include <sys/wait.h>

#include <cctype>
#include <cstdint>
#include <cstdlib>
#include <fstream>
#include <cstring>
#include <unistd.h>
#include <nlohmann/json.hpp>

#include "helpers.h"
#include "cutsim/core/huge_pages.h"

namespace cutsim::test {

int run_cli(const std::string& args, std::string* out, std::string* err) {
  return run_cli_raw(std::string(CUTSIM_BIN) + " " + args, out, err);
}

int run_cli_raw(const std::string& command, std::string* out, std::string* err) {
  char tmpl[] = "/tmp/cutsim-cli-XXXXXX";
  const std::string cap = ::mkdtemp(tmpl);
  const std::string o = cap + "/stdout", e = cap + "/stderr";
  const std::string cmd = command + " >" + o + " 2>" + e + " </dev/null";
  const int status = std::system(cmd.c_str());
  if (out) *out = slurp(o);
  if (err) *err = slurp(e);
  std::error_code ec;
  std::filesystem::remove_all(cap, ec);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

namespace {

namespace fs = std::filesystem;

const char* kGood = "G21 G90\nG0 X0 Y0 Z1\nG1 Z-0.1 F100\nG1 X1\nG0 Z1\nM30\n";

struct Case {
  std::string program;     // text of prog.nc
  std::string extra_args;  // appended after the program
  int exit_code;
  std::string location;    // expected "file:line:col" suffix, or ""
  std::string message;     // a part of the message
};

void expect_error(const Case& c) {
  TempDir dir;
  const std::string prog = dir.write("prog.nc", c.program);
  const std::string outdir = dir.file("out");
  std::string out, err;
  const int code = run_cli("run " + prog + " --stock-box -2,-2,-1,3,2,0 --voxel 0.02 -o " + outdir + " " + c.extra_args,
                           &out, &err);
  EXPECT_EQ(code, c.exit_code) << err;
  if (!c.location.empty()) {
    EXPECT_NE(err.find(c.location + ": error: "), std::string::npos) << err;
  }
  EXPECT_NE(err.find(c.message), std::string::npos) << err;
  EXPECT_FALSE(fs::exists(outdir + "/prog.glb"));
  EXPECT_FALSE(fs::exists(outdir + "/prog.report.json"));
  EXPECT_FALSE(fs::exists(outdir)) << "the output directory the run made is removed again";
}

TEST(Cli, MalformedWordGivesLineColumnAndCaret) {
  TempDir dir;
  expect_error({"G0 X0 Y0 Z1\nG1 X1.2.3 F10\n", "", 65, "prog.nc:2:8", "second decimal point"});
  std::string err;
  const auto prog = dir.write("p.nc", "G0 X0\nG1 X1.2.3 F10\n");
  EXPECT_EQ(run_cli("check " + prog, nullptr, &err), 65);
  EXPECT_NE(err.find("\n  G1 X1.2.3 F10\n         ^"), std::string::npos) << err;
}

TEST(Cli, UnknownGCodeIsADataError) {
  expect_error({"G0 X0 Y0 Z1\nG1 X1 F10\nG7.5 X2\n", "", 65, "prog.nc:3:1", "unknown G code G7.5"});
}

TEST(Cli, UnknownMCodeIsADataError) {
  expect_error({"G0 X0 Y0 Z1\nM3 S100 M47\n", "", 65, "prog.nc:2:9", "unknown M code M47"});
}

TEST(Cli, UnknownToolIsAConfigError) {
  expect_error({kGood, "--tool cone:d=1", 78, "--tool", "unknown tool kind 'cone'"});
}

TEST(Cli, MissingProgramIsNoInput) {
  TempDir dir;
  std::string err;
  EXPECT_EQ(run_cli("run " + dir.file("nope.nc") + " -o " + dir.file("out"), nullptr, &err), 66);
  EXPECT_NE(err.find("nope.nc: error: no such file"), std::string::npos) << err;
  EXPECT_FALSE(fs::exists(dir.file("out/nope.glb")));
}

TEST(Cli, UnwritableOutputDirectoryCannotCreate) {
  TempDir dir;
  const auto prog = dir.write("prog.nc", kGood);
  const auto blocker = dir.write("afile", "x");  // a file where a directory should be
  std::string err;
  EXPECT_EQ(run_cli("run " + prog + " --stock-box -2,-2,-1,3,2,0 -o " + blocker + "/sub", nullptr, &err), 73);
  EXPECT_NE(err.find(blocker + "/sub: error: cannot create output directory"), std::string::npos) << err;
}

// A run that fails leaves no trace: the directories it made for its
// output go again (all the levels it made), one that was there stays.
TEST(Cli, FailedRunRemovesTheOutputDirectoriesItMadeAndKeepsOthers) {
  TempDir dir;
  const auto prog = dir.write("prog.nc", "G0 X0 Y0 Z1\nG1 X1 Y\n");
  std::string err;
  EXPECT_EQ(run_cli("run " + prog + " --stock-box -2,-2,-1,3,2,0 -o " + dir.file("a/b/c"), nullptr, &err), 65);
  EXPECT_NE(err.find("prog.nc:2:7: error"), std::string::npos) << err;
  EXPECT_FALSE(fs::exists(dir.file("a"))) << "made by the run";
  fs::create_directories(dir.file("kept"));
  EXPECT_EQ(run_cli("run " + prog + " --stock-box -2,-2,-1,3,2,0 -o " + dir.file("kept/new"), nullptr, &err), 65);
  EXPECT_TRUE(fs::is_directory(dir.file("kept")));
  EXPECT_FALSE(fs::exists(dir.file("kept/new")));
  // A run that succeeds keeps what it made, with its result in it.
  const auto good = dir.write("good.nc", kGood);
  EXPECT_EQ(run_cli("run " + good + " --stock-box -2,-2,-1,3,2,0 --voxel 0.02 -o " + dir.file("a/b"), nullptr, &err), 0)
      << err;
  EXPECT_TRUE(fs::exists(dir.file("a/b/good.glb")));
  EXPECT_TRUE(fs::exists(dir.file("a/b/good.report.json")));
}

TEST(Cli, BadCommandLineIsUsage) {
  EXPECT_EQ(run_cli("run"), 64);
  EXPECT_EQ(run_cli("frobnicate x.nc"), 64);
  EXPECT_EQ(run_cli("run x.nc --voxel -1"), 64);
}

TEST(Cli, JobFileBesideTheProgramIsUsedAndReported) {
  TempDir dir;
  const auto prog = dir.write("slot.nc", "G0 X0 Y0 Z1\nG1 Z-0.2 F100\nG1 X3\nG0 Z1\n");
  dir.write("slot.toml", "[stock]\nbox = [-2, -2, -2, 5, 2, 0]\n[tool]\nspec = \"flat:d=2\"\n[simulation]\nvoxel_mm = 0.02\n");
  std::string out;
  ASSERT_EQ(run_cli("run " + prog + " --format json -o " + dir.file("out"), &out), 0);
  const auto j = nlohmann::json::parse(out);
  EXPECT_EQ(j["tool"]["spec"], "flat:d=2");
  EXPECT_DOUBLE_EQ(j["voxel_size_mm"].get<double>(), 0.02);
  EXPECT_NEAR(j["removed_volume_mm3"].get<double>(), (2 * 3 + kPi) * 0.2, 0.05 * 0.02 * (6 + kPi + 0.2 * (6 + 2 * kPi)));
  for (const char* key : {"program", "blocks", "moves", "voxel_size_mm", "stock_volume_before_mm3",
                          "stock_volume_after_mm3", "removed_volume_mm3", "timing_s", "peak_rss_mb"})
    EXPECT_TRUE(j.contains(key)) << key;
  for (const char* key : {"parse", "simulate", "export", "total"}) EXPECT_TRUE(j["timing_s"].contains(key)) << key;
  EXPECT_EQ(j["blocks"], 4);
  EXPECT_EQ(j["moves"], 4);
  EXPECT_EQ(slurp(dir.file("out/slot.report.json")), out);
}

TEST(Cli, DefaultsArePrinted) {
  TempDir dir;
  const auto prog = dir.write("p.nc", kGood);
  std::string out;
  ASSERT_EQ(run_cli("run " + prog + " -o " + dir.file("out"), &out), 0);
  EXPECT_NE(out.find("note: tool: ball:d=1 (default"), std::string::npos) << out;
  EXPECT_NE(out.find("note: stock: box -0.5,-0.5,-1.1,1.5,0.5,0 mm (default"), std::string::npos) << out;
  EXPECT_NE(out.find("note: voxel: 0.02 mm (default"), std::string::npos) << out;
}

TEST(Cli, CheckDumpPrintsOneJsonLinePerMove) {
  TempDir dir;
  const auto prog = dir.write("p.nc", "G20\nG0 X1 Y0 Z0 A90\nG3 X0 Y1 I-1 J0 F2\n");
  std::string out;
  ASSERT_EQ(run_cli("check --dump " + prog, &out), 0);
  std::istringstream lines(out);
  std::string l1, l2, l3;
  std::getline(lines, l1);
  std::getline(lines, l2);
  EXPECT_FALSE(std::getline(lines, l3));
  const auto a = nlohmann::json::parse(l1), b = nlohmann::json::parse(l2);
  EXPECT_EQ(a["line"], 2);
  EXPECT_EQ(a["motion"], "G0");
  EXPECT_DOUBLE_EQ(a["end"][0].get<double>(), 25.4);
  EXPECT_NEAR(a["end"][3].get<double>(), 90.0, 1e-12);
  EXPECT_EQ(b["motion"], "G3");
  EXPECT_DOUBLE_EQ(b["centre"][0].get<double>(), 0.0);
  EXPECT_DOUBLE_EQ(b["centre"][1].get<double>(), 0.0);
  EXPECT_DOUBLE_EQ(b["feed_mm_per_min"].get<double>(), 2 * 25.4);
  EXPECT_FALSE(a.contains("centre"));
}

TEST(Cli, TwoRunsGiveBitIdenticalReportsAndMeshes) {
  TempDir dir;
  std::string prog = "G0 X0 Y0 Z1\n";
  for (int i = 0; i < 12; ++i)
    prog += "G1 Z-0.05 F100\nG1 X" + std::to_string(2 + 0.1 * i) + " Y" + std::to_string(0.15 * i) +
            "\nG2 X0 Y" + std::to_string(0.15 * i + 0.15) + " R3\nG0 Z1\n";
  const auto p = dir.write("p.nc", prog);
  auto run_once = [&](const std::string& out) {
    EXPECT_EQ(run_cli("run " + p + " --tool ball:d=0.5 --stock-box -1,-1,-1,4,3,0 --voxel 0.005 -o " + out), 0);
    auto j = nlohmann::json::parse(slurp(out + "/p.report.json"));
    j.erase("timing_s");
    j.erase("peak_rss_mb");
    j.erase("peak_rss_simulate_mb");
    j["outputs"] = nullptr;
    return std::make_pair(j.dump(), slurp(out + "/p.glb"));
  };
  const auto a = run_once(dir.file("a")), b = run_once(dir.file("b"));
  EXPECT_EQ(a.first, b.first);
  EXPECT_GT(a.second.size(), 1000u);
  EXPECT_TRUE(a.second == b.second) << "the .glb files differ";
}

}  // namespace
// A V tool's planing (the snowflake's path: one-piece prism quarters and
// joints; with AVX2 the quarters of several pieces lower their bars
// without the portable version's cone) cut with CUTSIM_AVX2=1 and =0: the
// same glb.
TEST(Cli, Avx2LoopsCutTheSameVToolStockAsThePortableOnes) {
  TempDir dir;
  std::string prog = "G21 G90 G94\nG0 Z0.1\n";
  for (int layer = 1; layer <= 2; ++layer)
    for (int row = 0; row < 9; ++row) {
      const double y = -0.04 + 0.01 * row, z = -0.008 * layer - 0.002 * std::sin(3.0 * y);
      prog += "G0 X-0.3 Y" + std::to_string(y) + "\nG1 Z" + std::to_string(z) + " F60\n";
      for (int i = 1; i <= 6; ++i) prog += "G1 X" + std::to_string(-0.3 + 0.1 * i) + " Z" + std::to_string(z - 0.001 * (i % 2)) + "\n";
      prog += "G0 Z0.1\n";
    }
  prog += "M30\n";
  dir.write("v.nc", prog);
  dir.write("v.toml", "[stock]\nbox = [-1, -1, -1, 1, 1, 0]\n[tool]\nspec = \"vtool:angle=90,clearance=7,h=0.1,body=0.3\"\n"
                      "[simulation]\nvoxel_mm = 0.002\nstart = [0, 0, 0.1]\n");
  std::string err;
  for (const std::string env : {"CUTSIM_AVX2=1", "CUTSIM_AVX2=0"})
    ASSERT_LE(run_cli_raw("env " + env + " " + std::string(CUTSIM_BIN) + " run " + dir.file("v.nc") + " -o " +
                              dir.file(env.substr(12)),
                          nullptr, &err),
              1)  // (1: contacts, the clearance face on the walls)
        << err;
  const std::string wide = slurp(dir.file("1/v.glb")), portable = slurp(dir.file("0/v.glb"));
  EXPECT_GT(wide.size(), 10000u);
  EXPECT_TRUE(wide == portable) << "the glb differs (" << wide.size() << " and " << portable.size() << " bytes)";
  const auto j = nlohmann::json::parse(slurp(dir.file("0/v.report.json")));
  EXPECT_GT(j["removed_volume_mm3"].get<double>(), 1e-4);
  EXPECT_GT(j["voxel_evaluations"].get<double>(), 1e5);
}

// The four-axis case on one thread and on two: the same glb, deviation
// colours included (they once depended on how the threads split the
// vertices, in the last bits).
TEST(Cli, OneThreadAndTwoWriteTheSameGlb) {
  TempDir dir;
  const std::string prog = std::string(CUTSIM_SOURCE_DIR) + "/ncprograms/fouraxis_faces.nc";
  std::string err;
  for (const std::string t : {"1", "2"})
    ASSERT_EQ(run_cli_raw(std::string(CUTSIM_BIN) + " run " + prog + " --threads " + t + " -o " + dir.file(t), nullptr, &err), 0)
        << err;
  const std::string one = slurp(dir.file("1/fouraxis_faces.glb")), two = slurp(dir.file("2/fouraxis_faces.glb"));
  EXPECT_GT(one.size(), 100000u);
  EXPECT_TRUE(one == two) << "the glb differs (" << one.size() << " and " << two.size() << " bytes)";
}

}  // namespace cutsim::test

namespace cutsim::test {

// A contact is a finding, not a failure: outputs are written, each contact
// is printed as file:line with the NC text, the report lists them, and the
// exit code is 1. A clean run exits 0.
TEST(Cli, ContactsPrintByLineAndExitOne) {
  TempDir dir;
  const std::string tbl = dir.write("tools.tbl", "T3 P3 D1.0 Z0 ;ball end mill l=1 shank_d=3\n");
  const std::string prog = dir.write("plunge.nc", "T3 M6\nG0 X0 Y0 Z1\nG1 Z-1.5 F100\nG0 Z1\nM30\n");
  const std::string outdir = dir.file("out");
  std::string out, err;
  const int code = run_cli("run " + prog + " --tools " + tbl + " --stock-box -3,-3,-3,3,3,0 --voxel 0.02 -o " + outdir,
                           &out, &err);
  EXPECT_EQ(code, 1) << out << err;
  EXPECT_NE(out.find(prog + ":3: shank contact at least 40 um deep at ("), std::string::npos) << out;
  EXPECT_NE(out.find("): G1 Z-1.5 F100\n"), std::string::npos) << out;
  // Pulling the buried shank out with a rapid touches too.
  EXPECT_NE(out.find(prog + ":4: rapid contact (shank)"), std::string::npos) << out;
  const auto report = nlohmann::json::parse(slurp(outdir + "/plunge.report.json"));
  ASSERT_EQ(report["contacts"].size(), 2u);
  EXPECT_EQ(report["contacts"][0]["line"], 3);
  EXPECT_EQ(report["contacts"][0]["region"], "shank");
  EXPECT_EQ(report["contacts"][1]["rapid"], true);
  EXPECT_EQ(report["tools_used"][0]["number"], 3);
  // The glb marks each contact with a node named by its line.
  const std::string glb = slurp(outdir + "/plunge.glb");
  EXPECT_NE(glb.find("\"contact line 3 shank"), std::string::npos);
  EXPECT_NE(glb.find("\"contact line 4 rapid shank"), std::string::npos);
  {
    ASSERT_GT(glb.size(), 20u);
    std::uint32_t json_len = 0;
    std::memcpy(&json_len, glb.data() + 12, 4);
    const auto gj = nlohmann::json::parse(glb.substr(20, json_len));
    int found = 0;
    for (const auto& node : gj["nodes"])
      if (node.contains("extras") && node["extras"].value("kind", "") == "contact") {
        const auto& ex = node["extras"];
        if (ex["line"] == 3) {
          EXPECT_EQ(ex["region"], "shank");
          EXPECT_EQ(ex["text"], "G1 Z-1.5 F100");
          EXPECT_EQ(ex["motion"], "feed");
          EXPECT_DOUBLE_EQ(ex["depth_mm"].get<double>(), report["contacts"][0]["depth_mm"].get<double>());
        }
        ++found;
      }
    EXPECT_EQ(found, 2);
  }

  // Many contacts: a line per kind, then the 20 that matter most, so the
  // rapid pulling out at the end (line 29) shows behind 26 shank contacts
  // (lines 3-28), on the console and among the glb's markers.
  {
    std::string many = "T3 M6\nG0 X0 Y0 Z1\nG1 Z-1.5 F100\n";
    for (int k = 1; k <= 25; ++k) many += "G1 X" + std::to_string(0.04 * k) + "\n";
    many += "G0 Z1\nM30\n";
    const std::string mp = dir.write("many.nc", many);
    EXPECT_EQ(run_cli("run " + mp + " --tools " + tbl + " --stock-box -3,-3,-3,3,3,0 --voxel 0.02 -o " + outdir, &out, &err),
              1)
        << out << err;
    EXPECT_NE(out.find("28 contacts:\n  rapid (cutter): 1 on line 29, deepest at least 40 um at line 29"),
              std::string::npos)
        << out;
    EXPECT_NE(out.find("\n  shank: 26 on lines 3-28, deepest at least 40 um at line 3; 26 of them at least 40 um"),
              std::string::npos)
        << out;
    EXPECT_NE(out.find(mp + ":29: rapid contact (shank)"), std::string::npos) << out;
    EXPECT_NE(out.find(mp + ":20: shank contact"), std::string::npos) << out;  // 18 shank contacts: lines 3-20
    EXPECT_EQ(out.find(mp + ":21: shank contact"), std::string::npos) << out;
    EXPECT_NE(out.find("... and 8 more contacts"), std::string::npos) << out;
    const auto rep = nlohmann::json::parse(slurp(outdir + "/many.report.json"));
    EXPECT_EQ(rep["contacts"].size(), 28u);
    ASSERT_EQ(rep["contact_summary"].size(), 3u);
    EXPECT_EQ(rep["contact_summary"][2]["region"], "shank");
    EXPECT_EQ(rep["contact_summary"][2]["records"], 26);
    EXPECT_EQ(rep["contact_summary"][2]["first_line"], 3);
    EXPECT_EQ(rep["contact_summary"][2]["last_line"], 28);
  }

  // Within the flutes: clean, exit 0.
  const std::string ok = dir.write("ok.nc", "T3 M6\nG0 X0 Y0 Z1\nG1 Z-0.8 F100\nG0 Z1\nM30\n");
  EXPECT_EQ(run_cli("run " + ok + " --tools " + tbl + " --stock-box -3,-3,-3,3,3,0 --voxel 0.02 -o " + outdir, &out, &err), 0)
      << out << err;
  // An unknown T number is a configuration error at its line.
  const std::string bad = dir.write("bad.nc", "T4 M6\nG1 X1 F100\nM30\n");
  EXPECT_EQ(run_cli("run " + bad + " --tools " + tbl + " --stock-box -3,-3,-3,3,3,0 -o " + outdir, &out, &err), 78);
  EXPECT_NE(err.find(bad + ":2:1: error: tool T4 is not in the tool library"), std::string::npos) << err;
}

}  // namespace cutsim::test

namespace cutsim::test {

// `cutsim bench` runs every case (program + job) of a folder and prints a
// row per case; the JSON carries the same figures.
TEST(Cli, BenchRunsTheCasesOfAFolder) {
  TempDir dir;
  dir.write("slot.nc", "G0 X-2 Y0 Z1\nG1 Z-0.1 F100\nG1 X2\nG0 Z1\nM30\n");
  dir.write("slot.toml", "[stock]\nbox = [-1, -1, -1, 1, 1, 0]\n[tool]\nspec = \"flat:d=1\"\n[simulation]\nvoxel_mm = 0.02\n");
  dir.write("lonely.nc", "G0 X0\n");  // no job: not a case
  std::string out, err;
  ASSERT_EQ(run_cli("bench --dir " + dir.path().string() + " --repeat 2 --threads 1 --json " + dir.file("b.json"), &out, &err), 0)
      << err;
  EXPECT_NE(out.find("kernel: "), std::string::npos) << out;
  EXPECT_NE(out.find("\nslot "), std::string::npos) << out;
  EXPECT_EQ(out.find("lonely"), std::string::npos) << out;
  const auto j = nlohmann::json::parse(slurp(dir.file("b.json")));
  ASSERT_EQ(j.size(), 1u);
  EXPECT_EQ(j[0]["case"], "slot");
  EXPECT_EQ(j[0]["moves"], 4);
  EXPECT_EQ(j[0]["repeats"], 2);
  // The two runs cut the same (the contact records and volumes repeat).
  EXPECT_EQ(j[0]["repeats_agree"], true);
  EXPECT_EQ(err.find("different results"), std::string::npos) << err;
  // A 1 mm flat slot, 0.1 deep, across the 2 mm block: 0.2 mm^3.
  EXPECT_NEAR(j[0]["removed_mm3"].get<double>(), 0.2, 0.002);
  EXPECT_GT(j[0]["kernel_updates_per_s"].get<double>(), 0);
  // The update's rate counts the voxels the slot's band reaches (one more
  // run counts them): those within 2 voxels (0.04 mm) of the slot, in the
  // block (2 x 1.08 x 0.14 mm) and at most up to the grid's top, 0.06 mm
  // over it, and 0.06 mm past its ends (2.12 x 1.08 x 0.2 mm).
  const double h3 = 0.02 * 0.02 * 0.02, band = j[0]["band_voxels"].get<double>();
  EXPECT_GT(band, 0.97 * 2 * 1.08 * 0.14 / h3);
  EXPECT_LT(band, 1.03 * 2.12 * 1.08 * 0.2 / h3);
  // Culling evaluates fewer; the rates follow from the counts.
  const double evals = j[0]["voxel_evaluations"].get<double>();
  EXPECT_GT(evals, 0);
  EXPECT_LT(evals, band);
  EXPECT_DOUBLE_EQ(j[0]["evaluated_fraction"].get<double>(), evals / band);
  EXPECT_DOUBLE_EQ(j[0]["voxel_updates_per_s"].get<double>(), band / j[0]["stock_update_s"].get<double>());
  EXPECT_DOUBLE_EQ(j[0]["update_to_kernel"].get<double>(),
                   j[0]["voxel_updates_per_s"].get<double>() / j[0]["kernel_updates_per_s"].get<double>());
  // Where the time went: each phase's median, the update's the column's,
  // none more than the slowest run's total (with 2 runs, the medians are
  // the slower of each), and a line per case after the table.
  const auto& ph = j[0]["phases_s"];
  for (const char* k : {"parse", "stock_build", "stock_update", "contact_check", "mesh", "compare", "write", "total"}) {
    ASSERT_TRUE(ph.contains(k)) << k;
    EXPECT_GE(ph[k].get<double>(), 0) << k;
    EXPECT_LE(ph[k].get<double>(), ph["total"].get<double>()) << k;
  }
  EXPECT_EQ(ph["stock_update"], j[0]["stock_update_s"]);
  EXPECT_EQ(ph["total"], j[0]["wall_s"]);
  EXPECT_GT(ph["stock_update"].get<double>(), 0);
  EXPECT_NE(out.find("phases (s, medians of the repeats):\n  slot "), std::string::npos) << out;
  // An unknown case is a missing input.
  EXPECT_EQ(run_cli("bench nope --dir " + dir.path().string(), &out, &err), 66);
}

// A case's [bench] goals: each figure against its goal, in the JSON and in
// a line after the table; a bad goal is refused at its place before any
// case runs.
TEST(Cli, BenchPrintsTheFiguresAgainstTheJobsGoals) {
  TempDir dir;
  dir.write("slot.nc", "G0 X-2 Y0 Z1\nG1 Z-0.1 F100\nG1 X2\nG0 Z1\nM30\n");
  // A goal no run can miss (a terabyte) and one none can meet (a move a picosecond).
  const std::string job = "[stock]\nbox = [-1, -1, -1, 1, 1, 0]\n[tool]\nspec = \"flat:d=1\"\n[simulation]\nvoxel_mm = 0.02\n"
                          "[bench]\nmax_rss_mb = 1e6\nmin_moves_per_s = 1e12\n";
  dir.write("slot.toml", job);
  const std::string cmd = "bench --dir " + dir.path().string() + " --repeat 1 --threads 1 --band-every 0 --json ";
  std::string out, err;
  ASSERT_EQ(run_cli(cmd + dir.file("b.json"), &out, &err), 0) << err;
  const auto row = nlohmann::json::parse(slurp(dir.file("b.json")))[0];
  ASSERT_TRUE(row.contains("goals")) << row.dump();
  const auto& g = row["goals"];
  EXPECT_FALSE(g.contains("wall_s"));  // not set, not judged
  EXPECT_EQ(g["peak_rss_mb"]["value"], row["peak_rss_mb"]);
  EXPECT_EQ(g["peak_rss_mb"]["goal"], 1e6);
  EXPECT_EQ(g["peak_rss_mb"]["met"], true);
  EXPECT_DOUBLE_EQ(g["peak_rss_mb"]["factor"].get<double>(), row["peak_rss_mb"].get<double>() / 1e6);
  EXPECT_EQ(g["moves_per_s"]["value"], row["moves_per_s"]);
  EXPECT_EQ(g["moves_per_s"]["met"], false);
  EXPECT_DOUBLE_EQ(g["moves_per_s"]["factor"].get<double>(), 1e12 / row["moves_per_s"].get<double>());
  EXPECT_NE(out.find("goals ([bench] in each case's job):\n  slot "), std::string::npos) << out;
  EXPECT_NE(out.find("peak RSS "), std::string::npos) << out;
  EXPECT_NE(out.find("(at most 1000000 MB): met; moves/s "), std::string::npos) << out;
  EXPECT_NE(out.find("(at least 1000000000000): not met, "), std::string::npos) << out;
  // A goal that is no goal: refused at its place, before anything runs.
  dir.write("slot.toml", job + "max_wall_s = 0\n");
  EXPECT_EQ(run_cli(cmd + dir.file("c.json"), &out, &err), 78);
  EXPECT_NE(err.find("slot.toml:10:14: error: max_wall_s must be positive"), std::string::npos) << err;
  EXPECT_EQ(out.find("kernel: "), std::string::npos) << out;
  EXPECT_FALSE(std::filesystem::exists(dir.file("c.json")));
}

// Where the JSON cannot go, the bench says so before it runs a case (a
// bench takes minutes), and leaves nothing; a folder that is missing is
// made, and holds only the JSON when the bench is done.
TEST(Cli, BenchChecksWhereItsJsonGoesBeforeRunning) {
  TempDir dir;
  dir.write("slot.nc", "G0 X-2 Y0 Z1\nG1 Z-0.1 F100\nG1 X2\nG0 Z1\nM30\n");
  dir.write("slot.toml", "[stock]\nbox = [-1, -1, -1, 1, 1, 0]\n[tool]\nspec = \"flat:d=1\"\n[simulation]\nvoxel_mm = 0.02\n");
  dir.write("plain", "a file, not a folder\n");
  const std::string cmd = "bench --dir " + dir.path().string() + " --repeat 1 --threads 1 --band-every 0 --json ";
  std::string out, err;
  // Under a plain file: no folder can be made there.
  EXPECT_EQ(run_cli(cmd + dir.file("plain") + "/b.json", &out, &err), 73);
  EXPECT_NE(err.find(dir.file("plain")), std::string::npos) << err;
  EXPECT_EQ(out.find("kernel: "), std::string::npos) << out;  // nothing measured, no case run
  // A folder in the JSON's place.
  std::filesystem::create_directory(dir.file("taken.json"));
  EXPECT_EQ(run_cli(cmd + dir.file("taken.json"), &out, &err), 73);
  EXPECT_NE(err.find("is a directory"), std::string::npos) << err;
  EXPECT_EQ(out.find("kernel: "), std::string::npos) << out;
  EXPECT_TRUE(std::filesystem::is_empty(dir.file("taken.json")));
  // A missing folder is made; once done it holds the JSON and nothing else
  // (no temporary file left beside it).
  const std::string json = dir.file("results/deeper/b.json");
  ASSERT_EQ(run_cli(cmd + json, &out, &err), 0) << err;
  EXPECT_NE(out.find("\nslot "), std::string::npos) << out;
  EXPECT_EQ(nlohmann::json::parse(slurp(json))[0]["case"], "slot");
  std::size_t files = 0;
  for ([[maybe_unused]] const auto& e : std::filesystem::directory_iterator(dir.file("results/deeper"))) ++files;
  EXPECT_EQ(files, 1u);
}

// GLIBC_TUNABLES gains glibc.malloc.hugetlb=1 once; a value the user set
// stands, whatever it is.
TEST(HugePages, TunableAddedOnceAndTheUsersStands) {
  EXPECT_EQ(tunables_with_huge_pages(nullptr), "glibc.malloc.hugetlb=1");
  EXPECT_EQ(tunables_with_huge_pages(""), "glibc.malloc.hugetlb=1");
  EXPECT_EQ(tunables_with_huge_pages("glibc.malloc.arena_max=2"), "glibc.malloc.arena_max=2:glibc.malloc.hugetlb=1");
  EXPECT_EQ(tunables_with_huge_pages("glibc.malloc.hugetlb=0"), std::nullopt);
  EXPECT_EQ(tunables_with_huge_pages("glibc.malloc.arena_max=2:glibc.malloc.hugetlb=1"), std::nullopt);
  EXPECT_EQ(tunables_with_huge_pages("glibc.malloc.hugetlbx=1"), "glibc.malloc.hugetlbx=1:glibc.malloc.hugetlb=1");
}

// The export's guard: while it lives, memory touched for the first time
// comes in 4 KB pages even where madvise asks for huge ones; after, the
// process is as it was (and a guard inside another leaves it to the outer).
namespace {
// AnonHugePages of the mapping that starts at `at`, kB (/proc/self/smaps).
long anon_huge_kb(const void* at) {
  std::ifstream in("/proc/self/smaps");
  std::string line;
  bool mine = false;
  while (std::getline(in, line)) {
    if (std::isxdigit(static_cast<unsigned char>(line[0])) && line.find('-') != std::string::npos &&
        line.find(':') > line.find(' ')) {
      mine = std::stoull(line.substr(0, line.find('-')), nullptr, 16) == reinterpret_cast<std::uintptr_t>(at);
    } else if (mine && line.rfind("AnonHugePages:", 0) == 0) {
      return std::stol(line.substr(14));
    }
  }
  return -1;
}
}  // namespace

TEST(HugePages, ExportGuardTouchesNewMemoryInSmallPages) {
  // (A process started with huge pages off already, as a container may
  // start it, keeps them off and the guard does nothing.)
  const int before = ::prctl(PR_GET_THP_DISABLE, 0, 0, 0, 0);
  ASSERT_TRUE(before == 0 || before == 1);
  {
    const SmallPagesForNewMemory outer;
    EXPECT_EQ(outer.active(), before == 0);
    EXPECT_EQ(::prctl(PR_GET_THP_DISABLE, 0, 0, 0, 0), 1);
    EXPECT_FALSE(huge_pages_for_new_memory());
    {
      const SmallPagesForNewMemory inner;
      EXPECT_FALSE(inner.active());
    }
    EXPECT_EQ(::prctl(PR_GET_THP_DISABLE, 0, 0, 0, 0), 1);
    // 8 MB, 2 MB aligned, asking for huge pages, written through.
    const std::size_t n = 8u << 20;
    void* raw = ::mmap(nullptr, n + (2u << 20), PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    ASSERT_NE(raw, MAP_FAILED);
    const auto base = reinterpret_cast<std::uintptr_t>(raw);
    auto* p = reinterpret_cast<char*>((base + (2u << 20) - 1) & ~std::uintptr_t((2u << 20) - 1));
    // (Its own mapping, so that smaps lists it from p.)
    if (reinterpret_cast<char*>(raw) != p) ::munmap(raw, static_cast<std::size_t>(p - reinterpret_cast<char*>(raw)));
    ::madvise(p, n, MADV_HUGEPAGE);
    std::memset(p, 1, n);
    EXPECT_EQ(anon_huge_kb(p), 0);
    ::munmap(raw, n + (2u << 20));
  }
  EXPECT_EQ(::prctl(PR_GET_THP_DISABLE, 0, 0, 0, 0), before);
}

// A stock grid estimated under 2 GiB takes its new memory in small pages
// (cheaper to touch first on the 2-core machine); a larger one keeps the
// huge pages malloc asks for; CUTSIM_STOCK_PAGES overrides.
TEST(HugePages, GridsUnderTwoGiBTakeSmallPages) {
  const char* was = std::getenv("CUTSIM_STOCK_PAGES");
  const std::optional<std::string> before = was ? std::optional<std::string>(was) : std::nullopt;
  ::unsetenv("CUTSIM_STOCK_PAGES");
  const std::size_t gib2 = std::size_t(2) << 30;
  EXPECT_TRUE(stock_wants_small_pages(150u << 20));
  EXPECT_TRUE(stock_wants_small_pages(gib2 - 1));
  EXPECT_FALSE(stock_wants_small_pages(gib2));
  EXPECT_FALSE(stock_wants_small_pages(3 * (std::size_t(1) << 30)));
  ::setenv("CUTSIM_STOCK_PAGES", "huge", 1);
  EXPECT_FALSE(stock_wants_small_pages(150u << 20));
  ::setenv("CUTSIM_STOCK_PAGES", "small", 1);
  EXPECT_TRUE(stock_wants_small_pages(gib2));
  ::setenv("CUTSIM_STOCK_PAGES", "other", 1);  // (not a choice: the size decides)
  EXPECT_FALSE(stock_wants_small_pages(gib2));
  if (before) ::setenv("CUTSIM_STOCK_PAGES", before->c_str(), 1);
  else ::unsetenv("CUTSIM_STOCK_PAGES");
}

// The report says which pages the stock's memory came in: a small job's
// 4 KB; 2 MB only where told to and malloc asks for huge pages.
TEST(Cli, ReportSaysWhichPagesTheStockHad) {
  TempDir dir;
  dir.write("slot.nc", "G0 X-2 Y0 Z1\nG1 Z-0.1 F100\nG1 X2\nG0 Z1\nM30\n");
  dir.write("slot.toml", "[stock]\nbox = [-1, -1, -1, 1, 1, 0]\n[tool]\nspec = \"flat:d=1\"\n[simulation]\nvoxel_mm = 0.05\n");
  // (A process with huge pages off passes that on to the runs it starts.)
  const bool can =
      malloc_is_glibcs() && transparent_huge_pages_available() && ::prctl(PR_GET_THP_DISABLE, 0, 0, 0, 0) == 0;
  auto page_kb = [&](const std::string& env) {
    std::string out, err;
    EXPECT_EQ(run_cli_raw("env -u GLIBC_TUNABLES -u CUTSIM_HUGE_PAGES -u CUTSIM_STOCK_PAGES " + env + " " +
                              std::string(CUTSIM_BIN) + " run " + dir.file("slot.nc") + " --format json -o " +
                              dir.file("out"),
                          &out, &err),
              0)
        << err;
    return nlohmann::json::parse(out)["stock_page_kb"].get<int>();
  };
  EXPECT_EQ(page_kb(""), 4);
  EXPECT_EQ(page_kb("CUTSIM_STOCK_PAGES=huge"), can ? 2048 : 4);
  EXPECT_EQ(page_kb("CUTSIM_STOCK_PAGES=huge CUTSIM_HUGE_PAGES=0"), 4);
}

// cutsim starts itself again with huge pages asked for (where the kernel
// has them and the allocator is glibc's), and `cutsim bench` says which
// pages its runs had; CUTSIM_HUGE_PAGES=0 and a hugetlb the user set keep
// it from doing so.
TEST(Cli, StartsAgainWithHugePagesUnlessTold) {
  TempDir dir;
  dir.write("slot.nc", "G0 X-2 Y0 Z1\nG1 Z-0.1 F100\nG1 X2\nG0 Z1\nM30\n");
  dir.write("slot.toml", "[stock]\nbox = [-1, -1, -1, 1, 1, 0]\n[tool]\nspec = \"flat:d=1\"\n[simulation]\nvoxel_mm = 0.05\n");
  const bool can = malloc_is_glibcs() && transparent_huge_pages_available();
  auto huge = [&](const std::string& env) {
    std::string out, err;
    const std::string json = dir.file("b.json");
    EXPECT_EQ(run_cli_raw("env -u GLIBC_TUNABLES -u CUTSIM_HUGE_PAGES " + env + " " + std::string(CUTSIM_BIN) +
                              " bench --dir " + dir.path().string() + " --repeat 1 --threads 1 --json " + json,
                          &out, &err),
              0)
        << err;
    const auto j = nlohmann::json::parse(slurp(json));
    EXPECT_EQ(out.find("malloc: transparent huge pages") != std::string::npos, j[0]["malloc_huge_pages"].get<bool>()) << out;
    return j[0]["malloc_huge_pages"].get<bool>();
  };
  EXPECT_EQ(huge(""), can);
  EXPECT_FALSE(huge("CUTSIM_HUGE_PAGES=0"));
  EXPECT_FALSE(huge("GLIBC_TUNABLES=glibc.malloc.hugetlb=0"));
  EXPECT_EQ(huge("GLIBC_TUNABLES=glibc.malloc.arena_max=4"), can);
}


// The voxel step's AVX2 loops (voxel_kernels.h) give the portable
// versions' stock to the byte, end to end: a ball-end raster's glb with
// them and with CUTSIM_AVX2=0.
TEST(Cli, Avx2LoopsCutTheSameStockAsThePortableOnes) {
  TempDir dir;
  std::string prog = "G21 G90 G94\nG0 Z1\nG0 X-1.5 Y-1.5\nG1 Z-0.08 F500\n";
  for (int row = 0; row < 7; ++row) {
    const double y = -1.5 + 0.5 * row;
    prog += "G1 Y" + std::to_string(y) + "\n";
    for (int i = 1; i <= 12; ++i) {
      const double x = (row % 2 ? 1.5 - 0.25 * i : -1.5 + 0.25 * i);
      prog += "G1 X" + std::to_string(x) + " Z" + std::to_string(-0.08 - 0.02 * std::sin(x + y)) + "\n";
    }
  }
  prog += "G0 Z1\nM30\n";
  dir.write("r.nc", prog);
  dir.write("r.toml", "[stock]\nbox = [-2, -2, -1, 2, 2, 0]\n[tool]\nspec = \"ball:d=1\"\n[simulation]\nvoxel_mm = 0.02\n");
  std::string err;
  for (const std::string env : {"CUTSIM_AVX2=1", "CUTSIM_AVX2=0"})
    ASSERT_EQ(run_cli_raw("env " + env + " " + std::string(CUTSIM_BIN) + " run " + dir.file("r.nc") + " -o " +
                              dir.file(env.substr(12)),
                          nullptr, &err),
              0)
        << err;
  const std::string wide = slurp(dir.file("1/r.glb")), portable = slurp(dir.file("0/r.glb"));
  EXPECT_GT(wide.size(), 10000u);
  EXPECT_TRUE(wide == portable) << "the glb differs (" << wide.size() << " and " << portable.size() << " bytes)";
  // Both cut: the report's removed volume is well above nothing.
  const auto j = nlohmann::json::parse(slurp(dir.file("0/r.report.json")));
  EXPECT_GT(j["removed_volume_mm3"].get<double>(), 0.5);
}

}  // namespace cutsim::test
