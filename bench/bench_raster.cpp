// Times the ball-end raster case: one parseable line per run of the case.
//   bench_raster --voxel 0.01 --repeat 5
// prints: case=raster voxel_mm=... moves=... active_voxels=... seconds=...
//         moves_per_s=... peak_rss_mb=...   (seconds: median of the repeats,
// simulate phase: stock build and all cuts, no export)
#include <CLI/CLI.hpp>
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <unistd.h>
#include <vector>

#include "cutsim/sim/simulate.h"

int main(int argc, char** argv) {
  CLI::App app{"cutsim raster benchmark"};
  double voxel = 0.01;
  int repeat = 5;
  double pick = 0.05, width = 4.0;
  app.add_option("--voxel", voxel, "voxel size, mm");
  app.add_option("--repeat", repeat, "runs; the median is printed");
  app.add_option("--pick", pick, "pick feed, mm");
  app.add_option("--width", width, "side of the square rastered area, mm");
  CLI11_PARSE(app, argc, argv);

  // Zig-zag raster of a 1 mm ball end mill, 0.05 mm deep, over width^2.
  const std::string path = std::filesystem::temp_directory_path() / ("cutsim-bench-raster-" + std::to_string(::getpid()) + ".nc");
  {
    std::ofstream out(path);
    out << "G21 G90 G17\nG0 X0 Y0 Z1\nG1 Z-0.05 F200\n";
    const int passes = static_cast<int>(width / pick) + 1;
    for (int i = 0; i < passes; ++i) {
      out << "G1 X" << (i % 2 == 0 ? width : 0.0) << " F1000\n";
      if (i + 1 < passes) out << "G1 Y" << (i + 1) * pick << "\n";
    }
    out << "G0 Z1\nM30\n";
  }
  cutsim::sim::SimOptions opt;
  opt.program = path;
  opt.tool = cutsim::tool::parse_tool_spec("ball:d=1");
  opt.stock_box = cutsim::Aabb{cutsim::Vec3(-1, -1, -1), cutsim::Vec3(width + 1, width + 1, 0)};
  opt.voxel_mm = voxel;
  std::vector<double> secs;
  int moves = 0;
  std::size_t active = 0;
  for (int r = 0; r < repeat; ++r) {
    auto res = cutsim::sim::simulate(opt);
    secs.push_back(res.timing.simulate_s);
    moves = res.moves;
    active = res.stock->stats().active_voxels;
  }
  std::filesystem::remove(path);
  std::sort(secs.begin(), secs.end());
  const double med = secs[secs.size() / 2];
  std::printf("case=raster voxel_mm=%g moves=%d active_voxels=%zu seconds=%.3f moves_per_s=%.0f peak_rss_mb=%.0f\n",
              voxel, moves, active, med, moves / med, cutsim::sim::peak_rss_mb());
  return 0;
}
