// Robustness: interruption, degenerate programs and inputs, memory refusal.
// Each case has a defined answer: a result with the right figures, or a
// clear error and no output.
#include <chrono>
#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>

#include "cutsim/core/error.h"
#include "helpers.h"

namespace cutsim::test {
namespace {

namespace fs = std::filesystem;

// Thousands of overlapping passes over a small patch: the grid builds in
// a blink, the cutting takes many seconds.
std::string long_program() {
  std::string p = "G21 G90\nG0 X0 Y0 Z1\nG1 Z-0.02 F1000\n";
  for (int i = 0; i < 20000; ++i) p += (i % 2 ? "G1 X0 Y" : "G1 X0.6 Y") + std::to_string(0.6 * ((i / 2) % 2)) + "\n";
  return p + "G0 Z1\nM30\n";
}

double run_interrupted(const std::string& args, int* code, std::string* err, double after_s = 1.0) {
  const auto t0 = std::chrono::steady_clock::now();
  *code = run_cli_raw("timeout --preserve-status -s INT " + std::to_string(after_s) + " " + std::string(CUTSIM_BIN) + " " + args,
                      nullptr, err);
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

TEST(Interrupt, SigintStopsWithinASecondAndWritesNothing) {
  TempDir dir;
  const auto prog = dir.write("long.nc", long_program());
  int code = 0;
  std::string err;
  const double s = run_interrupted("run " + prog + " --tool ball:d=0.5 --stock-box -0.5,-0.5,-0.5,1.1,1.1,0 --voxel 0.001 -o " +
                                       dir.file("out"), &code, &err);
  EXPECT_EQ(code, 130) << err;
  // 36 ms from the signal to exit on an idle machine; a loaded CI machine
  // gets two seconds of slack.
  EXPECT_LT(s, 1.0 + 2.0) << "seconds from start to exit, SIGINT at 1.0 s";
  EXPECT_NE(err.find("long.nc:"), std::string::npos) << err;
  EXPECT_NE(err.find("interrupted while"), std::string::npos) << err;
  EXPECT_TRUE(!fs::exists(dir.file("out")) || fs::is_empty(dir.file("out")));
}

TEST(Interrupt, PartialWritesAMarkedResult) {
  TempDir dir;
  const auto prog = dir.write("long.nc", long_program());
  int code = 0;
  std::string err;
  // Late enough that cutting has begun even on a loaded machine (the
  // program cuts for 20 s or more).
  run_interrupted("run " + prog + " --partial --tool ball:d=0.5 --stock-box -0.5,-0.5,-0.5,1.1,1.1,0 --voxel 0.001 -o " +
                      dir.file("out"), &code, &err, 2.5);
  EXPECT_EQ(code, 130) << err;
  ASSERT_TRUE(fs::exists(dir.file("out/long.partial.report.json"))) << err;
  EXPECT_TRUE(fs::exists(dir.file("out/long.partial.glb")));
  EXPECT_FALSE(fs::exists(dir.file("out/long.report.json")));
  const auto j = nlohmann::json::parse(slurp(dir.file("out/long.partial.report.json")));
  EXPECT_EQ(j["partial"], true);
  EXPECT_GT(j["stopped_after_line"].get<int>(), 3);
  EXPECT_GT(j["removed_volume_mm3"].get<double>(), 0);
}

// One stop delivered twice (a supervisor such as `timeout` signals both
// the process and its group): the second, 50 ms after the first has been
// handled, is the same stop, not a second Ctrl-C that kills at once.
TEST(Interrupt, ASignalRepeatedWithinHalfASecondIsTheSameStop) {
  TempDir dir;
  const auto prog = dir.write("long.nc", long_program());
  std::string err;
  const int code = run_cli_raw("sh -c '" + std::string(CUTSIM_BIN) + " run " + prog +
                                   " --partial --tool ball:d=0.5 --stock-box -0.5,-0.5,-0.5,1.1,1.1,0 --voxel 0.001 -o " +
                                   dir.file("out") +
                                   " & p=$!; sleep 2.5; kill -INT $p; sleep 0.05; kill -INT $p; wait $p'",
                               nullptr, &err);
  EXPECT_EQ(code, 130) << err;
  EXPECT_NE(err.find("partial result written"), std::string::npos) << err;
  EXPECT_TRUE(fs::exists(dir.file("out/long.partial.report.json"))) << err;
}

TEST(Degenerate, EmptyProgramWithAStockCutsNothing) {
  TempDir dir;
  auto r = run_program(dir, "", "ball:d=1", Aabb{Vec3(0, 0, -1), Vec3(1, 1, 0)}, 0.01);
  EXPECT_EQ(r.blocks, 0);
  EXPECT_EQ(r.moves, 0);
  EXPECT_DOUBLE_EQ(r.stock->removed_volume_mm3(), 0);
  EXPECT_DOUBLE_EQ(r.stock->volume_mm3(), 1.0);
}

TEST(Degenerate, EmptyProgramWithoutAStockIsAConfigError) {
  TempDir dir;
  const auto prog = dir.write("e.nc", "");
  std::string err;
  EXPECT_EQ(run_cli("run " + prog + " -o " + dir.file("out"), nullptr, &err), 78);
  EXPECT_NE(err.find("no cutting moves"), std::string::npos) << err;
}

TEST(Degenerate, RapidsAboveTheStockCutNothing) {
  TempDir dir;
  auto r = run_program(dir, "G0 X0 Y0 Z5\nG0 X10 Y10\nG0 X0\n", "ball:d=1", Aabb{Vec3(-1, -1, -1), Vec3(11, 11, 0)}, 0.02);
  EXPECT_EQ(r.cutting_moves, 0);
  EXPECT_DOUBLE_EQ(r.stock->removed_volume_mm3(), 0);
}

TEST(Degenerate, ZeroLengthMovesCutOnePose) {
  TempDir dir;
  const double R = 0.5, d = 0.1, h = 0.005;
  auto r = run_program(dir, "G0 X0 Y0 Z1\nG1 Z-0.1 F100\nG1 Z-0.1\nG1 X0 Y0 Z-0.1\nG0 Z1\n", "ball:d=1",
                       Aabb{Vec3(-1, -1, -1), Vec3(1, 1, 0)}, h);
  const double cap = kPi * d * d * (3 * R - d) / 3;
  EXPECT_NEAR(r.stock->removed_volume_mm3(), cap, 0.05 * h * 2 * kPi * R * d);
}

TEST(Degenerate, TenMetreMoveCrossesTheBlock) {
  // A 10 m straight move through a 50 mm block at 10 um voxels: only the
  // slot inside the block is a grid; the volume is the segment area times
  // the block's length (no rounded ends inside it).
  TempDir dir;
  const double R = 0.5, d = 0.05, h = 0.01;
  auto r = run_program(dir, "G0 X-5000 Y0 Z1\nG1 Z-0.05 F1000\nG1 X5000\nG0 Z1\n", "ball:d=1",
                       Aabb{Vec3(-25, -25, -10), Vec3(25, 25, 0)}, h);
  const double seg = R * R * std::acos((R - d) / R) - (R - d) * std::sqrt(2 * R * d - d * d);
  const double area = 2 * R * std::acos((R - d) / R) * 50;
  EXPECT_NEAR(r.stock->removed_volume_mm3(), seg * 50, 0.05 * h * area);
}

TEST(Degenerate, ToolLargerThanTheStockRemovesAllOfIt) {
  TempDir dir;
  auto r = run_program(dir, "G0 X2.5 Y2.5 Z20\nG1 Z-20 F100\nG0 Z20\n", "flat:d=40,l=50",
                       Aabb{Vec3(0, 0, -5), Vec3(5, 5, 0)}, 0.05);
  // Everything goes; the box's edges bias the grid integral by h^2/4 per
  // mm of edge (12 x 5 mm here), which the figures are clamped against.
  EXPECT_NEAR(r.stock->volume_mm3(), 0.0, 1e-9);
  EXPECT_NEAR(r.stock->removed_volume_mm3(), 125.0, 1e-9);
  EXPECT_EQ(r.stock->stats().active_voxels, 0u);
}

TEST(Degenerate, NonFiniteExpressionIsAnErrorAtItsColumn) {
  TempDir dir;
  const auto prog = dir.write("n.nc", "G0 X0\nG1 X[EXP[1000]] F1\n");
  std::string err;
  EXPECT_EQ(run_cli("check " + prog, nullptr, &err), 65);
  EXPECT_NE(err.find("n.nc:2:"), std::string::npos) << err;
  EXPECT_NE(err.find("not a finite number"), std::string::npos) << err;
}

TEST(Degenerate, HugeSingleLineIsRefusedWithBoundedMemory) {
  TempDir dir;
  const auto prog = dir.write("big.nc", std::string(8 << 20, 'G'));
  std::string err;
  EXPECT_EQ(run_cli("check " + prog, nullptr, &err), 65);
  EXPECT_NE(err.find("big.nc:1:1: error: line is longer than 1048576 bytes"), std::string::npos) << err;
}

TEST(Memory, JobOverTheLimitIsRefusedWithTheFigureAndAVoxelThatFits) {
  TempDir dir;
  const auto prog = dir.write("p.nc", "G0 X0 Y0 Z1\nG1 Z-0.1 F100\nG1 X40\n");
  dir.write("p.toml", "[stock]\nbox = [-5, -5, -5, 45, 5, 0]\n[simulation]\nvoxel_mm = 0.0005\nmemory_limit_mb = 200\n");
  std::string err;
  EXPECT_EQ(run_cli("run " + prog + " -o " + dir.file("out"), nullptr, &err), 65);
  EXPECT_NE(err.find("would need about"), std::string::npos) << err;
  EXPECT_NE(err.find("over the limit of 200 MiB"), std::string::npos) << err;
  EXPECT_NE(err.find("um or coarser would fit"), std::string::npos) << err;
  EXPECT_TRUE(!fs::exists(dir.file("out")) || fs::is_empty(dir.file("out")));
}

TEST(Degenerate, VoxelFinerThanTheGridCanHoldIsRefused) {
  // OpenVDB's transform takes no voxel under 3e-15 mm^3 (0.0144 um): a
  // 0.01 um voxel is a clear error, with nothing written; 0.02 um runs.
  TempDir dir;
  const auto prog = dir.write("p.nc", "G0 X0 Y0 Z1\nG1 Z-0.0001 F100\nG1 X0.001\n");
  std::string err;
  EXPECT_EQ(run_cli("run " + prog + " --tool ball:d=0.002 --stock-box=-0.003,-0.003,-0.002,0.003,0.003,0 --voxel 0.00001 -o " +
                        dir.file("fine"),
                    nullptr, &err),
            65);
  EXPECT_NE(err.find("voxel size 0.01 um is finer than the stock grid can hold (0.015 um at least)"), std::string::npos)
      << err;
  EXPECT_FALSE(fs::exists(dir.file("fine")));
  EXPECT_EQ(run_cli("run " + prog + " --tool ball:d=0.002 --stock-box=-0.003,-0.003,-0.002,0.003,0.003,0 --voxel 0.00002 -o " +
                        dir.file("ok"),
                    nullptr, &err),
            0)
      << err;
  EXPECT_TRUE(fs::exists(dir.file("ok/p.glb")));
  // In a job file: the error at the key.
  dir.write("p.toml", "[stock]\nbox = [-0.003, -0.003, -0.002, 0.003, 0.003, 0]\n[simulation]\nvoxel_mm = 0.00001\n");
  EXPECT_EQ(run_cli("run " + prog + " --tool ball:d=0.002 -o " + dir.file("job"), nullptr, &err), 78);
  EXPECT_NE(err.find("p.toml:4:12: error: voxel_mm 1e-05 is finer than the stock grid can hold (1.5e-05 mm at least)"),
            std::string::npos)
      << err;
  EXPECT_FALSE(fs::exists(dir.file("job")));
}

}  // namespace
}  // namespace cutsim::test

namespace cutsim::test {

// Programs are streamed: the reader's memory does not grow with the
// program. 2,000,000 blocks (72 MB) against 200,000: the peak RSS of
// `cutsim check` may not grow by more than 8 MB (10,000,000 blocks are
// measured in bench/README.md: 33 MB). Under AddressSanitizer the child
// runs with its quarantine off (a freed block is otherwise held back, and
// the RSS grows with what the program freed, not with what it holds: 134
// MB against 412 MB with it, 104 against 104 without); a Release build
// ignores the variable.
TEST(Degenerate, MillionsOfBlocksKeepMemoryFlat) {
  TempDir dir;
  auto make = [&](const std::string& name, int blocks) {
    std::ofstream out(dir.file(name));
    out << "G0 X0 Y0 Z1\nF600\n";
    char buf[96];
    for (int i = 0; i < blocks; ++i) {
      std::snprintf(buf, sizeof buf, "G1 X%.6f Y%.6f Z%.6f\n", (i % 1000) * 0.001, (i % 977) * 0.001, -(i % 13) * 0.001);
      out << buf;
    }
    return dir.file(name);
  };
  auto peak = [&](const std::string& prog, int blocks) {
    std::string out, err;
    EXPECT_EQ(run_cli_raw("ASAN_OPTIONS=\"${ASAN_OPTIONS:+$ASAN_OPTIONS:}quarantine_size_mb=0\" " +
                              std::string(CUTSIM_BIN) + " check " + prog,
                          &out, &err),
              0)
        << err;
    EXPECT_NE(out.find(std::to_string(blocks + 2) + " blocks"), std::string::npos) << out;
    const auto at = out.find("peak RSS ");
    EXPECT_NE(at, std::string::npos) << out;
    return at == std::string::npos ? -1 : std::stoi(out.substr(at + 9));
  };
  const int small = peak(make("small.nc", 200000), 200000);
  const int large = peak(make("large.nc", 2000000), 2000000);
  EXPECT_GT(small, 0);
  EXPECT_LE(large, small + 8) << "small " << small << " MB, large " << large << " MB";
}

}  // namespace cutsim::test
