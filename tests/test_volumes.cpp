// Removed volumes against closed forms, through the whole pipeline.
//
// Tolerance: the stock's surface is the zero level set of a narrow-band
// distance field, recovered by the voxel-coverage integral
// sum clamp(1/2 - phi/h, 0, 1) h^3. For faces that are planes the integral
// is exact; curved faces and the edges where the CSG max() is not a true
// distance move the surface by a small fraction of a voxel. We allow
// 0.05 h per mm^2 of cut surface: |V - V_exact| <= 0.05 * h * A_cut.
#include <algorithm>
#include <atomic>
#include <cmath>
#include <functional>
#include <limits>
#include <map>
#include <mutex>
#include <optional>
#include <tuple>

#include "helpers.h"

namespace cutsim::test {
namespace {

double segment_area(double R, double depth) {
  return R * R * std::acos((R - depth) / R) - (R - depth) * std::sqrt(2 * R * depth - depth * depth);
}

TEST(Volume, BallSlotMatchesClosedForm) {
  TempDir dir;
  const double R = 0.5, depth = 0.2, len = 3.0, h = 0.01;
  auto r = run_program(dir, "G21 G90 G17\nG0 X0 Y0 Z5\nG1 Z-0.2 F100\nG1 X3 F300\nG0 Z5\nM30\n",
                       "ball:d=1", Aabb{Vec3(-2, -2, -2), Vec3(5, 2, 0)}, h);
  // Straight part: circular segment times length; the two rounded ends
  // together form one spherical cap of height `depth`.
  const double exact = segment_area(R, depth) * len + kPi * depth * depth * (3 * R - depth) / 3;
  const double area = 2 * R * std::acos((R - depth) / R) * len + 2 * kPi * R * depth;
  EXPECT_NEAR(r.stock->removed_volume_mm3(), exact, 0.05 * h * area);
  EXPECT_NEAR(r.stock->volume_mm3(), 7 * 4 * 2 - exact, 0.05 * h * area);
  EXPECT_EQ(r.moves, 4);
  EXPECT_EQ(r.cutting_moves, 2);
}

TEST(Volume, FlatSlotMatchesClosedForm) {
  TempDir dir;
  const double R = 1.0, depth = 0.2, len = 3.0, h = 0.01;
  auto r = run_program(dir, "G0 X0 Y0 Z1\nG1 Z-0.2 F100\nG1 X3\nG0 Z1\n",
                       "flat:d=2", Aabb{Vec3(-2, -2, -2), Vec3(5, 2, 0)}, h);
  const double exact = (2 * R * len + kPi * R * R) * depth;
  const double area = (2 * R * len + kPi * R * R) + (2 * len + 2 * kPi * R) * depth;
  EXPECT_NEAR(r.stock->removed_volume_mm3(), exact, 0.05 * h * area);
}

TEST(Volume, FullCircleFlatPocketMatchesClosedForm) {
  TempDir dir;
  // Tool centre on a circle of radius 2 about (0,0): an annulus 1..3 mm.
  const double R = 1.0, rho = 2.0, depth = 0.2, h = 0.01;
  auto r = run_program(dir, "G0 X2 Y0 Z1\nG1 Z-0.2 F100\nG2 X2 Y0 I-2 J0\nG0 Z1\n",
                       "flat:d=2", Aabb{Vec3(-4, -4, -1), Vec3(4, 4, 0)}, h);
  const double ring = kPi * ((rho + R) * (rho + R) - (rho - R) * (rho - R));
  const double exact = ring * depth;
  const double area = ring + 2 * kPi * ((rho + R) + (rho - R)) * depth;
  EXPECT_NEAR(r.stock->removed_volume_mm3(), exact, 0.05 * h * area);
}

TEST(Volume, HalfCircleBallArcMatchesPappus) {
  TempDir dir;
  // A ball of radius 0.5 whose centre runs a G3 half circle of radius 2 at
  // 0.3 mm below the top: Pappus for the swept segment plus the end caps.
  const double R = 0.5, rho = 2.0, depth = 0.2, h = 0.01;
  auto r = run_program(dir, "G0 X2 Y0 Z1\nG1 Z-0.2 F100\nG3 X-2 Y0 R2\nG0 Z1\n",
                       "ball:d=1", Aabb{Vec3(-4, -4, -1), Vec3(4, 4, 0)}, h);
  // The segment's centroid lies on the circle (symmetric about it), so
  // Pappus gives area * path length.
  const double exact = segment_area(R, depth) * kPi * rho + kPi * depth * depth * (3 * R - depth) / 3;
  const double area = 2 * R * std::acos((R - depth) / R) * kPi * rho + 2 * kPi * R * depth;
  EXPECT_NEAR(r.stock->removed_volume_mm3(), exact, 0.05 * h * area);
}

TEST(Volume, FlatRampMatchesQuadrature) {
  TempDir dir;
  // A flat end mill ramping from Z0 to Z-0.2 over 3 mm in X. The floor
  // under a point is set by the lowest tool position covering it:
  // depth(x, y) = 0.2 * min(1, (x + sqrt(1 - y^2)) / 3).
  const double h = 0.01;
  auto r = run_program(dir, "G0 X0 Y0 Z1\nG1 Z0 F100\nG1 X3 Z-0.2\nG0 Z1\n",
                       "flat:d=2", Aabb{Vec3(-2, -2, -2), Vec3(5, 2, 0)}, h);
  double exact = 0;
  const int n = 2000;
  for (int i = 0; i < n; ++i) {
    const double y = -1 + (i + 0.5) * 2.0 / n;
    const double w = std::sqrt(1 - y * y);
    for (int j = 0; j < 4 * n; ++j) {
      const double x = -1 + (j + 0.5) * 5.0 / (4 * n);
      if (x < -w || x > 3 + w) continue;
      exact += 0.2 * std::min(1.0, (x + w) / 3.0) * (2.0 / n) * (5.0 / (4 * n));
    }
  }
  const double area = 2 * 3 + kPi + 0.2 * (2 * 3 + 2 * kPi);
  EXPECT_NEAR(r.stock->removed_volume_mm3(), exact, 0.05 * h * area);
}

TEST(Volume, HelicalBallPlungeMatchesSweptSegment) {
  TempDir dir;
  // A helix of radius 1 descending 0.2 mm in one full turn, then a full
  // circle at the bottom: the same ring as a flat circle at the final depth
  // (the helix lies wholly above it), approximated by chords within h/20.
  const double R = 0.5, rho = 1.0, depth = 0.2, h = 0.01;
  auto r = run_program(dir, "G0 X1 Y0 Z1\nG1 Z0 F100\nG2 X1 Y0 Z-0.2 I-1 J0\nG2 X1 Y0 I-1 J0\nG0 Z1\n",
                       "ball:d=1", Aabb{Vec3(-3, -3, -1), Vec3(3, 3, 0)}, h);
  const double exact = segment_area(R, depth) * 2 * kPi * rho;
  const double area = 2 * R * std::acos((R - depth) / R) * 2 * kPi * rho;
  EXPECT_NEAR(r.stock->removed_volume_mm3(), exact, 0.05 * h * area);
}

TEST(Volume, CutOutsideTheRoiCornerOfABigBlockLeavesTheRestAnalytic) {
  TempDir dir;
  // A 50 x 50 x 10 mm block cut over 1 mm at its centre with 1 um voxels:
  // only the region the tool reaches is a grid.
  const double h = 0.001;
  auto r = run_program(dir, "G0 X0 Y0 Z1\nG1 Z-0.01 F100\nG1 X0.5\nG0 Z1\n",
                       "ball:d=0.2", Aabb{Vec3(-25, -25, -10), Vec3(25, 25, 0)}, h);
  const double R = 0.1, depth = 0.01, len = 0.5;
  const double exact = segment_area(R, depth) * len + kPi * depth * depth * (3 * R - depth) / 3;
  const double area = 2 * R * std::acos((R - depth) / R) * len + 2 * kPi * R * depth;
  EXPECT_NEAR(r.stock->removed_volume_mm3(), exact, 0.05 * h * area);
  EXPECT_DOUBLE_EQ(r.stock->initial_volume_mm3(), 50.0 * 50.0 * 10.0);
  EXPECT_LT(r.stock->roi().size().x(), 1.0);
}

// The bench's count of the voxels the moves' bands reach (measured, not
// timed), against closed forms: a ball end mill plunging into the block
// from above reaches every voxel below the top that lies within the
// band's half width g of the swept solid, a cylinder of radius R + g down
// to the ball's lowest centre with a half ball below. A move's pieces count
// once (their union); two moves count twice where both reach. The count
// changes no voxel.
TEST(Volume, BandVoxelsAreTheCylindersAroundEachMove) {
  const double h = 0.01, R = 0.25, g = 2 * h, r = R + g;
  const Aabb box{Vec3(-2, -2, -2), Vec3(2, 2, 0)};
  const Eigen::Matrix3d I = Eigen::Matrix3d::Identity();
  const tool::Tool ball = tool::parse_tool_spec("ball:d=0.5,l=3", "test");  // flutes above the top throughout
  const Vec3 top(0.013, -0.007, 1), mid(0.013, -0.007, -0.3), bottom(0.013, -0.007, -1);
  auto count = [&](const std::vector<sweep::Sweep>& moves, std::size_t every, double* removed = nullptr) {
    stock::StockOptions so;
    so.voxel_mm = h;
    so.measure_band_every = every;
    stock::Stock s(box, box, so);
    s.subtract(moves);
    if (removed) *removed = s.removed_volume_mm3();
    return static_cast<double>(s.stats().band_voxels);
  };
  // Voxels below the top within r of a plunge whose ball's lowest centre is z.
  auto reach = [&](double z) { return (kPi * r * r * -z + 2.0 / 3 * kPi * r * r * r) / (h * h * h); };
  // One move of two pieces (top to mid, mid to bottom): their union.
  sweep::Sweep whole = sweep::sweep_line(top, mid, I, ball);
  for (const auto& p : sweep::sweep_line(mid, bottom, I, ball).prims) whole.prims.push_back(p);
  double removed_counted = 0, removed_plain = 0;
  const double one = count({whole}, 1, &removed_counted);
  EXPECT_NEAR(one, reach(-1 + R), 0.01 * reach(-1 + R));
  // The same pieces as two moves: the first reaches down to its own ball.
  const double two = count({sweep::sweep_line(top, mid, I, ball), sweep::sweep_line(mid, bottom, I, ball)}, 1);
  EXPECT_NEAR(two, reach(-1 + R) + reach(-0.3 + R), 0.01 * (reach(-1 + R) + reach(-0.3 + R)));
  // Not measured: no count, and the same cut.
  EXPECT_EQ(count({whole}, 0, &removed_plain), 0.0);
  EXPECT_EQ(removed_counted, removed_plain);
  // The leaves the bounds do not settle evaluated in 1 leaf in 4 (some 100
  // of them here) and counted 4 times: an estimate, within its sampling
  // error on so few.
  EXPECT_NEAR(count({whole}, 4), one, 0.1 * one);
}

// A fly-cutter pass 3 um above the floor a deeper pass left: the binning
// passes over the leaves its torus's plane leaves whole, but the band's
// count still takes them, as a plain update would visit them. On a box
// stock whose ROI is the box, that is every voxel centre of the ROI nearer
// the torus than the band's half width, on a fresh stock or after the
// deeper pass (which leaves no air tiles): counted here one by one.
TEST(Volume, BandVoxelsOfAFlyCutPassCountTheFloorAPassBeforeLeft) {
  const double h = 0.01;
  const Aabb box{Vec3(-1, -1, -0.5), Vec3(1, 1, 0)};
  auto pass = [](double z) {
    Pose pose = Pose::Identity();
    pose.translation() = Vec3(0.004, -0.003, z);
    return sweep::sweep_tori({pose}, tool::SwingTorus{3, 0.5});
  };
  stock::StockOptions so;
  so.voxel_mm = h;
  so.measure_band_every = 1;
  auto brute = [&](const sweep::Sweep& sw) {
    const stock::Stock s(box, box, so);
    const double g = s.band_mm();
    const Vec3 lattice = s.roi_lattice_origin();
    const Aabb r = s.roi(), reach = sweep::bounds(sw.prims.at(0)).expanded(g + h).intersected(r);
    double n = 0;
    for (double x = lattice.x() + h * std::ceil((reach.min.x() - lattice.x()) / h); x <= reach.max.x(); x += h)
      for (double y = lattice.y() + h * std::ceil((reach.min.y() - lattice.y()) / h); y <= reach.max.y(); y += h)
        for (double z = lattice.z() + h * std::ceil((reach.min.z() - lattice.z()) / h); z <= reach.max.z(); z += h) {
          const Vec3 p(x, y, z);
          if (((p - r.min).array() < 0.5 * h - 1e-9).any() || ((r.max - p).array() < 0.5 * h - 1e-9).any()) continue;
          n += sweep::distance(sw.prims.at(0), p) < g;
        }
    return n;
  };
  auto count = [&](const std::vector<double>& depths, double* removed) {
    stock::Stock s(box, box, so);
    for (double z : depths) s.subtract(pass(z));  // one update each: the second sees the first's floor
    *removed = s.removed_volume_mm3();
    return static_cast<double>(s.stats().band_voxels);
  };
  double deep_removed = 0, shallow_removed = 0, both_removed = 0;
  const double deep = count({-0.006}, &deep_removed), shallow = count({-0.003}, &shallow_removed);
  const double both = count({-0.006, -0.003}, &both_removed);
  const double shallow_exact = brute(pass(-0.003)), deep_exact = brute(pass(-0.006));
  EXPECT_GT(shallow_exact, 1e3);
  EXPECT_NEAR(shallow, shallow_exact, 1e-3 * shallow_exact);
  EXPECT_NEAR(deep, deep_exact, 1e-3 * deep_exact);
  EXPECT_GT(deep_removed, shallow_removed);
  EXPECT_EQ(both_removed, deep_removed);  // the shallow pass cuts nothing
  EXPECT_NEAR(both, deep_exact + shallow_exact, 1e-3 * shallow_exact);
}

// A batch subtracts the union of its sweeps: every voxel value equals the
// one-move-at-a-time result, also when moves repeat and reverse (the
// pathological case for the batch's bounds: identical pieces).
// Blocks a cut empties are marked all air and passed over by later cuts;
// a cut through them into the material below must still remove it all.
// Four pocket depths, 1/4 of a block (0.64 mm) apart, so that in one of
// them the floor's block also holds emptied leaves above the floor.
TEST(Volume, CutThroughEmptiedBlocksMatchesClosedForm) {
  const double h = 0.02;
  const Aabb box{Vec3(-1.5, -1.5, -2.5), Vec3(1.5, 1.5, 0)};
  stock::StockOptions so;
  so.voxel_mm = h;
  const Eigen::Matrix3d I = Eigen::Matrix3d::Identity();
  for (const double depth : {1.2, 1.36, 1.52, 1.68}) {
    SCOPED_TRACE("pocket depth " + std::to_string(depth));
    stock::Stock s(box, box, so);
    const std::size_t air0 = s.stats().air_blocks;
    // A flat d=2 plunge: a cylinder r=1 whose inside is many 32-voxel blocks.
    s.subtract(sweep::sweep_line(Vec3(0, 0, 1), Vec3(0, 0, -depth), I, tool::parse_tool_spec("flat:d=2", "test")));
    const double pocket = kPi * depth, pocket_area = 2 * kPi + 2 * kPi * depth;
    EXPECT_NEAR(s.removed_volume_mm3(), pocket, 0.05 * h * pocket_area);
    EXPECT_GT(s.stats().air_blocks, air0) << "the pocket's blocks were not marked all air";
    // A flat d=1 plunge inside it to 0.5 mm below its floor: through the
    // air, then a cylinder r=0.5 more.
    s.subtract(sweep::sweep_line(Vec3(0.3, 0.2, 1), Vec3(0.3, 0.2, -depth - 0.5), I,
                                 tool::parse_tool_spec("flat:d=1", "test")));
    const double more = kPi * 0.25 * 0.5;
    EXPECT_NEAR(s.removed_volume_mm3(), pocket + more, 0.05 * h * (pocket_area + 2 * kPi * 0.25 + kPi * 0.5));
  }
}

// Every leaf holds a voxel of the band: a leaf of constant values takes a
// leaf's memory (2 KB) for what a tile holds. Faces are built exactly, the
// grid ends on whole leaves where the ROI ends inside the material, and a
// leaf a cut split from a material tile but left whole is a tile again.
TEST(Volume, EveryLeafHoldsTheBand) {
  const double h = 0.01;
  const Aabb box{Vec3(-2.013, -1.987, -3.004), Vec3(2.991, 2.017, 0.003)};
  const Aabb roi{Vec3(-1.2, -1.1, -0.9), Vec3(2.6, 2.3, 0.5)};  // ends inside the material below and aside
  stock::StockOptions so;
  so.voxel_mm = h;
  stock::Stock s(box, roi, so);
  EXPECT_GT(s.stats().leaf_nodes, 2000u);
  EXPECT_EQ(s.stats().idle_leaves, 0u) << "after the build";
  const Eigen::Matrix3d I = Eigen::Matrix3d::Identity();
  const tool::Tool ball = tool::parse_tool_spec("ball:d=1", "test");
  // Plunges on their own, to depths a voxel apart (every phase of the
  // leaves): the leaves just below the ball's lowest point are within reach
  // of its distance at their centres but not of its box.
  for (int k = 0; k < 8; ++k)
    s.subtract(sweep::sweep_line(Vec3(-0.6 + 1.1 * (k % 3), -0.5 + 1.1 * (k / 3), 1),
                                 Vec3(-0.6 + 1.1 * (k % 3), -0.5 + 1.1 * (k / 3), -0.2 - k * h), I, ball));
  EXPECT_EQ(s.stats().idle_leaves, 0u) << "after the plunges";
  std::vector<sweep::Sweep> moves;
  moves.push_back(sweep::sweep_line(Vec3(-0.6, 0.4, 1), Vec3(0, 0, -0.2), I, ball));
  moves.push_back(sweep::sweep_line(Vec3(0, 0, -0.2), Vec3(1.5, 0.7, -0.35), I, ball));
  moves.push_back(sweep::sweep_line(Vec3(1.5, 0.7, -0.35), Vec3(0.2, 1.1, -0.3), I, ball));
  s.subtract(moves);
  EXPECT_GT(s.removed_volume_mm3(), 1.0);
  EXPECT_EQ(s.stats().idle_leaves, 0u) << "after the cut";
}

// The block as built holds its exact signed distance, clamped to the band,
// at every voxel of the ROI: faces, edges and corners, the leaves the build
// fills along one axis only and the ones it fills voxel by voxel, and the
// partial leaves where the ROI ends inside the material.
TEST(Volume, TheBuiltBlockIsItsClampedDistanceAtEveryVoxel) {
  const double h = 0.01;
  const Aabb box{Vec3(-0.413, -0.387, -0.604), Vec3(0.391, 0.417, 0.003)};
  const Aabb roi{Vec3(-0.6, -0.2, -0.5), Vec3(0.6, 0.6, 0.5)};  // past three faces, inside on the others
  stock::StockOptions so;
  so.voxel_mm = h;
  stock::Stock s(box, roi, so);
  const double g = s.band_mm();
  std::size_t voxels = 0, band = 0, deep = 0, worst_at = 0;
  double worst = 0;
  std::mutex mu;
  s.for_each_roi_block([&](const stock::VoxelBlock& vb) {
    std::size_t n = 0, nb = 0, nd = 0;
    double w = 0;
    for (int x = 0; x < vb.n[0]; ++x)
      for (int y = 0; y < vb.n[1]; ++y)
        for (int z = 0; z < vb.n[2]; ++z) {
          const double v = vb.uniform ? vb.value : vb.values[(x * 8 + y) * 8 + z];
          const Vec3 p = vb.first_center + h * Vec3(x, y, z);
          const double want = std::clamp(box_signed_distance(box, p), -g, g);
          w = std::max(w, std::abs(v - want));
          ++n;
          nb += std::abs(want) < g;
          nd += want == -g;
        }
    std::lock_guard<std::mutex> lock(mu);
    voxels += n;
    band += nb;
    deep += nd;
    if (w > worst) worst = w, worst_at = voxels;
  });
  EXPECT_GT(band, 20000u);  // all six faces' bands are in the ROI somewhere
  EXPECT_GT(deep, 100000u);  // and the material below them, where the ROI ends inside it
  EXPECT_LT(worst, 1e-7 * h) << "at voxel " << worst_at;
}

// The ROI's blocks by groups (the grid's 128^3 nodes): with every group
// let through, the same blocks as one by one, each once; a group skipped
// skips its blocks and no other; a group's blocks lie in its ball, and a
// group called uniform holds its value at every voxel of them. The stock
// spans nine nodes along x at 5 um (a cut pocket makes some all air, the
// material below some all material, the faces' band the rest mixed).
TEST(Volume, BlockGroupsHoldTheirBlocksAndKnowTheirTiles) {
  const double h = 0.005;
  const Aabb box{Vec3(-2.5, -0.6, -1.2), Vec3(2.5, 0.6, 0)};
  stock::StockOptions so;
  so.voxel_mm = h;
  stock::Stock s(box, Aabb{Vec3(-2.3, -0.7, -1.3), Vec3(2.3, 0.5, 0.1)}, so);
  s.subtract(sweep::sweep_line(Vec3(-1.6, 0, 1), Vec3(1.6, 0, -0.9), Eigen::Matrix3d::Identity(),
                               tool::parse_tool_spec("flat:d=1.6", "test")));
  const auto dims = s.roi_block_dims();
  auto index = [&](const int* l) { return (static_cast<std::size_t>(l[0]) * dims[1] + l[1]) * dims[2] + l[2]; };
  const std::size_t n = static_cast<std::size_t>(dims[0]) * dims[1] * dims[2];
  std::vector<std::atomic<int>> plain(n), grouped(n), in_group(n);
  s.for_each_roi_block([&](const stock::VoxelBlock& b) { plain[index(b.leaf)] += 1; });
  std::atomic<int> groups{0}, uniform_groups{0}, skipped{0}, wrong{0};
  std::vector<std::atomic<int>> skip_mark(n);
  s.for_each_roi_block(
      [&](const stock::VoxelBlock& b) {
        const std::size_t i = index(b.leaf);
        grouped[i] += 1;
        if (skip_mark[i] != 0) ++wrong;  // a block of a skipped group
        if (in_group[i] == 0) ++wrong;   // visited outside its group's call
      },
      true,
      [&](const stock::BlockGroup& g) {
        ++groups;
        for (int x = g.lo[0]; x < g.hi[0]; ++x)
          for (int y = g.lo[1]; y < g.hi[1]; ++y)
            for (int z = g.lo[2]; z < g.hi[2]; ++z) {
              const int l[3] = {x, y, z};
              in_group[index(l)] += 1;
            }
        // Every 7th group is skipped.
        const bool skip = (g.lo[0] * 31 + g.lo[1] * 7 + g.lo[2]) % 7 == 3;
        if (skip) {
          ++skipped;
          for (int x = g.lo[0]; x < g.hi[0]; ++x)
            for (int y = g.lo[1]; y < g.hi[1]; ++y)
              for (int z = g.lo[2]; z < g.hi[2]; ++z) {
                const int l[3] = {x, y, z};
                skip_mark[index(l)] = 1;
              }
        }
        // The group's voxels as the blocks' own visit gives them.
        std::atomic<int> far{0}, off{0};
        s.for_each_roi_block([&](const stock::VoxelBlock& b) {
          if (b.leaf[0] < g.lo[0] || b.leaf[0] >= g.hi[0] || b.leaf[1] < g.lo[1] || b.leaf[1] >= g.hi[1] ||
              b.leaf[2] < g.lo[2] || b.leaf[2] >= g.hi[2])
            return;
          for (int x = 0; x < b.n[0]; ++x)
            for (int y = 0; y < b.n[1]; ++y)
              for (int z = 0; z < b.n[2]; ++z) {
                const Vec3 p = b.first_center + h * Vec3(x, y, z);
                if ((p - g.centre).norm() > g.radius) ++far;
                const float v = b.uniform ? b.value : b.values[(x * 8 + y) * 8 + z];
                if (g.uniform && v != g.value) ++off;
              }
        });
        if (far != 0 || off != 0) ++wrong;
        if (g.uniform) ++uniform_groups;
        return !skip;
      });
  EXPECT_EQ(wrong.load(), 0);
  EXPECT_GE(groups.load(), 9 * 2);
  EXPECT_GT(uniform_groups.load(), 0);
  EXPECT_LT(uniform_groups.load(), groups.load());
  EXPECT_GT(skipped.load(), 0);
  std::size_t blocks = 0;
  for (std::size_t i = 0; i < n; ++i) {
    blocks += plain[i] == 1;
    ASSERT_EQ(plain[i].load(), 1) << "block " << i;
    ASSERT_EQ(in_group[i].load(), 1) << "block " << i << " in more or fewer groups than one";
    ASSERT_EQ(grouped[i].load(), skip_mark[i] != 0 ? 0 : 1) << "block " << i;
  }
  EXPECT_EQ(blocks, n);
}

// Every voxel of the ROI, by block.
std::map<std::tuple<double, double, double>, std::vector<float>> voxels_of(const stock::Stock& s) {
  std::mutex mu;
  std::map<std::tuple<double, double, double>, std::vector<float>> out;
  s.for_each_roi_block([&](const stock::VoxelBlock& vb) {
    std::vector<float> v;
    for (int x = 0; x < vb.n[0]; ++x)
      for (int y = 0; y < vb.n[1]; ++y)
        for (int z = 0; z < vb.n[2]; ++z) v.push_back(vb.uniform ? vb.value : vb.values[(x * 8 + y) * 8 + z]);
    std::lock_guard<std::mutex> lock(mu);
    out[{vb.first_center.x(), vb.first_center.y(), vb.first_center.z()}] = std::move(v);
  });
  return out;
}

// Voxels of `b` that differ from `a`'s (a block only one of them holds counts whole).
std::size_t differing_voxels(const stock::Stock& a, const stock::Stock& b) {
  const auto va = voxels_of(a), vb = voxels_of(b);
  std::size_t n = 0;
  for (const auto& [k, v] : va) {
    const auto it = vb.find(k);
    if (it == vb.end()) n += v.size();
    else
      for (std::size_t i = 0; i < v.size(); ++i) n += i >= it->second.size() || v[i] != it->second[i];
  }
  for (const auto& [k, v] : vb) n += va.count(k) ? 0 : v.size();
  return n;
}

// The moves subtracted from a block three ways: as one batch, as one batch
// applied in parts of `budget` (leaf, piece) pairs, and one by one.
struct Grouped {
  double whole_removed_mm3 = 0, parts_removed_mm3 = 0;
  std::size_t whole_updates = 0, parts_updates = 0;
  std::size_t differ_parts = 0, differ_one = 0;  // voxels unlike the whole batch's
};
Grouped subtract_grouped(const Aabb& box, double voxel_mm, std::size_t budget, const std::vector<sweep::Sweep>& moves) {
  stock::StockOptions whole_opt;
  whole_opt.voxel_mm = voxel_mm;
  stock::StockOptions parts_opt = whole_opt;
  parts_opt.max_update_pairs = budget;
  stock::Stock whole(box, box, whole_opt), parts(box, box, parts_opt), one(box, box, whole_opt);
  whole.subtract(moves);
  parts.subtract(moves);
  for (const auto& m : moves) one.subtract(m);
  return {whole.removed_volume_mm3(), parts.removed_volume_mm3(), whole.stats().grid_updates,
          parts.stats().grid_updates, differing_voxels(whole, parts), differing_voxels(whole, one)};
}

TEST(Volume, BatchedSubtractEqualsMoveByMove) {
  const Aabb box{Vec3(-1, -1, -1), Vec3(2, 2, 0)};
  stock::StockOptions so;
  so.voxel_mm = 0.02;
  const tool::Tool t = tool::parse_tool_spec("ball:d=0.5", "test");
  std::vector<sweep::Sweep> moves;
  const Eigen::Matrix3d I = Eigen::Matrix3d::Identity();
  const Vec3 pts[] = {Vec3(0, 0, -0.1), Vec3(1, 0, -0.12), Vec3(1, 1, -0.1), Vec3(0, 0.5, -0.15), Vec3(0, 0, -0.1)};
  for (int rep = 0; rep < 3; ++rep)
    for (int i = 0; i + 1 < 5; ++i) moves.push_back(sweep::sweep_line(pts[i], pts[i + 1], I, t));
  moves.push_back(sweep::sweep_line(pts[1], pts[0], I, t));  // reversed
  stock::Stock one(box, box, so), batch(box, box, so);
  for (const auto& m : moves) one.subtract(m);
  batch.subtract(moves);
  EXPECT_GT(one.removed_volume_mm3(), 0.05);
  EXPECT_EQ(one.removed_volume_mm3(), batch.removed_volume_mm3());
  const auto a = voxels_of(one), b = voxels_of(batch);
  ASSERT_EQ(a.size(), b.size());
  std::size_t differ = 0;
  for (const auto& [k, v] : a) differ += v != b.at(k);
  EXPECT_EQ(differ, 0u);
}

// What the stock update must leave at voxel p, by brute force over every
// piece: clamp(-min_k d_k, -gamma, gamma), as a float; nothing within the
// stock block's own faces' band (their values are the block's, not a cut's).
std::optional<float> brute_force_voxel(const std::vector<sweep::Sweep>& moves, const Aabb& box, const Vec3& p, double g,
                                       double h) {
  const double inside = std::min((p - box.min).minCoeff(), (box.max - p).minCoeff());
  if (inside < g + 2 * h) return std::nullopt;
  double d = std::numeric_limits<double>::infinity();
  for (const auto& m : moves)
    for (const auto& prim : m.prims) d = std::min(d, sweep::distance(prim, p));
  const auto gf = static_cast<float>(g);
  return std::max(-gf, static_cast<float>(std::min(-d, g)));
}

// The voxels of the stock's ROI against brute_force_voxel: how many were
// checked, how many are air or in the band (the cut's surface), and how
// many differ from it in any bit. With `near`, only the blocks whose
// first and last voxel centres it accepts, and the voxels it accepts as
// both (a plane through the cut).
struct BruteForce {
  std::size_t checked = 0, air = 0, surface = 0, differ = 0;
};
BruteForce against_brute_force(const stock::Stock& s, const std::vector<sweep::Sweep>& moves, const Aabb& box, double h,
                               const std::function<bool(const Vec3&, const Vec3&)>& near = {}) {
  const double g = s.band_mm();
  const float gf = static_cast<float>(g);
  std::atomic<std::size_t> checked{0}, air{0}, surface{0}, differ{0};
  s.for_each_roi_block([&](const stock::VoxelBlock& vb) {
    const Vec3 lo = vb.first_center, hi = lo + h * Vec3(vb.n[0] - 1, vb.n[1] - 1, vb.n[2] - 1);
    if (near && !near(lo, hi)) return;
    for (int x = 0; x < vb.n[0]; ++x)
      for (int y = 0; y < vb.n[1]; ++y)
        for (int z = 0; z < vb.n[2]; ++z) {
          const Vec3 p = vb.first_center + h * Vec3(x, y, z);
          if (near && !near(p, p)) continue;
          const auto want_at = brute_force_voxel(moves, box, p, g, h);
          if (!want_at) continue;  // the block's faces' band
          const float want = *want_at;
          const float got = vb.uniform ? vb.value : vb.values[(x * 8 + y) * 8 + z];
          ++checked;
          air += want == gf;
          surface += want > -gf && want < gf;
          differ += got != want;
        }
  });
  return {checked.load(), air.load(), surface.load(), differ.load()};
}

TEST(Volume, EveryVoxelInsideTheBlockIsTheNearestPiecesDepth) {
  // Deeper than the band inside the block the stock held -gamma, so after the cuts each
  // voxel must hold exactly clamp(-min_k d_k, -gamma, gamma), d_k the
  // pieces' distances at its centre: whatever the update's bounds skipped,
  // and the quarters it set to air whole, must agree with that to the bit.
  const Aabb box{Vec3(-1, -1, -1), Vec3(2, 2, 0)};
  stock::StockOptions so;
  so.voxel_mm = 0.02;
  const tool::Tool t = tool::parse_tool_spec("ball:d=0.8", "test");
  const Eigen::Matrix3d I = Eigen::Matrix3d::Identity();
  std::vector<sweep::Sweep> moves;
  moves.push_back(sweep::sweep_line(Vec3(-0.3, 0.2, -0.35), Vec3(1.5, 0.3, -0.3), I, t));
  moves.push_back(sweep::sweep_line(Vec3(1.5, 0.3, -0.3), Vec3(1.4, 1.2, -0.4), I, t));
  moves.push_back(sweep::sweep_line(Vec3(0.2, 1.4, 0.1), Vec3(0.2, 1.4, -0.45), I, t));  // plunge
  moves.push_back(sweep::sweep_line(Vec3(0.0, -0.2, -0.1), Vec3(1.0, 1.1, -0.38), I, t));  // ramp across
  stock::Stock s(box, box, so);
  s.subtract(moves);
  const BruteForce bf = against_brute_force(s, moves, box, so.voxel_mm);
  EXPECT_GT(bf.checked, 200000u);
  EXPECT_GT(bf.air, 40000u);  // the cuts' insides, where quarters are set to air whole
  EXPECT_GT(s.stats().voxels_aired, 10000u);
  EXPECT_EQ(bf.differ, 0u);
}

TEST(Volume, VToolGroovesAreTheNearestPrismsDepth) {
  // Level planing passes of a 90 deg V tool, 20 um deep and 8 um apart
  // (the snowflake's pick feed). Each pass in 20 um moves: most quarters
  // are reached by one prism (the update's one-piece path), those where
  // moves and grooves meet by several. Along its cutting direction a V
  // prism's distance is exact, so each voxel must hold exactly
  // clamp(-min_k d_k, -gamma, gamma), to the bit. (Lifting moves shear
  // the prism, whose first-order distance can fall below its box's,
  // bench/README.md: not asserted here.)
  const tool::Tool t = tool::parse_tool_spec("vtool:angle=90,h=0.05", "test");
  const Eigen::Matrix3d I = Eigen::Matrix3d::Identity();
  const Aabb box{Vec3(-0.06, -0.04, -0.04), Vec3(0.06, 0.04, 0)};
  stock::StockOptions so;
  so.voxel_mm = 0.001;
  stock::Stock s(box, box, so);
  const double band = s.band_mm();
  // Each pass's moves joined as the simulation joins them (sweep::Joiner).
  std::size_t joints = 0, extended = 0;
  auto passes = [&](int moves_each) {
    std::vector<sweep::Sweep> moves;
    sweep::Joiner join(band, box.expanded(band + 2 * so.voxel_mm));  // the simulation's reach
    for (int pass = 0; pass < 4; ++pass) {
      const double y = -0.012 + 0.008 * pass;
      for (int k = 0; k < moves_each; ++k) {
        moves.push_back(sweep::sweep_line(Vec3(-0.05 + 0.1 * k / moves_each, y, -0.02),
                                          Vec3(-0.05 + 0.1 * (k + 1) / moves_each, y, -0.02), I, t));
        join(moves.back());
        joints += moves.back().prims.size() - 1;
      }
    }
    moves.push_back(join.finish());
    joints += moves.back().prims.size();
    extended += join.extended();
    return moves;
  };
  const std::vector<sweep::Sweep> split = passes(5);
  // Each pass's moves run on one line: each joint closed by drawing the
  // next prism back over it (no JointPrim), within its pass, not to the
  // next pass's start.
  EXPECT_EQ(joints, 0u);
  EXPECT_EQ(extended, 4u * 4u);
  s.subtract(split);
  const BruteForce bf = against_brute_force(s, split, box, so.voxel_mm);
  EXPECT_GT(bf.checked, 200000u);
  EXPECT_GT(bf.air, 10000u);
  EXPECT_GT(bf.surface, 20000u);
  EXPECT_EQ(bf.differ, 0u);
  // The grooves' union: four 20 um deep V's (40 um wide at the top) 8 um
  // apart. Its depth at y is 20 um less the way to the nearest groove's
  // centre: the two outer flanks 20^2 / 2 um^2 each, the three gaps
  // 8 * 20 - 4^2 each, 832 um^2 in all, over the 100 um of the passes
  // (flat caps at both ends). One move a pass, and split into five: the
  // joints' pieces keep the moves' end caps, inside the cut, from counting
  // a sheet of material at each joint (without them the split passes came
  // out 81,536 um^3, half a voxel of the section short per joint; the
  // prisms drawn back over their joints do the same): the same volume to
  // the bit.
  stock::Stock whole(box, box, so);
  whole.subtract(passes(1));
  EXPECT_NEAR(whole.removed_volume_mm3() * 1e9, 832.0 * 100, 0.001 * 832 * 100);
  EXPECT_DOUBLE_EQ(s.removed_volume_mm3(), whole.removed_volume_mm3());
}

TEST(Volume, FlyCutVoxelsAreTheNearestTorussDepth) {
  // Fly-cutter passes (swing 2, nose 0.5) 40 um apart, 0.15 mm deep, one of
  // them on a turned spindle: tori a voxel apart and less, all cutting the
  // same voxels, which the update culls by their tangent planes (their
  // convex minorant on the cutting side). Each voxel must still hold
  // exactly clamp(-min_k d_k, -gamma, gamma), to the bit.
  const tool::Tool t = tool::parse_tool_spec("flycutter:swing=2,r=0.5", "test");
  const Eigen::Matrix3d turned = Eigen::AngleAxisd(0.25, Vec3(0.1, 0.05, 1).normalized()).toRotationMatrix();
  std::vector<sweep::Sweep> moves;
  for (int line = 0; line < 6; ++line) {
    const double y = 0.02 + 0.04 * line, z = -0.15 - 0.01 * line;
    moves.push_back(sweep::sweep_line(Vec3(-0.5, y, z), Vec3(0.5, y + 0.01 * line, z),
                                      line == 3 ? turned : Eigen::Matrix3d::Identity(), t));
  }
  const Aabb box{Vec3(-0.3, -0.05, -0.35), Vec3(0.3, 0.3, 0)};
  stock::StockOptions so;
  so.voxel_mm = 0.01;
  std::size_t tori = 0;
  for (const auto& m : moves) tori += m.prims.size();
  ASSERT_GT(tori, 100u);
  stock::Stock s(box, box, so);
  s.subtract(moves);
  const BruteForce bf = against_brute_force(s, moves, box, so.voxel_mm);
  EXPECT_GT(bf.checked, 30000u);
  EXPECT_GT(bf.surface, 6000u);  // the cut's band, where the tori are culled
  // (A plane 0.02 um too high, by a wrong bound, made 35 voxels differ;
  // the core-point bound without its bend, 3.)
  EXPECT_EQ(bf.differ, 0u);
  // The passes one update each: every pass after the first is binned over
  // the floors of those before, against its leaves' material figures as
  // the updates left them (Stock::Impl::LeafPlanes), and must leave the
  // same voxels.
  stock::Stock one_by_one(box, box, so);
  for (const auto& m : moves) one_by_one.subtract(m);
  const BruteForce bf1 = against_brute_force(one_by_one, moves, box, so.voxel_mm);
  EXPECT_EQ(bf1.checked, bf.checked);
  EXPECT_EQ(bf1.differ, 0u);
  // A raster at one depth, 20 um a line, one update each: each pass cuts
  // beside the floor the one before left, where a torus's plane and the
  // leaves' figures come closest. (Passing over leaves whose bound is
  // above -h/2 instead of 0 made 41 voxels differ above, 1,536 here.)
  std::vector<sweep::Sweep> raster;
  for (int line = 0; line < 5; ++line) {
    const double y = 0.08 + 0.02 * line;
    raster.push_back(sweep::sweep_line(Vec3(-0.5, y, -0.15), Vec3(0.5, y, -0.15), Eigen::Matrix3d::Identity(), t));
  }
  stock::Stock rs(box, box, so);
  for (const auto& m : raster) rs.subtract(m);
  const BruteForce bfr = against_brute_force(rs, raster, box, so.voxel_mm);
  EXPECT_GT(bfr.surface, 3000u);
  EXPECT_EQ(bfr.differ, 0u);
}

TEST(Volume, BlocksDeepInsideAPieceAreAiredWholeAndNoVoxelMore) {
  // A d=9 flat end plunges 6 mm and moves aside: its cylinder holds 32^3-
  // and 128^3-voxel blocks deeper than the band and their half diagonals,
  // which are set to air without listing their leaves. The ROI ends
  // inside the cylinder (at x = 2.3), where no block is whole. The voxels
  // on two planes through the cut (x = 0 and z = -3: the cylinder's side,
  // the blocks' edges, the ROI's end) must hold exactly
  // clamp(-min_k d_k, -gamma, gamma), and the volume must be the cylinder's.
  const double h = 0.02;
  const Aabb box{Vec3(-5, -5, -7), Vec3(5, 5, 0)};
  const Aabb roi{Vec3(-5, -5, -7), Vec3(2.3, 5, 0.5)};
  stock::StockOptions so;
  so.voxel_mm = h;
  const Eigen::Matrix3d I = Eigen::Matrix3d::Identity();
  const tool::Tool t = tool::parse_tool_spec("flat:d=9,l=20", "test");
  std::vector<sweep::Sweep> moves;
  moves.push_back(sweep::sweep_line(Vec3(-0.2, 0.1, 1), Vec3(-0.2, 0.1, -6), I, t));
  moves.push_back(sweep::sweep_line(Vec3(-0.2, 0.1, -6), Vec3(0.3, 0.4, -6), I, t));
  stock::Stock s(box, roi, so);
  const double v0 = s.removed_volume_mm3();
  s.subtract(moves);
  EXPECT_GE(s.stats().blocks_aired, 64u + 100u) << "no 128^3 block, or few 32^3 ones, aired whole";
  // The planes x = 0 and z = -3, within half a voxel.
  const BruteForce bf = against_brute_force(s, moves, box, h, [h](const Vec3& lo, const Vec3& hi) {
    return (lo.x() <= h / 2 && hi.x() >= -h / 2) || (lo.z() <= -3 + h / 2 && hi.z() >= -3 - h / 2);
  });
  EXPECT_GT(bf.checked, 300000u);
  EXPECT_GT(bf.air, 100000u);
  EXPECT_GT(bf.surface, 3000u);  // the cylinder's side and floor on the planes
  EXPECT_EQ(bf.differ, 0u);
  // The volume: the disc r=4.5 swept from (-0.2, 0.1) to (0.3, 0.4), within
  // the ROI (its end snapped to the voxel cells) and the box, 6 mm deep;
  // its area by midpoint sums.
  const Vec3 a(-0.2, 0.1, 0), b(0.3, 0.4, 0);
  const double x1 = s.roi().max.x();
  ASSERT_NEAR(x1, 2.3, h);
  const int n = 2000;
  double area = 0;
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j) {
      const Vec3 q(-5 + (x1 + 5) * (i + 0.5) / n, -5 + 10.0 * (j + 0.5) / n, 0);
      const double u = std::clamp((q - a).dot(b - a) / (b - a).squaredNorm(), 0.0, 1.0);
      area += (q - a - u * (b - a)).norm() <= 4.5;
    }
  area *= (x1 + 5) * 10.0 / (double(n) * n);
  const double removed = s.removed_volume_mm3() - v0;
  EXPECT_NEAR(removed, area * 6, 0.05 * h * (2 * area + 2 * kPi * 4.5 * 6));
}

TEST(Volume, BatchAppliedInPartsEqualsWhole) {
  // A batch whose (leaf, piece) pairs pass the budget is applied in parts,
  // chunk by chunk of its pieces: the same voxels as applied whole, and as
  // move by move; a ramp, a plunge and level passes of a ball end, crossing.
  const Aabb box{Vec3(-1, -1, -1), Vec3(2, 2, 0)};
  const tool::Tool t = tool::parse_tool_spec("ball:d=0.5", "test");
  const Eigen::Matrix3d I = Eigen::Matrix3d::Identity();
  std::vector<sweep::Sweep> moves;
  for (int k = 0; k < 12; ++k) {
    const double y = -0.3 + 0.12 * k;
    moves.push_back(sweep::sweep_line(Vec3(-0.2, y, -0.05 - 0.01 * (k % 3)), Vec3(1.4, y + 0.05, -0.12), I, t));
  }
  moves.push_back(sweep::sweep_line(Vec3(0.5, 0.5, 0.1), Vec3(0.5, 0.5, -0.3), I, t));  // plunge
  moves.push_back(sweep::sweep_line(Vec3(0.0, 1.2, -0.2), Vec3(1.0, -0.2, -0.08), I, t));  // across
  const Grouped g = subtract_grouped(box, 0.02, 50, moves);
  EXPECT_EQ(g.whole_updates, 1u);
  EXPECT_GE(g.parts_updates, 5u);  // the budget really split it (8 pieces, then one by one)
  EXPECT_GT(g.whole_removed_mm3, 0.2);
  EXPECT_EQ(g.whole_removed_mm3, g.parts_removed_mm3);
  EXPECT_EQ(g.differ_parts, 0u);
  EXPECT_EQ(g.differ_one, 0u);
}

TEST(Volume, VToolPlaningInPartsEqualsWholeAndMoveByMove) {
  // A V tool planing along X, lowering and lifting on the way (the
  // snowflake's moves, in the plane of its cutting direction and axis):
  // its prisms count as 1-Lipschitz, so the update culls with them as
  // with a ball end. The voxels must not depend on how the moves are
  // grouped, to the bit; lines 30 um apart leave cusps between them.
  const Aabb box{Vec3(-0.05, -0.1, -0.05), Vec3(0.25, 0.1, 0)};
  const tool::Tool t = tool::parse_tool_spec("vtool:angle=90,h=0.04,body=0.1", "test");
  const Eigen::Matrix3d I = Eigen::Matrix3d::Identity();
  std::vector<sweep::Sweep> moves;
  sweep::Joiner join(stock::StockOptions{}.half_band_voxels * 0.001, box);  // as the simulation joins them
  for (int line = 0; line < 4; ++line) {
    const double y = -0.045 + 0.03 * line;
    for (int k = 0; k < 20; ++k) {
      const double x0 = 0.01 * k, x1 = x0 + 0.01;
      auto z = [](double x) { return -0.012 + 0.008 * std::sin(20 * x); };
      moves.push_back(sweep::sweep_line(Vec3(x0, y, z(x0)), Vec3(x1, y, z(x1)), I, t));
      join(moves.back());
    }
  }
  moves.push_back(join.finish());
  std::size_t joints = 0;
  for (const auto& m : moves)
    for (const auto& p : m.prims) {
      ASSERT_TRUE(sweep::lipschitz(p));
      joints += std::holds_alternative<sweep::JointPrim>(p);
    }
  // Over the crests (the slope falls: sin(20 x) for x < pi / 20) each
  // joint where the slope falls by 0.01 or less is closed by the next
  // prism drawn back 2 um (every move is 10 um, more than that), each
  // sharper one by a crest's piece; in the valleys by JointPrims, one for
  // each prism beside such a joint.
  std::size_t drawn = 0, sharp = 0, jointed = 0;
  {
    auto z = [](double x) { return -0.012 + 0.008 * std::sin(20 * x); };
    auto slope = [&](int k) { return (z(0.01 * (k + 1)) - z(0.01 * k)) / 0.01; };
    auto crest = [&](int k) { return slope(k) <= slope(k - 1); };  // the joint before move k
    for (int k = 1; k < 20; ++k) {
      drawn += crest(k) && slope(k - 1) - slope(k) <= 0.01;
      sharp += crest(k) && slope(k - 1) - slope(k) > 0.01;
    }
    for (int k = 0; k < 20; ++k) jointed += (k >= 1 && !crest(k)) || (k + 1 < 20 && !crest(k + 1));
  }
  ASSERT_GE(drawn, 2u);
  ASSERT_GE(sharp, 5u);
  ASSERT_LT(drawn + sharp, 19u);
  EXPECT_EQ(join.extended(), 4 * drawn);
  EXPECT_EQ(join.crests(), 4 * sharp);
  EXPECT_EQ(join.joints(), 4 * jointed);
  EXPECT_EQ(joints, 4 * (jointed + sharp));
  const Grouped g = subtract_grouped(box, 0.001, 200, moves);
  EXPECT_GE(g.parts_updates, 5u);
  // The closed form, integrated: across Y the union of four 90 deg V
  // grooves, each as deep as the tip (and half as wide as twice that).
  double expect = 0;
  constexpr int kNx = 2000, kNy = 2000;
  for (int i = 0; i < kNx; ++i) {
    const double x = 0.2 * (i + 0.5) / kNx, depth = 0.012 - 0.008 * std::sin(20 * x);
    for (int j = 0; j < kNy; ++j) {
      const double y = -0.1 + 0.2 * (j + 0.5) / kNy;
      double d = 0;
      for (int line = 0; line < 4; ++line) d = std::max(d, depth - std::fabs(y - (-0.045 + 0.03 * line)));
      expect += d * (0.2 / kNx) * (0.2 / kNy);
    }
  }
  // Measured 0.72 % under at 1 um voxels: the coverage integral's bias on
  // the sharp V bottoms and ridges. (4.4 % before the joint pieces, whose
  // end caps left a sheet of half a voxel of material at each of the 76
  // joints; and the groupings differed in 7 far-band voxels until the
  // prisms' distance was held to their boxes'.)
  EXPECT_NEAR(g.whole_removed_mm3, expect, 0.01 * expect);
  EXPECT_LT(g.whole_removed_mm3, expect);
  EXPECT_EQ(g.differ_parts, 0u);
  EXPECT_EQ(g.differ_one, 0u);
}

// The distance from (y, z) to the region below z = c + |y| (the material
// under a 90 deg V whose tip is at height c), signed: negative below.
double below_v_distance(double y, double z, double c) {
  const double u = z - c - std::fabs(y);  // > 0: inside the V (air)
  if (u >= 0) return u / std::sqrt(2.0);  // to the nearer flank (the V is convex)
  // Below the V: to the V's region above, whose nearest point is on a
  // flank or at the tip.
  const double ay = std::fabs(y), dz = z - c;
  if (dz <= -ay) return -std::hypot(ay, dz);  // below the tip's normal cone: the tip
  return u / std::sqrt(2.0);
}

// A 90 deg V groove along X at Y = 0 whose tip runs through (xs, zs).
struct VGroove {
  std::vector<double> xs, zs;

