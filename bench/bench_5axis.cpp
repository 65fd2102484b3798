// Simultaneous 5-axis finishing on the xyzbc machine: a 1 mm ball end mill
// under G43.4 sweeps a 4 x 4 mm patch in X while B swings between -20 and
// +20 deg and C turns, so every move is sampled. Prints the time spent in
// kinematics and sweep sampling beside the stock update.
//   bench_5axis --voxel 0.005 --repeat 5
#include <CLI/CLI.hpp>
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <unistd.h>
#include <vector>

#include "cutsim/sim/simulate.h"

int main(int argc, char** argv) {
  CLI::App app{"cutsim 5-axis benchmark"};
  double voxel = 0.005;
  int repeat = 5, passes = 20;
  app.add_option("--voxel", voxel, "voxel size, mm");
  app.add_option("--repeat", repeat, "runs; medians are printed");
  app.add_option("--passes", passes, "raster passes");
  CLI11_PARSE(app, argc, argv);

  const std::string path = std::filesystem::temp_directory_path() / ("cutsim-bench-5axis-" + std::to_string(::getpid()) + ".nc");
  int moves = 0;
  {
    std::ofstream out(path);
    out << "G21 G90\nG0 X-2 Y-2 Z1 B0 C0\nG43.4 H1\n";
    for (int i = 0; i < passes; ++i) {
      const double y = -2 + 4.0 * i / std::max(1, passes - 1);
      out << "G0 X-2 Y" << y << " Z1\nG1 Z-0.05 F300\n";
      for (int k = 1; k <= 10; ++k) {
        const double x = -2 + 0.4 * k;
        out << "G1 X" << x << " B" << 20 * ((k % 2) ? 1 : -1) << " C" << (i * 10 + k) * 3 << " F300\n";
        ++moves;
      }
      out << "G0 Z1\n";
    }
    out << "G49\nM30\n";
  }
  cutsim::sim::SimOptions opt;
  opt.program = path;
  opt.dialect = cutsim::gcode::Dialect::fanuc;
  opt.machine = "xyzbc";
  opt.tool = cutsim::tool::parse_tool_spec("ball:d=1");
  opt.stock_box = cutsim::Aabb{cutsim::Vec3(-3, -3, -1), cutsim::Vec3(3, 3, 0)};
  opt.voxel_mm = voxel;
  std::vector<double> total, plan, update, build;
  for (int r = 0; r < repeat; ++r) {
    auto res = cutsim::sim::simulate(opt);
    total.push_back(res.timing.simulate_s);
    plan.push_back(res.timing.plan_sweep_s);
    update.push_back(res.timing.stock_update_s);
    build.push_back(res.timing.stock_build_s);
  }
  std::filesystem::remove(path);
  auto med = [](std::vector<double> v) { std::sort(v.begin(), v.end()); return v[v.size() / 2]; };
  const double t = med(total), p = med(plan), u = med(update), b = med(build);
  std::printf("case=5axis voxel_mm=%g simultaneous_moves=%d simulate_s=%.3f stock_build_s=%.3f plan_and_sweep_s=%.3f "
              "stock_update_s=%.3f plan_and_sweep_share=%.1f%% peak_rss_mb=%.0f\n",
              voxel, moves, t, b, p, u, 100.0 * p / t, cutsim::sim::peak_rss_mb());
  return 0;
}
