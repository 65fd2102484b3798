// The stock's private bounds, tested directly (stock_impl.h).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>

#include "stock_impl.h"

namespace cutsim::test {
namespace {

using LeafPlanes = stock::Stock::Impl::LeafPlanes;
constexpr double kH = 0.01;     // voxel, mm
constexpr float kGamma = 0.03f; // half band, mm

// min over the leaf's voxels short of the band's air edge of
// v(p) + g . (p - c), c the leaf's centre.
double exact_least(const float* v, const Vec3& g) {
  double best = std::numeric_limits<double>::infinity();
  for (int x = 0; x < 8; ++x)
    for (int y = 0; y < 8; ++y)
      for (int z = 0; z < 8; ++z) {
        const float val = v[(x << 6) | (y << 3) | z];
        if (val >= kGamma) continue;
        best = std::min(best, val + g.dot(kH * Vec3(x - 3.5, y - 3.5, z - 3.5)));
      }
  return best;
}

TEST(Stock, LeafPlanesBoundALeafsMaterialUnderEveryPlane) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1, 1);
  float v[512];
  int exact_hits = 0;
  for (int trial = 0; trial < 400; ++trial) {
    // A clamped distance to a random plane or ball, or noise, with some
    // voxels at the band's edges.
    const Vec3 n = Vec3(u(rng), u(rng), u(rng)).normalized(), c = 0.05 * Vec3(u(rng), u(rng), u(rng));
    const int kind = trial % 3;
    for (int i = 0; i < 512; ++i) {
      const Vec3 p = kH * Vec3((i >> 6) - 3.5, ((i >> 3) & 7) - 3.5, (i & 7) - 3.5);
      const double d = kind == 0 ? n.dot(p - c) : kind == 1 ? (p - c).norm() - 0.03 : 0.04 * u(rng);
      v[i] = static_cast<float>(std::clamp(d, -double(kGamma), double(kGamma)));
    }
    const LeafPlanes lp = LeafPlanes::of_leaf(v, kH, kGamma);
    for (int j = 0; j < 50; ++j) {
      Vec3 g = Vec3(u(rng), u(rng), u(rng)).normalized();
      if (j < 6) g = Vec3::Unit(j / 2) * (j % 2 ? -1.0 : 1.0) * (1 + 1e-15);  // past 1 in rounding
      const double bound = lp.least(g, kH), exact = exact_least(v, g);
      ASSERT_LE(bound, exact + 1e-12) << "trial " << trial << " plane " << j;
      exact_hits += bound > exact - 1e-7;
    }
  }
  // Along an axis the bound is the exact least; it is not vacuous.
  EXPECT_GE(exact_hits, 400 * 6 / 2);
}

TEST(Stock, LeafPlanesSeeAFlatFloorUnderAToolAbove) {
  // A machined floor 12 um under the leaf's centre; the tool's plane
  // (distance falling upwards) d(p) = t - (z - c_z): a tool bottom at
  // height t - ... above the floor leaves every voxel, one below does not.
  // The voxels of air at the band's edge must not count, or the bound is
  // 3.5 voxels less than the band's lower.
  float v[512];
  const double floor_z = -0.012;
  for (int i = 0; i < 512; ++i) {
    const double z = kH * ((i & 7) - 3.5);
    v[i] = static_cast<float>(std::clamp(z - floor_z, -double(kGamma), double(kGamma)));
  }
  const LeafPlanes lp = LeafPlanes::of_leaf(v, kH, kGamma);
  const Vec3 down(0, 0, -1);
  EXPECT_NEAR(lp.least(down, kH), 0 - floor_z, 1e-8);  // v - (z - c_z) = c_z - floor
  // All air at the band's edge: nothing there can change.
  std::fill(std::begin(v), std::end(v), kGamma);
  EXPECT_EQ(LeafPlanes::of_leaf(v, kH, kGamma).least(down, kH), std::numeric_limits<double>::infinity());
  EXPECT_EQ(LeafPlanes::of_tile(kGamma, kH, kGamma).least(down, kH), std::numeric_limits<double>::infinity());
  // A material tile: its least is at the top voxels, 3.5 voxels up.
  EXPECT_NEAR(LeafPlanes::of_tile(-kGamma, kH, kGamma).least(down, kH), -kGamma - 3.5 * kH, 1e-8);
}

}  // namespace
}  // namespace cutsim::test