  double tip(double x) const {
    for (std::size_t k = 0; k + 1 < xs.size(); ++k)
      if (x <= xs[k + 1]) return zs[k] + (zs[k + 1] - zs[k]) * (x - xs[k]) / (xs[k + 1] - xs[k]);
    return zs.back();
  }
  // The exact signed distance to the groove's material (below the
  // grooves' surface; the top face ignored): the least over slices x' of
  // the way to the material (or, from the material, to the cut) of that
  // slice's V, sampled at h / 64 along X within 3 voxels (the slices'
  // distance is smooth).
  double exact(const Vec3& p, double h) const {
    const double inside = below_v_distance(p.y(), p.z(), tip(p.x())) > 0 ? 1.0 : -1.0;
    double best = std::numeric_limits<double>::infinity();
    for (int i = -3 * 64; i <= 3 * 64; ++i) {
      const double dx = i * h / 64, d = below_v_distance(p.y(), p.z(), tip(p.x() + dx));
      best = std::min(best, std::hypot(dx, inside > 0 ? std::max(d, 0.0) : std::max(-d, 0.0)));
    }
    return inside * best;
  }
};

// A V groove over steps: flat runs of 5 moves of 3.5 um joined by single
// moves that rise or fall 3 um, from (0, -12 um).
VGroove stepped_groove() {
  VGroove g{{0.0}, {-0.012}};
  for (int k = 0; g.xs.size() < 41; ++k) {
    const int phase = k % 12;
    g.xs.push_back(g.xs.back() + 0.0035);
    g.zs.push_back(g.zs.back() + (phase == 5 ? 0.003 : phase == 11 ? -0.003 : 0.0));
  }
  return g;
}

struct ExactCheck {
  int air = 0, material = 0, air_off = 0, material_off = 0;
  double air_worst = 0, material_worst = 0;
};
// The stock's voxels within 1.5 voxels of the groove (exactly), away from
// its ends and 3 voxels below the top (another surface), against the
// exact distance: off where the error is over 4 % of a voxel in the cut
// and a quarter in the material.
ExactCheck check_against_exact(const stock::Stock& stock, const VGroove& g, double h) {
  ExactCheck c;
  const Vec3 origin = stock.roi_lattice_origin();  // a voxel's centre
  auto first = [&](double v, int k) { return static_cast<int>(std::ceil((v - origin[k]) / h)); };
  for (int ix = first(0.004, 0); origin.x() + ix * h < g.xs.back() - 0.004; ++ix)
    for (int iy = first(-0.02, 1); origin.y() + iy * h < 0.02; ++iy)
      for (int iz = first(-0.025, 2); origin.z() + iz * h < -0.003; ++iz) {
        const Vec3 p = origin + h * Vec3(ix, iy, iz);
        // (The own slice's distance bounds the exact one above; 6 voxels
        // away no slice within 3 voxels comes within 1.5.)
        if (std::fabs(below_v_distance(p.y(), p.z(), g.tip(p.x()))) >= 6 * h) continue;
        const double e = g.exact(p, h);
        if (std::fabs(e) >= 1.5 * h) continue;
        const double err = std::fabs(stock.sample(p) - e) / h;
        if (e > 0) {
          ++c.air;
          c.air_worst = std::max(c.air_worst, err);
          c.air_off += err > 0.04;
        } else {
          ++c.material;
          c.material_worst = std::max(c.material_worst, err);
          c.material_off += err > 0.25;
        }
      }
  return c;
}

TEST(Volume, VToolStepsMatchTheExactDistanceBesideShortCrests) {
  // One groove of a 90 deg V planing along X over steps. Each rise ends
  // in a crest run of one move, 3.5 um, shorter than the two half widths
  // (4 um at 1 um voxels) that drawing the next prism back over the
  // crest takes: the crest's joint was then closed by a JointPrim, the
  // intersection of the prisms, which is a valley's shape, and beside
  // those crests the voxels read up to half a voxel too little depth (the
  // snowflake's rises, moves of 1.988 um at 0.5 um voxels, met the same).
  // Every voxel whose exact distance is within 1.5 voxels (all that the
  // volumes and the mesher read) must match it: in the cut to 4 % of a
  // voxel (a crest piece's depth is its nearer flank plane's, short of
  // the way to the crease itself: 0.031 voxels 1.5 voxels deep); in the
  // material to a quarter (a sheared prism's distance outside is a
  // first-order estimate beside its caps: measured 0.21 voxels where the
  // rises and falls start).
  const double h = 0.001;
  const Aabb box{Vec3(-0.02, -0.03, -0.03), Vec3(0.16, 0.03, 0)};
  const tool::Tool t = tool::parse_tool_spec("vtool:angle=90,h=0.04,body=0.1", "test");
  const Eigen::Matrix3d I = Eigen::Matrix3d::Identity();
  const VGroove g = stepped_groove();
  std::vector<sweep::Sweep> moves;
  sweep::Joiner join(stock::StockOptions{}.half_band_voxels * h, box);  // as the simulation joins them
  for (std::size_t k = 0; k + 1 < g.xs.size(); ++k) {
    moves.push_back(sweep::sweep_line(Vec3(g.xs[k], 0, g.zs[k]), Vec3(g.xs[k + 1], 0, g.zs[k + 1]), I, t));
    join(moves.back());
  }
  moves.push_back(join.finish());
  // Crests' pieces where each rise ends and each fall starts (6), and at
  // the first joint of the flat at the start and after each fall (4):
  // straight on, but run 3.5 um, too short to draw the next prism back.
  EXPECT_EQ(join.crests(), 10u);
  stock::StockOptions opt;
  opt.voxel_mm = h;
  stock::Stock stock(box, box, opt);
  stock.subtract(moves);
  const ExactCheck c = check_against_exact(stock, g, h);
  EXPECT_GT(c.air, 3000);
  EXPECT_GT(c.material, 4000);
  EXPECT_EQ(c.air_off, 0) << "worst " << c.air_worst << " voxels";
  EXPECT_EQ(c.material_off, 0) << "worst " << c.material_worst << " voxels";
}

TEST(Volume, VToolStepsProgramMatchesTheExactDistance) {
  // The same groove as a program through the whole simulation (its
  // Joiner at the stock's band and reach, the contact check's batches):
  // the same figures.
  TempDir dir;
  const double h = 0.001;
  const VGroove g = stepped_groove();
  std::string prog = "G21 G90 G94\nG0 X0 Y0 Z0.02\nG1 Z-0.012 F30\n";
  for (std::size_t k = 1; k < g.xs.size(); ++k)
    prog += "G1 X" + std::to_string(g.xs[k]) + " Z" + std::to_string(g.zs[k]) + "\n";
  prog += "G0 Z0.02\nM30\n";
  auto r = run_program(dir, prog, "vtool:angle=90,h=0.04,body=0.1",
                       Aabb{Vec3(-0.02, -0.03, -0.03), Vec3(0.16, 0.03, 0)}, h);
  ASSERT_TRUE(r.stock);
  EXPECT_EQ(r.stock->voxel_mm(), h);
  const ExactCheck c = check_against_exact(*r.stock, g, h);
  EXPECT_GT(c.air, 3000);
  EXPECT_GT(c.material, 4000);
  EXPECT_EQ(c.air_off, 0) << "worst " << c.air_worst << " voxels";
  EXPECT_EQ(c.material_off, 0) << "worst " << c.material_worst << " voxels";
}

}  // namespace
}  // namespace cutsim::test
