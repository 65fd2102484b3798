// Case 5 (CASES.md, seeds/003): the 4-axis face experiment with
// dy_AY = -0.50 mm, and its target: both faces where an error-free machine
// puts them.
#include <algorithm>
#include <cmath>

#include "cases_impl.h"

namespace cutsim::cases {
namespace {

// The nominal part in the workpiece frame: the 20 x 48 x 12 block less the
// two side-milled regions (6 mm flat end mill, centre at y = -25, faces at
// y = -22): z >= -5 up to x = 9 (then the tool's round end), and, cut at A180,
// z <= 5 from x = 11 down. Material spans y from y_lo(x, z) to 24.
double y_lo(double x, double z) {
  double y = -24;
  auto cut = [&](double end_dx) {
    if (end_dx <= 0) return -22.0;
    if (end_dx >= 3) return -24.0;
    return std::max(-24.0, -25 + std::sqrt(9 - end_dx * end_dx));
  };
  if (z >= -5) y = std::max(y, cut(x - 9));
  if (z <= 5) y = std::max(y, cut(11 - x));
  return y;
}

}  // namespace

std::vector<File> fouraxis_files() {
  const std::string program =
      "(Reference case 5, seeds/003: assembly error of a 4-axis machine)\n"
      "(Side milling with a 6 mm flat end mill on the xyza machine: a face cut)\n"
      "(at A0 with the tool at Y-25, then one at A180 with the tool at Y+25,)\n"
      "(each on its own stretch of X. With dy_AY = -0.50 mm in the job the two)\n"
      "(faces end up 2 |dy| = 1.00 mm apart; without it they line up.)\n"
      "G21 G90 G94\n"
      "G0 X-4 Y-25 Z20 A0\n"
      "G0 Z-5\n"
      "G1 X9 F300\n"
      "G0 Z20\n"
      "G0 A180\n"
      "G0 X11 Y25 Z20\n"
      "G1 Z-5 F300\n"
      "G1 X24\n"
      "G0 Z20\n"
      "M30\n";
  const std::string job =
      "# Reference case 5 (CASES.md, seeds/003): the 4-axis face experiment.\n"
      "[stock]\n"
      "box = [0, -24, -6, 20, 24, 6]      # 20 x 48 x 12 mm block on the A axis\n"
      "\n"
      "[tool]\n"
      "spec = \"flat:d=6,l=12\"\n"
      "\n"
      "[machine]\n"
      "name = \"xyza\"\n"
      "\n"
      "[machine.errors]\n"
      "A = \"dy=-0.5\"                      # dy_AY of seeds/003 eq. 2, mm\n"
      "\n"
      "[simulation]\n"
      "voxel_mm = 0.05\n"
      "start = [-4, -25, 20]\n"
      "\n[target]\nfile = \"../models/cases/fouraxis_faces.ply\"   # both faces at y = -22, as without the error\n"
      "tolerance_mm = 0.01\n";
  // A height field in -y over (x, z), mapped (u, v, w) -> (u, -w, v), which keeps the orientation.
  std::vector<double> xs, zs;
  for (int i = 0; i <= 400; ++i) xs.push_back(0.05 * i);
  for (int i = 0; i <= 240; ++i) {
    const double z = -6 + 0.05 * i;
    if (std::abs(std::abs(z) - 5) > 1e-9) {
      zs.push_back(z);
      continue;
    }
    // The steps at z = -5 and +5: two rows 0.1 um apart, a near-vertical wall.
    zs.push_back(z < 0 ? -5.00005 : 4.99995);
    zs.push_back(z < 0 ? -4.99995 : 5.00005);
  }
  TriMesh m = height_field_solid(xs, zs, [](double x, double z) { return -y_lo(x, z); }, -24);
  for (Vec3& p : m.positions) p = Vec3(p.x(), -p.z(), p.y());
  return {{"ncprograms/fouraxis_faces.nc", program, true},
          {"ncprograms/fouraxis_faces.toml", job, true},
          {"models/cases/fouraxis_faces.ply", ply_binary(m), false}};
}

}  // namespace cutsim::cases
