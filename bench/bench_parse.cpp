// Parser throughput on a program of N blocks of `G1 X.. Y.. Z..` with six
// decimals: reader (lexing, parameters, control flow) plus the modal
// interpreter, one core; beside it `wc -l` on the same file in the same run.
//   bench_parse --blocks 1000000 --repeat 5
// prints: case=parse blocks=... bytes=... seconds=... mb_per_s=...
//         wc_seconds=... ratio_to_wc=... peak_rss_mb=...
#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>
#include <unistd.h>

#include "cutsim/sim/simulate.h"

int main(int argc, char** argv) {
  CLI::App app{"cutsim parser benchmark"};
  long blocks = 1000000;
  int repeat = 5;
  std::string keep;
  app.add_option("--blocks", blocks, "program length");
  app.add_option("--repeat", repeat, "runs; the median is printed");
  app.add_option("--file", keep, "write the program here and keep it");
  CLI11_PARSE(app, argc, argv);

  const std::string path = keep.empty() ? (std::filesystem::temp_directory_path() /
                                           ("cutsim-bench-parse-" + std::to_string(::getpid()) + ".nc")).string()
                                        : keep;
  {
    std::ofstream out(path);
    std::mt19937_64 rng(1);
    std::uniform_real_distribution<double> u(-50, 50);
    out << "G21 G90 G17\nG0 X0 Y0 Z1\nG1 F1000\n";
    char buf[128];
    for (long i = 0; i < blocks; ++i) {
      const int n = std::snprintf(buf, sizeof buf, "G1 X%.6f Y%.6f Z%.6f\n", u(rng), u(rng), u(rng) / 50);
      out.write(buf, n);
    }
    out << "M30\n";
  }
  const double bytes = static_cast<double>(std::filesystem::file_size(path));
  using Clock = std::chrono::steady_clock;
  std::vector<double> secs, wc;
  long moves = 0;
  for (int r = 0; r < repeat; ++r) {
    auto t0 = Clock::now();
    const std::string cmd = "wc -l " + path + " >/dev/null";
    if (std::system(cmd.c_str()) != 0) return 1;
    wc.push_back(std::chrono::duration<double>(Clock::now() - t0).count());
    t0 = Clock::now();
    moves = 0;
    cutsim::sim::check_program(path, {}, {}, [&](const cutsim::motion::Move&) { ++moves; });
    secs.push_back(std::chrono::duration<double>(Clock::now() - t0).count());
  }
  if (keep.empty()) std::filesystem::remove(path);
  std::sort(secs.begin(), secs.end());
  std::sort(wc.begin(), wc.end());
  const double s = secs[secs.size() / 2], w = wc[wc.size() / 2];
  std::printf("case=parse blocks=%ld moves=%ld bytes=%.0f seconds=%.3f mb_per_s=%.1f wc_seconds=%.3f ratio_to_wc=%.1f peak_rss_mb=%.0f\n",
              blocks, moves, bytes, s, bytes / s / 1e6, w, s / w, cutsim::sim::peak_rss_mb());
  return 0;
}
