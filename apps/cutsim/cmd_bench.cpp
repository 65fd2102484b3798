// cutsim bench [CASES...]: runs reference cases (NC program + job in
// ncprograms/) as child `cutsim run`s and prints one row per case, with
// the stock update's voxel rate against the bare kernel measured here.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <sys/wait.h>
#include <unistd.h>

#include <nlohmann/json.hpp>
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>

#include "commands.h"
#include "cutsim/core/error.h"
#include "cutsim/core/huge_pages.h"
#include "cutsim/io/atomic_file.h"
#include "cutsim/io/job.h"
#include "cutsim/sweep/sweep.h"

namespace cutsim::app {

namespace fs = std::filesystem;

namespace {

// The run report's phases (timing_s) the bench reports, in the run's order.
constexpr const char* kPhases[] = {"parse", "stock_build", "stock_update", "contact_check", "mesh", "compare", "write",
                                   "total"};

struct BenchArgs {
  std::vector<std::string> cases;
  int repeat = 3;
  int threads = 0;
  std::string json;
  std::string dir = "ncprograms";
  double voxel = 0;  // 0: each job's own
  std::size_t band_every = 1;  // --measure-band N of the counting run; 0: none
};

// The bare voxel-update kernel: a ball-end sweep's distance at the voxels of
// an in-cache 8 x 8 x 8 block, max with the stock value, written back.
// Evaluations per second over `threads` threads, one round.
double kernel_round(int threads) {
  const tool::Tool t = tool::parse_tool_spec("ball:d=1", "bench");
  const sweep::Sweep sw = sweep::sweep_line(Vec3(-0.5, 0, -0.1), Vec3(0.5, 0, -0.1), Eigen::Matrix3d::Identity(), t);
  const sweep::Primitive prim = sw.prims.front();
  const int n = std::max(1, threads);
  const long per_thread = 4'000'000;
  std::vector<float> sink(static_cast<std::size_t>(n));
  const auto t0 = std::chrono::steady_clock::now();
  tbb::parallel_for(0, n, [&](int k) {
    float v[512];
    std::fill(std::begin(v), std::end(v), 0.03f);
    const double h = 0.01;
    std::vector<Vec3> pos(512);
    for (int i = 0; i < 512; ++i)
      pos[static_cast<std::size_t>(i)] = Vec3(-0.04 + 0.001 * k, -0.04, -0.14) + h * Vec3(i >> 6, (i >> 3) & 7, i & 7);
    for (long it = 0; it < per_thread / 512; ++it)
      for (int i = 0; i < 512; ++i) {
        const float d = static_cast<float>(-sweep::distance(prim, pos[static_cast<std::size_t>(i)]));
        if (d > v[i]) v[i] = std::min(d, 0.03f);
      }
    sink[static_cast<std::size_t>(k)] = v[17];
  });
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  volatile float keep = sink[0];
  (void)keep;
  return static_cast<double>(per_thread) * n / s;
}

// The kernel's rate: the best of several rounds. One round of some 30 ms
// read anywhere from 1.6e8 to 2.9e8 on this machine (the threads' start,
// the clock ramping up), which made the update-to-kernel ratio swing.
double kernel_rate(int threads) {
  double best = 0;
  for (int i = 0; i < 7; ++i) best = std::max(best, kernel_round(threads));
  return best;
}

// Runs a command, returns its exit status; stdout into `out`, stderr into `err`.
int run_child(const std::string& cmd, std::string& out, std::string& err) {
  char tmpl[] = "/tmp/cutsim-bench-XXXXXX";
  const char* d = ::mkdtemp(tmpl);
  if (!d) throw OutputError("/tmp", "cannot create a temporary directory");
  const std::string dir = d;
  const std::string full = cmd + " >" + dir + "/out 2>" + dir + "/err </dev/null";
  const int status = std::system(full.c_str());
  auto slurp = [](const std::string& p) {
    std::ifstream in(p, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), {});
  };
  out = slurp(dir + "/out");
  err = slurp(dir + "/err");
  std::error_code ec;
  fs::remove_all(dir, ec);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

std::string fmt_g(double v) {
  char b[64];
  std::snprintf(b, sizeof b, "%.9g", v);
  return b;
}

std::string quote(const std::string& s) {
  std::string q = "'";
  for (char c : s) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

}  // namespace

Action add_bench_command(CLI::App& app) {
  auto a = std::make_shared<BenchArgs>();
  CLI::App* cmd = app.add_subcommand("bench", "run reference cases and print a table of time, memory, throughput and results");
  cmd->add_option("cases", a->cases, "case names: DIR/<name>.nc with DIR/<name>.toml (default: every such pair in DIR)");
  cmd->add_option("--repeat", a->repeat, "runs per case; times are medians")->check(kPositive);
  cmd->add_option("--threads", a->threads, "worker threads (default: all cores)")->check(kNonNegative);
  cmd->add_option("--json", a->json, "also write the table as JSON to this file (its folder made if missing; checked before any case runs)");
  cmd->add_option("--dir", a->dir, "folder of the cases (default: ncprograms)");
  cmd->add_option("--voxel", a->voxel, "voxel size for every case, mm (default: each job's own)")
      ->check(kPositive);
  cmd->add_option("--band-every", a->band_every,
                  "one more untimed run per case counts the voxels the moves' bands reach, one voxel at a time in "
                  "1 leaf in N (default 1: all; 0: no count, no update-to-kernel ratio)")
      ->check(kNonNegative);

  return [a]() -> int {
    if (!fs::is_directory(a->dir)) throw InputError(a->dir, "no such folder of cases");
    std::vector<std::string> cases = a->cases;
    if (cases.empty()) {
      for (const auto& e : fs::directory_iterator(a->dir))
        if (e.path().extension() == ".nc" && fs::exists(fs::path(e.path()).replace_extension(".toml")))
          cases.push_back(e.path().stem().string());
      std::sort(cases.begin(), cases.end());
    }
    // Each case's goals ([bench] in its job), read before any case runs:
    // a job the runs would refuse is refused here, at its line.
    std::vector<io::BenchGoals> goals;
    for (const auto& c : cases) {
      const fs::path nc = fs::path(a->dir) / (c + ".nc");
      if (!fs::exists(nc)) throw InputError(nc.string(), "no such case (its program is missing)");
      const fs::path job = fs::path(nc).replace_extension(".toml");
      if (!fs::exists(job)) throw InputError(nc.string(), "the case has no job file beside it");
      goals.push_back(io::load_job(job.string()).bench.value_or(io::BenchGoals{}));
    }
    // The JSON's place, made ready before any case runs (a bench takes
    // minutes): its folder created if missing, the file written beside it
    // under a temporary name and renamed into place only when every case
    // has run. A run that fails leaves neither.
    std::optional<io::OutputDirectory> json_dir;
    std::optional<io::AtomicFile> json_file;
    if (!a->json.empty()) {
      std::error_code ec;
      if (fs::is_directory(a->json, ec)) throw OutputError(a->json, "is a directory, not a file for the JSON");
      if (const fs::path parent = fs::path(a->json).parent_path(); !parent.empty()) json_dir.emplace(parent.string());
      json_file.emplace(a->json);
    }
    const int threads = a->threads > 0 ? a->threads : static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
    // The kernel, measured before each timed run (the machine's speed
    // drifts by some 10 % over minutes, and a case's runs take minutes): a
    // case's ratio is to the median of its runs' kernels.
    auto kernel_now = [threads] {
      tbb::global_control gc(tbb::global_control::max_allowed_parallelism, static_cast<std::size_t>(threads));
      return kernel_rate(threads);
    };
    const double kernel0 = kernel_now();
    const std::string exe = fs::read_symlink("/proc/self/exe").string();
    char tmpl[] = "/tmp/cutsim-bench-out-XXXXXX";
    const char* od = ::mkdtemp(tmpl);
    if (!od) throw OutputError("/tmp", "cannot create a temporary directory");
    const std::string outdir = od;
    // (Removed however the bench ends.)
    struct RemoveAll {
      std::string dir;
      ~RemoveAll() {
        std::error_code ec;
        fs::remove_all(dir, ec);
      }
    } remove_outdir{outdir};

    nlohmann::ordered_json rows = nlohmann::ordered_json::array();
    std::vector<std::pair<std::string, std::string>> goal_lines;  // (case, its goals' line)
    std::vector<std::pair<std::string, std::string>> phase_lines;  // (case, its phases' line)
    // (The runs inherit this process's GLIBC_TUNABLES, and with it malloc's pages.)
    const bool huge = malloc_huge_pages();
    const std::string stock_pages =
        huge ? "; a stock grid under " + fmt_g(static_cast<double>(kStockHugePagesFrom) / (1u << 30)) + " GiB, 4 KB pages"
             : "";
    std::printf("kernel: %.3g voxel updates/s on %d thread%s (ball-end distance, max, write back, in cache; "
                "measured again before each run, /kern is to the case's median)\n"
                "malloc: %s%s\n",
                kernel0, threads, threads == 1 ? "" : "s",
                huge ? "transparent huge pages (glibc.malloc.hugetlb=1)" : "4 KB pages",
                stock_pages.c_str());
    std::printf("%-20s %8s %8s %8s %12s %8s %7s %9s %10s %10s %6s %6s %11s %11s %11s %8s %6s\n", "case", "blocks",
                "moves", "voxel_um", "active_vox", "wall_s", "rss_MB", "moves/s", "eval/s", "vox_upd/s", "/kern", "eval%",
                "removed_mm3", "over_mm3", "under_mm3", "contacts", "axis");
    for (const auto& c : cases) {
      const std::string nc = (fs::path(a->dir) / (c + ".nc")).string();
      std::vector<double> walls, sims, upds, kernels;
      std::map<std::string, std::vector<double>> phases;  // the report's timing_s, by phase
      double rss = 0;
      bool same = true;  // every repeat gave the results of the first
      nlohmann::json rep, first;
      double band = 0;  // voxels the moves' bands reach, from the counting run
      const int runs = a->repeat + (a->band_every > 0 ? 1 : 0);
      for (int r = 0; r < runs; ++r) {
        const bool counting = r == a->repeat;  // last, untimed: its counting costs more than the update
        if (!counting) kernels.push_back(kernels.empty() && &c == &cases.front() ? kernel0 : kernel_now());
        std::string out, err;
        const int code = run_child(quote(exe) + " run " + quote(nc) + " --format json --threads " +
                                       std::to_string(threads) +
                                       (a->voxel > 0 ? " --voxel " + fmt_g(a->voxel) : std::string()) +
                                       (counting ? " --measure-band " + std::to_string(a->band_every) : std::string()) +
                                       " -o " + quote(outdir),
                                   out, err);
        if (code != 0 && code != 1) {
          throw Error(static_cast<ExitCode>(code > 0 ? code : 70), SourceLocation{nc, 0, 0, {}},
                      "case " + c + " failed (exit " + std::to_string(code) + "): " + err);
        }
        if (counting) {
          const nlohmann::json cr = nlohmann::json::parse(out);
          band = cr.value("band_voxels", 0.0);
          same = same && cr["removed_volume_mm3"] == first["removed_volume_mm3"];
          continue;
        }
        rep = nlohmann::json::parse(out);
        walls.push_back(rep["timing_s"]["total"].get<double>());
        sims.push_back(rep["timing_s"]["simulate"].get<double>());
        upds.push_back(rep["timing_s"]["stock_update"].get<double>());
        for (const char* k : kPhases)
          if (rep["timing_s"].contains(k)) phases[k].push_back(rep["timing_s"][k].get<double>());
        rss = std::max(rss, rep["peak_rss_mb"].get<double>());
        if (r == 0) first = rep;
        else
          same = same && rep["removed_volume_mm3"] == first["removed_volume_mm3"] && rep["contacts"] == first["contacts"] &&
                 rep.value("overcut_volume_mm3", 0.0) == first.value("overcut_volume_mm3", 0.0) &&
                 rep.value("undercut_volume_mm3", 0.0) == first.value("undercut_volume_mm3", 0.0);
      }
      // Times are medians of the repeats (each on its own); the memory is
      // the largest any repeat needed.
      auto median = [](std::vector<double> v) {
        std::sort(v.begin(), v.end());
        return v[v.size() / 2];
      };
      const double wall = median(walls);
      const double sim_s = median(sims);
      const double upd_s = median(upds);
      const double kernel = median(kernels);
      if (!same) std::fprintf(stderr, "cutsim bench: warning: case %s gave different results in its repeats\n", c.c_str());
      const double evals = rep.value("voxel_evaluations", 0.0);
      const double moves = rep["moves"].get<double>();
      const double eps = upd_s > 0 ? evals / upd_s : 0;
      // The update's rate: the voxels the moves' bands reach, each of which a
      // plain update would evaluate, over the update's seconds.
      const double vps = upd_s > 0 ? band / upd_s : 0;
      nlohmann::ordered_json row;
      row["case"] = c;
      row["blocks"] = rep["blocks"];
      row["moves"] = rep["moves"];
      row["voxel_mm"] = rep["voxel_size_mm"];
      row["active_voxels"] = rep["active_voxels"];
      row["wall_s"] = wall;
      row["repeats"] = a->repeat;
      row["peak_rss_mb"] = rss;
      row["moves_per_s"] = sim_s > 0 ? moves / sim_s : 0;
      row["stock_update_s"] = upd_s;
      {
        // Where the time goes, each phase's median over the repeats (so
        // they need not add up to the wall time's median).
        nlohmann::ordered_json ph = nlohmann::ordered_json::object();
        std::string line;
        for (const char* k : kPhases) {
          if (!phases.count(k)) continue;
          const double v = median(phases[k]);
          ph[k] = v;
          char buf[64];
          std::snprintf(buf, sizeof buf, "%s%s %.2f", line.empty() ? "" : ", ", k, v);
          line += buf;
        }
        row["phases_s"] = ph;
        phase_lines.emplace_back(c, line);
      }
      row["voxel_evaluations"] = evals;
      row["evaluations_per_s"] = eps;
      row["band_voxels"] = band;
      row["band_every"] = a->band_every;
      row["voxel_updates_per_s"] = vps;
      row["kernel_updates_per_s"] = kernel;
      row["malloc_huge_pages"] = huge;
      row["stock_page_kb"] = rep.value("stock_page_kb", 4);
      // The figures against the case's goals: in the row, and as a line
      // printed after the table.
      {
        const io::BenchGoals& g = goals[static_cast<std::size_t>(&c - cases.data())];
        nlohmann::ordered_json gj = nlohmann::ordered_json::object();
        std::string line;
        auto against = [&](const char* figure, const char* name, const char* unit, int digits, double value, double goal,
                           bool at_most) {
          const bool met = at_most ? value <= goal : value >= goal;
          // How far off: the factor the figure must improve by (1 or less: met).
          const double factor =
              at_most ? value / goal : (value > 0 ? goal / value : std::numeric_limits<double>::infinity());
          nlohmann::ordered_json e;
          e["value"] = value;
          e["goal"] = goal;
          e["at_most"] = at_most;
          e["met"] = met;
          e["factor"] = factor;
          gj[figure] = e;
          char buf[200];
          std::snprintf(buf, sizeof buf, "%s%s %.*f%s (%s %.*f%s): ", line.empty() ? "" : "; ", name, digits, value, unit,
                        at_most ? "at most" : "at least", digits, goal, unit);
          line += buf;
          if (met) {
            line += "met";
          } else {
            std::snprintf(buf, sizeof buf, "not met, %.2fx off", factor);
            line += buf;
          }
        };
        if (g.max_wall_s) against("wall_s", "wall", " s", 2, wall, *g.max_wall_s, true);
        if (g.max_rss_mb) against("peak_rss_mb", "peak RSS", " MB", 0, rss, *g.max_rss_mb, true);
        if (g.min_moves_per_s)
          against("moves_per_s", "moves/s", "", 0, row["moves_per_s"].get<double>(), *g.min_moves_per_s, false);
        if (!gj.empty()) {
          row["goals"] = gj;
          goal_lines.emplace_back(c, line);
        }
      }
      row["update_to_kernel"] = kernel > 0 ? vps / kernel : 0;
      row["evaluated_fraction"] = band > 0 ? evals / band : 0;
      row["removed_mm3"] = rep["removed_volume_mm3"];
      row["overcut_mm3"] = rep.value("overcut_volume_mm3", 0.0);
      row["undercut_mm3"] = rep.value("undercut_volume_mm3", 0.0);
      row["contacts"] = rep["contacts"].size();
      row["axis_limit_violations"] = rep["axis_limit_violations"].size();
      row["threads"] = threads;
      row["repeats_agree"] = same;
      rows.push_back(row);
      // Without the band's count (--band-every 0, or nothing cut) its columns say "-".
      char upd[32] = "-", ratio[32] = "-", share[32] = "-";
      if (band > 0) {
        std::snprintf(upd, sizeof upd, "%.3g", vps);
        std::snprintf(ratio, sizeof ratio, "%.2f", row["update_to_kernel"].get<double>());
        std::snprintf(share, sizeof share, "%.1f", 100 * row["evaluated_fraction"].get<double>());
      }
      std::printf("%-20s %8d %8d %8.3g %12lld %8.3f %7.0f %9.0f %10.3g %10s %6s %6s %11.6g %11.4g %11.4g %8zu %6zu\n",
                  c.c_str(), rep["blocks"].get<int>(), rep["moves"].get<int>(), rep["voxel_size_mm"].get<double>() * 1000,
                  rep["active_voxels"].get<long long>(), wall, rss, row["moves_per_s"].get<double>(), eps, upd, ratio, share,
                  rep["removed_volume_mm3"].get<double>(), row["overcut_mm3"].get<double>(),
                  row["undercut_mm3"].get<double>(), rep["contacts"].size(), rep["axis_limit_violations"].size());
      std::fflush(stdout);
    }
    // The goals the cases' jobs set, one line a case.
    if (!goal_lines.empty()) std::printf("goals ([bench] in each case's job):\n");
    for (const auto& [name, line] : goal_lines) std::printf("  %-18s %s\n", name.c_str(), line.c_str());
    std::printf("phases (s, medians of the repeats):\n");
    for (const auto& [name, line] : phase_lines) std::printf("  %-18s %s\n", name.c_str(), line.c_str());
    if (json_file) {
      const std::string text = rows.dump(2) + "\n";
      json_file->write(text.data(), text.size());
      json_file->commit();
    }
    return 0;
  };
}

}  // namespace cutsim::app
