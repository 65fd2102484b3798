// Scallop height of a ball-end raster against h = R - sqrt(R^2 - (p/2)^2).
#include <cmath>
#include <sstream>

#include "helpers.h"

namespace cutsim::test {
namespace {

TEST(Scallop, BallRasterCuspHeightMatchesFormula) {
  TempDir dir;
  const double R = 0.5, p = 0.2, h = 0.002, depth = 0.05;
  std::ostringstream prog;
  prog << "G21 G90\nG0 X0 Y0 Z1\n";
  const int passes = 7;
  for (int i = 0; i < passes; ++i) {
    const double y = i * p;
    prog << "G0 X0 Y" << y << "\nG1 Z" << -depth << " F200\nG1 X1.5\nG0 Z1\n";
  }
  auto r = run_program(dir, prog.str(), "ball:d=1", Aabb{Vec3(-1, -1, -1), Vec3(2.5, 2.2, 0)}, h);
  const double expected = R - std::sqrt(R * R - (p / 2) * (p / 2));
  ASSERT_GT(expected, 4 * h) << "the scallop must span several voxels";
  // Between the inner passes: valleys on the pass lines, cusps half way.
  for (int i = 2; i < passes - 2; ++i) {
    const double valley = r.stock->surface_height(0.75, i * p, 0.5);
    const double cusp = r.stock->surface_height(0.75, (i + 0.5) * p, 0.5);
    EXPECT_NEAR(valley, -depth, 0.1 * h);
    EXPECT_NEAR(cusp - valley, expected, 0.25 * h) << "between passes " << i << " and " << i + 1;
  }
}

}  // namespace
}  // namespace cutsim::test
