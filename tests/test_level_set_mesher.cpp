// The stock's own mesher (level_set_mesher.h), on level sets whose surface
// is known: closed, facing out, where the level set says, merged where
// flat, and the same whatever the threads.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>
#include <random>

#include <openvdb/tools/LevelSetSphere.h>
#include <tbb/global_control.h>

#include "cutsim/stock/level_set_mesher.h"
#include "helpers.h"

namespace cutsim::test {
namespace {

using stock::LevelSetMesh;
using stock::mesh_level_set;

::testing::AssertionResult closed(const LevelSetMesh& m) { return edges_matched(m); }

double volume(const LevelSetMesh& m) {
  double v = 0;
  for (const auto& t : m.triangles) v += m.points[t[0]].dot(m.points[t[1]].cross(m.points[t[2]]));
  return v / 6.0;
}

TEST(LevelSetMesher, SphereIsClosedOutwardAndOnTheSurface) {
  const double r = 20.0;  // voxels
  const Vec3 c(3.3, -7.6, 11.2);
  auto grid = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(static_cast<float>(r), openvdb::Vec3f(3.3f, -7.6f, 11.2f),
                                                                      1.0f, 3.0f);
  const LevelSetMesh m = mesh_level_set(grid->tree(), 0.0);
  ASSERT_GT(m.triangles.size(), 1000u);
  EXPECT_TRUE(closed(m));
  EXPECT_EQ(m.merged_cells, 0u);
  // A point per cell, each the mean of its crossings of the (linearly
  // interpolated) distance: within a few hundredths of a voxel of the
  // sphere at this radius.
  double worst = 0;
  for (const Vec3& p : m.points) worst = std::max(worst, std::fabs((p - c).norm() - r));
  EXPECT_LT(worst, 0.05);
  // Normals outward along the radius: the gradient at the cell's centre,
  // at most half a voxel's diagonal from the point (1/46 rad here).
  ASSERT_EQ(m.normals.size(), m.points.size());
  double least_dot = 1;
  for (std::size_t i = 0; i < m.points.size(); ++i) {
    EXPECT_NEAR(m.normals[i].norm(), 1.0f, 1e-5f);
    least_dot = std::min(least_dot, m.normals[i].cast<double>().dot((m.points[i] - c).normalized()));
  }
  EXPECT_GT(least_dot, 0.999);
  // Outward (positive) volume, the sphere's less the chords' caps.
  const double exact = 4.0 / 3.0 * std::numbers::pi * r * r * r;
  EXPECT_LT(volume(m), exact);
  EXPECT_GT(volume(m), exact * (1 - 3e-3));
}

TEST(LevelSetMesher, MergedSphereStaysClosedAndNearTheSurface) {
  // At 60 voxels' radius an 8^3 block's normals span 7.6 degrees, within
  // the default adaptivity: most cells merge, and the triangles between
  // merged points 8 voxels apart sag by their chords (L^2 / 8R, about a
  // quarter voxel) besides the points' own offset. OpenVDB's mesher gives
  // 0.34 voxel here at its worst triangle's centre.
  const double r = 60.0;
  const Vec3 c(0.3, 0.1, 0.2);
  auto grid = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(static_cast<float>(r), openvdb::Vec3f(0.3f, 0.1f, 0.2f),
                                                                      1.0f, 3.0f);
  const LevelSetMesh fine = mesh_level_set(grid->tree(), 0.0);
  const LevelSetMesh m = mesh_level_set(grid->tree(), 0.01);
  EXPECT_TRUE(closed(m));
  EXPECT_GT(m.merged_cells, fine.points.size() / 2);
  EXPECT_LT(m.triangles.size(), fine.triangles.size() / 10);
  double worst = 0;
  for (const auto& t : m.triangles) {
    const Vec3 g = (m.points[t[0]] + m.points[t[1]] + m.points[t[2]]) / 3;
    worst = std::max(worst, std::fabs((g - c).norm() - r));
  }
  EXPECT_LT(worst, 0.4);
  // Every triangle faces out: quads of merged points, far from flat, are
  // split along the diagonal that does not fold.
  std::size_t inward = 0;
  for (const auto& t : m.triangles) {
    const Vec3 f = (m.points[t[1]] - m.points[t[0]]).cross(m.points[t[2]] - m.points[t[0]]);
    if (f.dot(m.points[t[0]] - c) <= 0) ++inward;
  }
  EXPECT_EQ(inward, 0u);
  // A merged point's normal is its cells' mean: within their spread.
  for (std::size_t i = 0; i < m.points.size(); ++i)
    EXPECT_GT(m.normals[i].cast<double>().dot((m.points[i] - c).normalized()), 0.995) << i;
  const double exact = 4.0 / 3.0 * std::numbers::pi * r * r * r;
  EXPECT_NEAR(volume(m), exact, 0.012 * exact);
}

TEST(LevelSetMesher, AdaptivityMergesTheFlatFacesAndStaysClosed) {
  // A box 24 x 16 x 12 voxels from -0.5 (cell-centred faces), its exact
  // distance in a dense band of leaves.
  openvdb::FloatGrid::Ptr grid = openvdb::FloatGrid::create(3.0f);
  auto acc = grid->getAccessor();
  const Vec3 lo(-0.5, -0.5, -0.5), hi(23.5, 15.5, 11.5);
  for (int x = -8; x < 32; ++x)
    for (int y = -8; y < 24; ++y)
      for (int z = -8; z < 24; ++z) {
        const Vec3 p(x, y, z);
        const Vec3 q = (p - 0.5 * (lo + hi)).cwiseAbs() - 0.5 * (hi - lo);
        const double d = q.cwiseMax(0.0).norm() + std::min(q.maxCoeff(), 0.0);
        acc.setValue(openvdb::Coord(x, y, z), static_cast<float>(std::clamp(d, -3.0, 3.0)));
      }
  const LevelSetMesh fine = mesh_level_set(grid->tree(), 0.0);
  const LevelSetMesh coarse = mesh_level_set(grid->tree(), 0.01);
  EXPECT_TRUE(closed(fine));
  EXPECT_TRUE(closed(coarse));
  // The flat faces are exact. At the box's sharp edges the cells' means
  // cut the corner a quarter voxel deep (0.24 voxel^2 per voxel of edge,
  // as OpenVDB's mesher does); the merged faces' wider triangles meet the
  // edges' points farther back, about doubling that.
  const double exact = 24.0 * 16 * 12, edges = 4.0 * (24 + 16 + 12);
  EXPECT_LT(volume(fine), exact);
  EXPECT_GT(volume(fine), exact - 0.3 * edges);
  EXPECT_LT(volume(coarse), volume(fine));
  EXPECT_GT(volume(coarse), volume(fine) - 0.4 * edges);
  EXPECT_GT(coarse.merged_cells, 0u);
  EXPECT_LT(coarse.triangles.size(), fine.triangles.size() / 3);
  // Away from the box's edges every point, merged or not, is on a face:
  // a merged one is the mean of its cells' points on that face's plane.
  // (Near an edge the cells' means cut the corner.)
  std::size_t on_faces = 0;
  for (const Vec3& p : coarse.points) {
    std::array<double, 6> d = {p.x() - lo.x(), hi.x() - p.x(), p.y() - lo.y(), hi.y() - p.y(), p.z() - lo.z(), hi.z() - p.z()};
    for (double& x : d) x = std::fabs(x);
    std::sort(d.begin(), d.end());
    if (d[1] < 1.0) continue;
    EXPECT_LT(d[0], 1e-9) << p.transpose();
    ++on_faces;
  }
  EXPECT_GT(on_faces, coarse.points.size() / 4);
}

TEST(LevelSetMesher, MeshesEdgesBetweenALeafAndATile) {
  // One leaf of material (below z = 3.5) in air that is only tiles and
  // background: every sign change has one end in a tile, and the cells
  // whose first corner lies in a tile must close the surface.
  openvdb::FloatGrid::Ptr grid = openvdb::FloatGrid::create(1.0f);
  grid->tree().fill(openvdb::CoordBBox(openvdb::Coord(-64), openvdb::Coord(63)), 1.0f, false);  // air tiles
  auto acc = grid->getAccessor();
  for (int x = 0; x < 8; ++x)
    for (int y = 0; y < 8; ++y)
      for (int z = 0; z < 8; ++z) acc.setValue(openvdb::Coord(x, y, z), static_cast<float>(std::min(z - 3.5, 1.0)));
  ASSERT_EQ(grid->tree().leafCount(), 1u);
  const LevelSetMesh m = mesh_level_set(grid->tree(), 0.0);
  EXPECT_TRUE(closed(m));
  // The surface lies between the material's last voxels and the tiles'
  // first: x and y in (-1, 0) and (7, 8), z in (-1, 0) and 3.5.
  Vec3 lo = m.points.front(), hi = lo;
  for (const Vec3& p : m.points) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  EXPECT_GT(lo.x(), -1);
  EXPECT_LT(lo.x(), 0);
  EXPECT_GT(hi.x(), 7);
  EXPECT_LT(hi.x(), 8);
  EXPECT_GT(lo.z(), -1);
  EXPECT_LT(lo.z(), 0);
  EXPECT_NEAR(hi.z(), 3.5, 1e-9);
  EXPECT_GT(volume(m), 8.0 * 8 * 4);  // the voxels' cubes, and some of the way to their air neighbours
  EXPECT_LT(volume(m), 10.0 * 10 * 5);
}

TEST(LevelSetMesher, NoiseStaysClosedAndTheSameOnAnyThreads) {
  // Random values over several leaves (many ambiguous cells, thin
  // sheets), air around them: closed whether merged or not, and the same
  // points and triangles on one thread as on all.
  openvdb::FloatGrid::Ptr grid = openvdb::FloatGrid::create(1.0f);
  auto acc = grid->getAccessor();
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  for (int x = 0; x < 24; ++x)
    for (int y = 0; y < 16; ++y)
      for (int z = 0; z < 16; ++z) {
        // Smooth-ish below, noise above: some merges, some refusals.
        const float v = z < 8 ? static_cast<float>(z) - 4.3f + 0.02f * u(rng) : u(rng);
        acc.setValue(openvdb::Coord(x, y, z), v);
      }
  for (double adaptivity : {0.0, 0.01, 0.5}) {
    LevelSetMesh one;
    {
      tbb::global_control gc(tbb::global_control::max_allowed_parallelism, 1);
      one = mesh_level_set(grid->tree(), adaptivity);
    }
    const LevelSetMesh all = mesh_level_set(grid->tree(), adaptivity);
    EXPECT_TRUE(closed(all)) << "adaptivity " << adaptivity;
    EXPECT_EQ(one.points, all.points);
    EXPECT_EQ(one.triangles, all.triangles);
    if (adaptivity > 0) {
      EXPECT_GT(all.merged_cells, 0u);
    }
  }
}

}  // namespace
}  // namespace cutsim::test
