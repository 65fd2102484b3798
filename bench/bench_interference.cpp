// Interference checking against material removal on a snowflake-size
// raster: a 90 deg V tool planing 8 um pick-feed lines 10 um deep over a
// square the size of the snowflake (0.64 mm), one direction, lifting
// between lines (CASES.md 1).
//   bench_interference --voxel 0.0005 --repeat 5 [--layers 2]
// prints: case=vraster ... update_s=... check_s=... ratio=...
// (medians of the repeats; ratio = contact check / stock update)
#include <CLI/CLI.hpp>
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <unistd.h>
#include <vector>

#include "cutsim/sim/simulate.h"

int main(int argc, char** argv) {
  CLI::App app{"cutsim interference benchmark"};
  double voxel = 0.0005, side = 0.64, pick = 0.008, depth = 0.010;
  int repeat = 5, layers = 2;
  std::string tool = "vtool:angle=90,clearance=7";
  app.add_option("--voxel", voxel, "voxel size, mm");
  app.add_option("--repeat", repeat, "runs; the median is printed");
  app.add_option("--side", side, "side of the rastered square, mm");
  app.add_option("--layers", layers, "layers of 10 um");
  app.add_option("--tool", tool, "tool spec");
  CLI11_PARSE(app, argc, argv);

  const std::string path =
      std::filesystem::temp_directory_path() / ("cutsim-bench-vraster-" + std::to_string(::getpid()) + ".nc");
  int lines = 0;
  {
    std::ofstream out(path);
    out << "G21 G90 G17\n";
    for (int l = 1; l <= layers; ++l)
      for (double y = 0; y <= side + 1e-9; y += pick, ++lines)
        out << "G0 X-0.05 Y" << y << " Z0.01\nG1 Z" << -l * depth << " F100\nG1 X" << side + 0.05 << "\nG0 Z0.01\n";
    out << "M30\n";
  }
  cutsim::sim::SimOptions opt;
  opt.program = path;
  opt.tool = cutsim::tool::parse_tool_spec(tool);
  opt.stock_box = cutsim::Aabb{cutsim::Vec3(0, -0.02, -0.2), cutsim::Vec3(side, side + 0.02, 0)};
  opt.voxel_mm = voxel;
  std::vector<double> upd, chk, tot;
  std::size_t contacts = 0;
  for (int r = 0; r < repeat; ++r) {
    auto res = cutsim::sim::simulate(opt);
    upd.push_back(res.timing.stock_update_s);
    chk.push_back(res.timing.contact_check_s);
    tot.push_back(res.timing.simulate_s);
    contacts = res.contacts.size();
  }
  std::filesystem::remove(path);
  auto median = [](std::vector<double> v) {
    std::sort(v.begin(), v.end());
    return v[v.size() / 2];
  };
  const double u = median(upd), c = median(chk);
  std::printf("case=vraster voxel_mm=%g lines=%d contacts=%zu simulate_s=%.3f update_s=%.3f check_s=%.3f ratio=%.2f "
              "peak_rss_mb=%.0f\n",
              voxel, lines, contacts, median(tot), u, c, c / u, cutsim::sim::peak_rss_mb());
  return 0;
}
