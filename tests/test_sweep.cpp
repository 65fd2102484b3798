// Swept-envelope distances against densely sampled tool poses.
#include <cmath>
#include <functional>
#include <limits>
#include <random>
#include <string>
#include <utility>
#include <variant>
#include <vector>

#include "cutsim/gcode/block_reader.h"
#include "cutsim/motion/interpreter.h"
#include "cutsim/sweep/sweep.h"
#include "helpers.h"

namespace cutsim::test {
namespace {

motion::Move single_move(const std::string& program) {
  std::istringstream in(program);
  gcode::BlockReader reader(in, "t.nc");
  motion::Interpreter interp("t.nc");
  std::vector<motion::Move> moves;
  gcode::Block b;
  while (reader.next(b)) interp.execute(b, moves);
  return moves.back();
}

// Minimum over N poses along the move of the single-pose envelope distance.
// Outside the swept region this converges to the exact distance from above
// with error O((path length / N)^2 / R).
double sampled_distance(const motion::Move& m, const tool::Tool& t, const Vec3& x, int n) {
  double d = std::numeric_limits<double>::infinity();
  for (int i = 0; i <= n; ++i) d = std::min(d, sweep::tool_at(m.point_at(double(i) / n), t).distance(x));
  return d;
}

void compare(const std::string& program, const std::string& tool_spec, int n_samples, double tol) {
  const motion::Move m = single_move(program);
  const tool::Tool t = tool::parse_tool_spec(tool_spec);
  const sweep::Sweep s = sweep::sweep_move(m, t, sweep::SweepOptions{1e-6});
  std::mt19937_64 rng(42);
  const Aabb b = s.bounds.expanded(0.3);
  std::uniform_real_distribution<double> ux(b.min.x(), b.max.x()), uy(b.min.y(), b.max.y()), uz(b.min.z(), b.max.z());
  int outside = 0, inside = 0;
  for (int i = 0; i < 3000; ++i) {
    const Vec3 x(ux(rng), uy(rng), uz(rng));
    const double exact = s.distance(x);
    const double ref = sampled_distance(m, t, x, n_samples);
    if (ref > tol) {
      ++outside;
      EXPECT_NEAR(exact, ref, tol) << "at " << x.transpose();
    } else if (ref < -tol) {
      ++inside;
      EXPECT_LT(exact, 0) << "at " << x.transpose();
      EXPECT_LE(exact, ref + tol) << "inside depth is at least the deepest single pose's";
    }
  }
  EXPECT_GT(outside, 100);
  EXPECT_GT(inside, 100);
}

TEST(Sweep, BallLineMatchesSampledPoses) {
  compare("G0 X0 Y0 Z0\nG1 X1 Y0.5 Z-0.3 F1\n", "ball:d=1,l=1.5", 4000, 2e-5);
  // Level and plunging lines: the same parallelogram (or segment) core.
  compare("G0 X0 Y0 Z0\nG1 X1 Y0.5 F1\n", "ball:d=1,l=1.5", 4000, 2e-5);
  compare("G0 X0 Y0 Z0\nG1 Z-0.6 F1\n", "ball:d=1,l=1.5", 4000, 2e-5);
  compare("G0 X0 Y0 Z0\nG1 Z0.4 F1\n", "ball:d=1,l=1.5", 4000, 2e-5);
}

TEST(Sweep, FlatHorizontalLineMatchesSampledPoses) {
  compare("G0 X0 Y0 Z0\nG1 X1 Y-0.7 F1\n", "flat:d=1,l=1", 4000, 2e-5);
}

TEST(Sweep, FlatRampMatchesSampledPoses) {
  compare("G0 X0 Y0 Z0\nG1 X1 Y0.3 Z-0.4 F1\n", "flat:d=1,l=1", 4000, 2e-5);
}

TEST(Sweep, BullRampMatchesSampledPoses) {
  compare("G0 X0 Y0 Z0\nG1 X-1 Y0.3 Z0.4 F1\n", "bull:d=1,r=0.2,l=1", 4000, 2e-5);
}

TEST(Sweep, FlatG17ArcMatchesSampledPoses) {
  compare("G0 X1 Y0 Z0\nG3 X-1 Y0 R1 F1\n", "flat:d=1,l=1", 8000, 2e-5);
}

TEST(Sweep, BallHelixChordsMatchSampledPoses) {
  compare("G0 X1 Y0 Z0\nG2 X0 Y-1 Z-0.5 I-1 J0 F1\n", "ball:d=1,l=1", 8000, 2e-5);
}

TEST(Sweep, BallG18ArcChordsMatchSampledPoses) {
  compare("G18 G0 X1 Y0 Z0\nG2 X-1 Z0 I-1 K0 F1\n", "ball:d=1,l=1", 8000, 2e-5);
}

// The pieces `sweep::lipschitz` vouches for change by no more than the
// distance moved, inside as well as outside: the stock update bounds a
// voxel by a value at another point on that promise.
void check_lipschitz(const std::string& program, const std::string& tool_spec, bool expect) {
  const motion::Move m = single_move(program);
  const sweep::Sweep s = sweep::sweep_move(m, tool::parse_tool_spec(tool_spec), sweep::SweepOptions{1e-6});
  ASSERT_FALSE(s.prims.empty());
  std::mt19937_64 rng(7);
  for (const auto& p : s.prims) {
    EXPECT_EQ(sweep::lipschitz(p), expect) << program;
    if (!expect) continue;
    const Aabb b = sweep::bounds(p).expanded(0.2);
    std::uniform_real_distribution<double> ux(b.min.x(), b.max.x()), uy(b.min.y(), b.max.y()), uz(b.min.z(), b.max.z());
    std::normal_distribution<double> step(0, 0.05);
    int inside = 0;
    for (int i = 0; i < 4000; ++i) {
      const Vec3 x(ux(rng), uy(rng), uz(rng)), y = x + Vec3(step(rng), step(rng), step(rng));
      const double dx = sweep::distance(p, x), dy = sweep::distance(p, y);
      inside += dx < 0 && dy < 0;
      ASSERT_LE(std::fabs(dx - dy), (x - y).norm() * (1 + 1e-9) + 1e-12)
          << program << " at " << x.transpose() << " and " << y.transpose();
    }
    EXPECT_GT(inside, 200) << program;
  }
}

// A long flute tilting as it moves, with only its lower part inside the
// region (the stock): the orientation held over a piece only needs to
// hold for that part, so far fewer pieces are cut, and inside the region
// the sweep is still within the tolerance of densely sampled poses.
TEST(Sweep, PosesCappedToTheRegionKeepTheToleranceInsideIt) {
  const tool::Shape shape = tool::cutting_shape(tool::parse_tool_spec("ball:d=1,l=6", "test"));
  auto pose_at = [](double t) {
    Pose p = Pose::Identity();
    p.linear() = Eigen::AngleAxisd(0.6 * t, Vec3::UnitY()).toRotationMatrix();
    p.translation() = Vec3(1.5 * t, 0.2 * t, -0.3);
    return p;
  };
  const double tol = 1e-3;
  const Aabb region{Vec3(-1.5, -1.5, -1.5), Vec3(3, 1.5, 0.6)};
  const sweep::Sweep capped = sweep::sweep_poses(pose_at, shape, tol, 4, &region);
  const sweep::Sweep full = sweep::sweep_poses(pose_at, shape, tol, 4);
  EXPECT_LT(capped.prims.size() * 3, full.prims.size()) << capped.prims.size() << " vs " << full.prims.size();
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> ux(region.min.x(), region.max.x()), uy(region.min.y(), region.max.y()),
      uz(region.min.z(), region.max.z());
  int near = 0;
  for (int i = 0; i < 4000; ++i) {
    const Vec3 x(ux(rng), uy(rng), uz(rng));
    double ref = std::numeric_limits<double>::infinity();
    for (int k = 0; k <= 3000; ++k) ref = std::min(ref, tool::shape_distance(shape, pose_at(k / 3000.0).inverse() * x));
    if (ref <= 0 || ref > 0.3) continue;  // outside, near the swept surface
    ++near;
    EXPECT_NEAR(capped.distance(x), ref, 1.2 * tol) << "at " << x.transpose();
  }
  EXPECT_GT(near, 300);
}

TEST(Sweep, ConvexPiecesGiveTheirDistanceAndATangentPlaneBelowIt) {
  // The stock update skips a piece at a voxel when the tangent plane from
  // an earlier voxel already clears the bar: the plane must stay below.
  std::mt19937_64 rng(11);
  int checked = 0;
  std::vector<std::pair<std::string, sweep::Sweep>> sweeps;
  for (const char* program : {"G0 X0 Y0 Z0\nG1 X1 Y0.4 Z-0.3 F1\n", "G0 X0 Y0 Z0\nG1 X-0.2 Y0.7 Z0.5 F1\n",
                              "G0 X0 Y0 Z0\nG1 X0.6 Y-0.5 F1\n", "G0 X0 Y0 Z0\nG1 Z-0.7 F1\n", "G0 X0 Y0 Z0\nG1 Z0.3 F1\n"})
    sweeps.emplace_back(program, sweep::sweep_move(single_move(program), tool::parse_tool_spec("ball:d=1,l=1")));
  // A tilted axis (the piece's frame rotated): the same, through the rotation.
  const Eigen::Matrix3d R = Eigen::AngleAxisd(0.4, Vec3(0.3, 1, 0.2).normalized()).toRotationMatrix();
  sweeps.emplace_back("tilted", sweep::sweep_line(Vec3(0, 0, 0), Vec3(0.8, -0.3, 0.2), R, tool::parse_tool_spec("ball:d=1,l=1")));
  for (const auto& [program, s] : sweeps) {
    ASSERT_EQ(s.prims.size(), 1u);
    const auto& p = s.prims[0];
    const Aabb b = sweep::bounds(p).expanded(0.3);
    std::uniform_real_distribution<double> ux(b.min.x(), b.max.x()), uy(b.min.y(), b.max.y()), uz(b.min.z(), b.max.z());
    for (int i = 0; i < 3000; ++i) {
      const Vec3 x(ux(rng), uy(rng), uz(rng)), y(ux(rng), uy(rng), uz(rng));
      double dx = 0;
      Vec3 g;
      ASSERT_TRUE(sweep::convex_distance(p, x, &dx, &g));
      EXPECT_EQ(dx, sweep::distance(p, x));
      EXPECT_LE(g.norm(), 1 + 1e-12);
      EXPECT_GE(sweep::distance(p, y), dx + g.dot(y - x) - 1e-12) << program << " from " << x.transpose() << " to "
                                                                 << y.transpose();
      // Off the core the plane touches: the gradient matches the distance's slope.
      const double e = 1e-7;
      if (dx > -0.45) {
        const Vec3 fd((sweep::distance(p, x + Vec3(e, 0, 0)) - sweep::distance(p, x - Vec3(e, 0, 0))) / (2 * e),
                      (sweep::distance(p, x + Vec3(0, e, 0)) - sweep::distance(p, x - Vec3(0, e, 0))) / (2 * e),
                      (sweep::distance(p, x + Vec3(0, 0, e)) - sweep::distance(p, x - Vec3(0, 0, e))) / (2 * e));
        EXPECT_NEAR((fd - g).norm(), 0, 1e-5) << program << " at " << x.transpose();
        ++checked;
      }
    }
  }
  EXPECT_GT(checked, 6000);
  // Other pieces say no.
  const sweep::Sweep arc =
      sweep::sweep_move(single_move("G17 G0 X1 Y0 Z0\nG3 X-1 Y0 I-1 J0 F1\n"), tool::parse_tool_spec("flat:d=0.6,l=1"));
  double d = 0;
  Vec3 g;
  EXPECT_FALSE(sweep::convex_distance(arc.prims.at(0), Vec3(0, 1, 0), &d, &g));
}

// A fly-cutter's torus is not convex, but on its cutting side (not nearer
// the spindle axis than the tube's core circle) it lies above a convex
// function equal to it there, so the stock update may cull tori with the
// tangent plane as it does ball ends. Nearer the axis it must say no.
TEST(Sweep, FlyCutterTorusGivesATangentPlaneBelowItOnItsCuttingSide) {
  const tool::SwingTorus st{3, 0.5};
  const Eigen::Matrix3d R = Eigen::AngleAxisd(0.3, Vec3(0.2, 0.1, 1).normalized()).toRotationMatrix();
  std::vector<sweep::Primitive> tori;
  for (const Eigen::Matrix3d& m : {Eigen::Matrix3d(Eigen::Matrix3d::Identity()), R}) {
    Pose pose = Pose::Identity();
    pose.linear() = m;
    pose.translation() = Vec3(0.2, -0.1, -0.05);
    tori.push_back(sweep::sweep_tori({pose}, st).prims.at(0));
  }
  std::mt19937_64 rng(17);
  int planes = 0, refused = 0, slopes = 0;
  for (const auto& p : tori) {
    const auto& tp = std::get<sweep::TorusPrim>(p);
    const Aabb whole = sweep::bounds(p).expanded(0.5);
    // Near the tip, where it cuts, and anywhere in and around the torus.
    const Aabb tip{tp.origin - Vec3(1.2, 1.2, 0.3), tp.origin + Vec3(1.2, 1.2, 0.6)};
    for (const Aabb& b : {tip, whole}) {
      std::uniform_real_distribution<double> ux(b.min.x(), b.max.x()), uy(b.min.y(), b.max.y()), uz(b.min.z(), b.max.z());
      for (int i = 0; i < 4000; ++i) {
        const Vec3 x(ux(rng), uy(rng), uz(rng));
        const Vec3 local = tp.to_local * (x - tp.origin);
        const double u = std::hypot(local.x(), local.z() - st.swing);
        double dx = 0;
        Vec3 g = Vec3::Zero();
        const bool ok = sweep::convex_distance(p, x, &dx, &g);
        // The torus at rest, in its own frame: the same distance.
        EXPECT_NEAR(sweep::distance(p, x), tool::shape_distance(tool::Shape(st), local), 1e-12);
        if (u < st.swing - st.nose_radius - 1e-9) {
          EXPECT_FALSE(ok) << "at " << x.transpose();
          ++refused;
          continue;
        }
        if (u <= st.swing - st.nose_radius + 1e-9) continue;  // on the edge: either
        ASSERT_TRUE(ok) << "at " << x.transpose();
        ++planes;
        EXPECT_EQ(dx, sweep::distance(p, x));
        EXPECT_LE(g.norm(), 1 + 1e-12);
        for (int j = 0; j < 8; ++j) {
          // Anywhere: near x (where the plane is tight), and across the torus.
          const Vec3 y = j < 4 ? Vec3(x + 0.05 * Vec3(ux(rng) - x.x(), uy(rng) - x.y(), uz(rng) - x.z()))
                               : Vec3(ux(rng), uy(rng), uz(rng));
          EXPECT_GE(sweep::distance(p, y), dx + g.dot(y - x) - 1e-12) << "from " << x.transpose() << " to "
                                                                     << y.transpose();
        }
        const double e = 1e-7;
        if (std::hypot(u - (st.swing - st.nose_radius), local.y()) > 1e-3) {
          const Vec3 fd((sweep::distance(p, x + Vec3(e, 0, 0)) - sweep::distance(p, x - Vec3(e, 0, 0))) / (2 * e),
                        (sweep::distance(p, x + Vec3(0, e, 0)) - sweep::distance(p, x - Vec3(0, e, 0))) / (2 * e),
                        (sweep::distance(p, x + Vec3(0, 0, e)) - sweep::distance(p, x - Vec3(0, 0, e))) / (2 * e));
          EXPECT_NEAR((fd - g).norm(), 0, 1e-5) << "at " << x.transpose();
          ++slopes;
        }
      }
    }
  }
  EXPECT_GT(planes, 8000);
  EXPECT_GT(slopes, 8000);
  EXPECT_GT(refused, 1000);  // the inside of the swing, nearer the axis
  // The plane is tight where the fly-cut needs it: a voxel (10 um) beside
  // the tip, the torus lies within 0.1 um of it (the cone bound, last
  // value less the step, is 10 um below).
  const auto& p = tori[0];
  const Vec3 x = std::get<sweep::TorusPrim>(p).origin + Vec3(0.3, 0.2, 0.01);
  double dx = 0;
  Vec3 g;
  ASSERT_TRUE(sweep::convex_distance(p, x, &dx, &g));
  const Vec3 y = x + Vec3(0.01, 0, 0);
  EXPECT_LT(sweep::distance(p, y) - (dx + g.dot(y - x)), 1e-4);
}

// A fly-cutter revolution's box, cut to the stock's reach: only the tip's
// few micrometres reach into the stock, so the box must hold every point
// of the torus within the reach, and little more (the stock bins each
// torus into the leaves its box covers).
TEST(Sweep, FlyCutterTorusBoxClippedToTheReachHoldsAllOfItThere) {
  const tool::SwingTorus st{18, 2};
  const Eigen::Matrix3d R = Eigen::AngleAxisd(0.02, Vec3(1, 0.5, 0).normalized()).toRotationMatrix();
  const Aabb reach{Vec3(-1.05, -0.05, -0.55), Vec3(1.05, 10.05, 0.05)};  // a fly-cut's stock, grown 50 um
  std::mt19937_64 rng(23);
  std::uniform_real_distribution<double> unit(0, 1);
  int within = 0;
  for (const Eigen::Matrix3d& m : {Eigen::Matrix3d(Eigen::Matrix3d::Identity()), R}) {
    Pose pose = Pose::Identity();
    pose.linear() = m;
    pose.translation() = Vec3(0.3, 4, -0.003);
    sweep::Sweep s = sweep::sweep_tori({pose}, st);
    sweep::clip_bounds(s, reach);
    const Aabb b = sweep::bounds(s.prims.at(0));
    if (m.isIdentity()) {  // (tilted 20 mrad, the reach's far corners lift the top)
      EXPECT_LT(b.max.y() - b.min.y(), 1.0);  // the whole tube is 4 mm across
      EXPECT_LT(b.max.z() - b.min.z(), 0.06);
    }
    // Points of the solid torus near its tip: the swing angle within 0.1 rad
    // of the bottom, anywhere around the tube, any depth in it.
    for (int i = 0; i < 200000; ++i) {
      const double th = 0.1 * (2 * unit(rng) - 1), ph = 2 * M_PI * unit(rng), rho = st.nose_radius * std::sqrt(unit(rng));
      const double u = st.swing - st.nose_radius + rho * std::cos(ph);
      const Vec3 local(u * std::sin(th), rho * std::sin(ph), st.swing - u * std::cos(th));
      const Vec3 w = pose * local;
      if (!reach.contains(w)) continue;
      ++within;
      ASSERT_TRUE(b.expanded(1e-12).contains(w)) << "torus point " << w.transpose() << " outside the clipped box";
    }
  }
  EXPECT_GT(within, 200);
}

// A piece whose distance is its core's less a radius (ball end line,
// hull, fly-cutter torus) is bounded above by the distance to x's nearest
// core point: d(y) <= d(x) + g . (y - x) + |y - x|^2 / 2D, D = d(x) + radius.
// The stock update drops, per quarter of a leaf, the pieces whose planes
// clear that bound of the nearest one; a bound too low would lose cuts.
TEST(Sweep, CorePiecesAreBoundedAboveByTheirNearestCorePoint) {
  const Eigen::Matrix3d R = Eigen::AngleAxisd(0.4, Vec3(0.3, 1, 0.2).normalized()).toRotationMatrix();
  std::vector<std::pair<std::string, sweep::Primitive>> pieces;
  pieces.emplace_back("ball line", sweep::sweep_line(Vec3(0, 0, 0), Vec3(0.8, -0.3, 0.2), R, tool::parse_tool_spec("ball:d=1,l=1")).prims.at(0));
  pieces.emplace_back("ball plunge", sweep::sweep_move(single_move("G0 X0 Y0 Z0\nG1 Z-0.7 F1\n"), tool::parse_tool_spec("ball:d=1,l=1")).prims.at(0));
  pieces.emplace_back("hull", sweep::hull_prim(Vec3(0, 0, 0.5), Vec3(0.1, 0.2, 2.5), Vec3(1.0, 0.3, 0.4), Vec3(1.3, -0.4, 2.3), 0.5));
  Pose pose = Pose::Identity();
  pose.linear() = R;
  pieces.emplace_back("torus", sweep::sweep_tori({pose}, tool::SwingTorus{3, 0.5}).prims.at(0));
  std::mt19937_64 rng(29);
  std::uniform_real_distribution<double> step(-0.2, 0.2);
  for (const auto& [what, p] : pieces) {
    EXPECT_FALSE(std::isnan(sweep::core_radius(p))) << what;
    const Aabb b = std::holds_alternative<sweep::TorusPrim>(p) ? Aabb{Vec3(-1.5, -1, -0.3), Vec3(1.5, 1, 1)}
                                                               : sweep::bounds(p).expanded(0.3);
    std::uniform_real_distribution<double> ux(b.min.x(), b.max.x()), uy(b.min.y(), b.max.y()), uz(b.min.z(), b.max.z());
    int checked = 0, bent = 0;
    for (int i = 0; i < 20000; ++i) {
      const Vec3 x(ux(rng), uy(rng), uz(rng));
      double dx = 0;
      Vec3 g;
      if (!sweep::convex_distance(p, x, &dx, &g)) continue;
      const double D = dx + sweep::core_radius(p);
      if (!(D > 0)) continue;
      const Vec3 h(step(rng), step(rng), step(rng));
      const double bound = dx + g.dot(h) + h.squaredNorm() / (2 * D);
      EXPECT_LE(sweep::distance(p, x + h), bound + 1e-12) << what << " from " << x.transpose() << " by " << h.transpose();
      bent += sweep::distance(p, x + h) > dx + g.dot(h) + 1e-12;  // the plane alone is not enough
      ++checked;
    }
    EXPECT_GT(checked, 5000) << what;
    EXPECT_GT(bent, 100) << what;
  }
  // Other pieces have no core radius.
  const sweep::Sweep arc =
      sweep::sweep_move(single_move("G17 G0 X1 Y0 Z0\nG3 X-1 Y0 I-1 J0 F1\n"), tool::parse_tool_spec("flat:d=0.6,l=1"));
  EXPECT_TRUE(std::isnan(sweep::core_radius(arc.prims.at(0))));
}

// A ball end turning while it moves becomes hull pieces: the core's hull
// at the two ends of each piece, grown by the ball. A roll about the
// motion turns the axis out of the motion's plane (the hull is then a
// true tetrahedron and its thickness splits it); a turn within that plane
// (a tool held on a wall's normal) leaves it flat. Both against 3000
// sampled poses, from both sides. Holding an orientation would take some
// 1,200 pieces for either (top x half turn <= tolerance, 2,048 after the
// bisection); the roll takes about as many hulls (its thickness is about
// the shorter of the step and the top's turn), the plane turn far fewer.
TEST(Sweep, TurningBallEndHullsKeepTheToleranceInFewPieces) {
  const tool::Shape shape = tool::cutting_shape(tool::parse_tool_spec("ball:d=1,l=4", "test"));
  const double tol = 1e-3;
  struct Case { const char* what; double roll, pitch; std::size_t max_pieces; };
  for (const Case& c : {Case{"roll about the motion", 0.5, 0.0, 2049}, Case{"turn in the motion's plane", 0.0, 0.6, 64}}) {
    SCOPED_TRACE(c.what);
    auto pose_at = [&](double t) {
      Pose p = Pose::Identity();
      p.linear() = (Eigen::AngleAxisd(c.roll * t, Vec3::UnitX()) * Eigen::AngleAxisd(c.pitch * t, Vec3::UnitY())).toRotationMatrix();
      p.translation() = Vec3(1.5 * t, 0, -0.3);
      return p;
    };
    const sweep::Sweep s = sweep::sweep_poses(pose_at, shape, tol, 4);
    ASSERT_FALSE(s.prims.empty());
    EXPECT_TRUE(std::holds_alternative<sweep::HullPrim>(s.prims[0]));
    EXPECT_LT(s.prims.size(), c.max_pieces);
    RecordProperty(c.pitch > 0 ? "plane_turn_pieces" : "roll_pieces", static_cast<int>(s.prims.size()));
    std::mt19937_64 rng(5);
    const Aabb b = s.bounds;
    std::uniform_real_distribution<double> ux(b.min.x(), b.max.x()), uy(b.min.y(), b.max.y()), uz(b.min.z(), b.max.z());
    int near = 0;
    for (int i = 0; i < 3000; ++i) {
      const Vec3 x(ux(rng), uy(rng), uz(rng));
      double ref = std::numeric_limits<double>::infinity();
      for (int k = 0; k <= 3000; ++k) ref = std::min(ref, tool::shape_distance(shape, pose_at(k / 3000.0).inverse() * x));
      if (ref <= -0.3 || ref > 0.3) continue;  // near the swept surface, on either side
      ++near;
      ASSERT_NEAR(s.distance(x), ref, 1.2 * tol) << "at " << x.transpose();
    }
    EXPECT_GT(near, 300);
  }
}

// The hull piece's distance is exact (against the nearest of a dense cloud
// of the tetrahedron's points) and convex: its tangent plane stays below.
TEST(Sweep, HullPieceDistanceIsExactAndConvex) {
  // A true tetrahedron (volume 0.25).
  const sweep::HullPrim hp = sweep::hull_prim(Vec3(0, 0, 0.5), Vec3(0.1, 0.2, 2.5), Vec3(1.0, 0.3, 0.4), Vec3(1.3, -0.4, 2.3), 0.5);
  const sweep::Primitive p = hp;
  std::vector<Vec3> cloud;
  const int n = 40;
  for (int i = 0; i <= n; ++i)
    for (int j = 0; i + j <= n; ++j)
      for (int k = 0; i + j + k <= n; ++k) {
        const double a = double(i) / n, b = double(j) / n, c = double(k) / n;
        cloud.push_back(a * hp.p[0] + b * hp.p[1] + c * hp.p[2] + (1 - a - b - c) * hp.p[3]);
      }
  std::mt19937_64 rng(3);
  const Aabb box = hp.bounds.expanded(0.3);
  std::uniform_real_distribution<double> ux(box.min.x(), box.max.x()), uy(box.min.y(), box.max.y()), uz(box.min.z(), box.max.z());
  const double spacing = 2.5 / n;  // the cloud's farthest gap from the solid, less than this
  int inside = 0;
  for (int i = 0; i < 400; ++i) {
    const Vec3 x(ux(rng), uy(rng), uz(rng)), y(ux(rng), uy(rng), uz(rng));
    double near = std::numeric_limits<double>::infinity();
    for (const Vec3& q : cloud) near = std::min(near, (q - x).squaredNorm());
    const double d = sweep::distance(p, x);
    EXPECT_LE(d, std::sqrt(near) - hp.radius + 1e-12) << "at " << x.transpose();
    EXPECT_GE(d, std::sqrt(near) - hp.radius - spacing) << "at " << x.transpose();
    double dx = 0;
    Vec3 g;
    ASSERT_TRUE(sweep::convex_distance(p, x, &dx, &g));
    EXPECT_EQ(dx, d);
    EXPECT_GE(sweep::distance(p, y), dx + g.dot(y - x) - 1e-12) << "from " << x.transpose() << " to " << y.transpose();
    inside += d == -hp.radius;
  }
  EXPECT_GT(inside, 0);  // some fall inside the core
  EXPECT_TRUE(sweep::lipschitz(p));

  // Hulls flat up to rounding (a tilted core translated, as a piece of a
  // move that does not turn), at awkward places: their faces' sides are
  // noise and must not call a point beside them inside. Against the
  // parallelogram's own distance, a closed form.
  std::uniform_real_distribution<double> w(-1, 1);
  int checked = 0;
  for (int trial = 0; trial < 400; ++trial) {
    const Vec3 a = 30 * Vec3(w(rng), w(rng), w(rng)), u = Vec3(w(rng), w(rng), w(rng)).normalized() * 2.3,
               v = 0.01 * Vec3(w(rng), w(rng), w(rng));
    const sweep::Primitive flat = sweep::hull_prim(a, a + u, a + v, a + v + u, 0.5);
    for (int i = 0; i < 50; ++i) {
      const Vec3 x = a + 0.5 * (u + v) + 0.6 * Vec3(w(rng), w(rng), w(rng));
      const Vec3 r = x - a;
      const double uu = u.dot(u), vv = v.dot(v), uv = u.dot(v), det = uu * vv - uv * uv;
      const double s = (r.dot(v) * uu - r.dot(u) * uv) / det, t = (r.dot(u) * vv - r.dot(v) * uv) / det;
      auto seg = [&](const Vec3& p0, const Vec3& p1) {
        const double k = std::clamp((x - p0).dot(p1 - p0) / (p1 - p0).squaredNorm(), 0.0, 1.0);
        return (x - p0 - k * (p1 - p0)).norm();
      };
      const double ref = s >= 0 && s <= 1 && t >= 0 && t <= 1
                             ? (r - s * v - t * u).norm()
                             : std::min({seg(a, a + u), seg(a + v, a + v + u), seg(a, a + v), seg(a + u, a + u + v)});
      ASSERT_NEAR(sweep::distance(flat, x), ref - 0.5, 1e-9) << "hull " << trial << " at " << x.transpose();
      ++checked;
    }
  }
  EXPECT_EQ(checked, 20000);
}

TEST(Sweep, DistancesMarkedLipschitzAreLipschitzInsideToo) {
  check_lipschitz("G0 X0 Y0 Z0\nG1 X1 Y0.4 Z-0.3 F1\n", "ball:d=1,l=1", true);    // ball ramp: parallelogram core
  check_lipschitz("G0 X0 Y0 Z0\nG1 X1 Y0.4 F1\n", "flat:d=1,l=1", true);          // horizontal
  check_lipschitz("G0 X0 Y0 Z0\nG1 Z-0.5 F1\n", "bull:d=1,r=0.2,l=1", true);       // vertical
  check_lipschitz("G17 G0 X1 Y0 Z0\nG3 X-1 Y0 I-1 J0 F1\n", "flat:d=0.6,l=1", true);  // G17 arc
  check_lipschitz("G0 X0 Y0 Z0\nG1 X1 Z-0.3 F1\n", "flat:d=1,l=1", false);        // flat ramp: a 1-D search
}

}  // namespace
TEST(Sweep, VToolPlaningPrismIsOneLipschitz) {
  // The stock's culling takes a piece's distance at one point, less the
  // way to another, as a bound there; for a V tool's prism that holds
  // where it moves in the plane of its cutting direction and axis
  // (sweep::lipschitz), inside and outside, across the bisector and the
  // ends. Random pairs near the prism, the move lowering by 1 in 8.
  const tool::Tool t = tool::parse_tool_spec("vtool:angle=90,h=0.05", "test");
  const sweep::Sweep s = sweep::sweep_line(Vec3(0, 0, 0), Vec3(0.02, 0, -0.0025), Eigen::Matrix3d::Identity(), t);
  ASSERT_EQ(s.prims.size(), 1u);
  ASSERT_TRUE(sweep::lipschitz(s.prims[0]));
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> ux(-0.01, 0.03), uy(-0.03, 0.03), uz(-0.01, 0.04), step(-0.002, 0.002);
  double worst = 0;
  int inside = 0;
  for (int i = 0; i < 200000; ++i) {
    const Vec3 x(ux(rng), uy(rng), uz(rng));
    const Vec3 y = x + Vec3(step(rng), step(rng), step(rng));
    const double dx = sweep::distance(s.prims[0], x), dy = sweep::distance(s.prims[0], y);
    inside += dx < 0;
    worst = std::max(worst, std::fabs(dx - dy) / (x - y).norm());
  }
  EXPECT_GT(inside, 10000);
  EXPECT_LE(worst, 1 + 1e-9);
  // Sideways, the two sides lean differently: not claimed.
  const sweep::Sweep side = sweep::sweep_line(Vec3(0, 0, 0), Vec3(0.02, 0.005, 0), Eigen::Matrix3d::Identity(), t);
  EXPECT_FALSE(sweep::lipschitz(side.prims[0]));
}

// The stock update passes over a round nose's or a sideways prism's
// distance at a voxel where its section bound, worked out at the quarter's
// centre, clears the bar: the prism must never lie below it. Nose and V
// tools, moves sheared sideways and up or down, a tilted tool frame; pairs
// near the prism, inside and out, and past its ends. Each part of the
// bound is needed: the plane alone passes above the prism outside, the
// plane within the length alone past its ends, past an end the plane
// without the end's drift (shear), and inside the way to the nearer end.
TEST(Sweep, ProfilePrismLiesAboveItsSectionBound) {
  std::mt19937_64 rng(23);
  int checked = 0, inside = 0, plane_above = 0, length_above = 0, past_used = 0, drift_needed = 0, end_inside = 0;
  for (const PrismMove& cs : prism_moves()) {
    const sweep::Sweep s =
        sweep::sweep_line(prism_start, prism_start + cs.move, cs.frame, tool::parse_tool_spec(cs.spec, "test"));
    ASSERT_EQ(s.prims.size(), 1u) << cs.spec;
    const auto& p = s.prims[0];
    const Aabb b = sweep::bounds(p).expanded(0.05);
    std::uniform_real_distribution<double> ux(b.min.x(), b.max.x()), uy(b.min.y(), b.max.y()), uz(b.min.z(), b.max.z());
    std::uniform_real_distribution<double> step(-0.06, 0.06);
    for (int i = 0; i < 40000; ++i) {
      const Vec3 x(ux(rng), uy(rng), uz(rng));
      const Vec3 y = i % 2 ? Vec3(ux(rng), uy(rng), uz(rng)) : Vec3(x + Vec3(step(rng), step(rng), step(rng)));
      sweep::SectionPlane sp;
      ASSERT_TRUE(sweep::prism_section_plane(p, x, &sp)) << cs.spec;
      const double dy = sweep::distance(p, y);
      EXPECT_GE(dy, sweep::section_bound(sp, y - x) - 1e-12) << cs.spec << " from " << x.transpose() << " to "
                                                            << y.transpose();
      inside += dy < 0;
      const double plane = sp.c + sp.g.dot(y - x);
      plane_above += dy < plane - 1e-9;
      length_above += dy < (plane >= 0 ? sp.f_min * plane : plane) - 1e-9;
      const double px = sp.px + sp.axis.dot(y - x);
      const double past = std::max(sp.lo - px, px - sp.hi);
      if (past > 0) {
        past_used += sp.f_min * (plane - past * sp.shear) > past + 1e-9;  // the section's term bounds it, not the way past
        drift_needed += dy < sp.f_min * plane - 1e-9;
      } else {
        end_inside += plane < past - 1e-9;  // the nearer end bounds it, not the plane
      }
      ++checked;
    }
  }
  EXPECT_EQ(checked, 200000);
  EXPECT_GT(inside, 20000);
  EXPECT_GT(plane_above, 100);
  EXPECT_GT(length_above, 100);
  EXPECT_GT(past_used, 1000);
  EXPECT_GT(drift_needed, 100);
  EXPECT_GT(end_inside, 1000);
  // Other pieces say no.
  const sweep::Sweep ball = sweep::sweep_line(Vec3(0, 0, 0), Vec3(1, 0, 0), Eigen::Matrix3d::Identity(),
                                              tool::parse_tool_spec("ball:d=1", "test"));
  sweep::SectionPlane sp;
  EXPECT_FALSE(sweep::prism_section_plane(ball.prims.at(0), Vec3(0, 0, 0), &sp));
}

// The stock update passes a whole quarter over where the section bound's
// least over the quarter clears its deepest voxel's bar: that least must
// lie below the bound (and so the prism) at every voxel of the cube, and
// it must not be idle: where the cube lies beside the prism it clears
// zero, and past an end the way past bounds it.
TEST(Sweep, SectionBoundOverACubeIsBelowItAtEveryVoxel) {
  std::mt19937_64 rng(29);
  const Eigen::Matrix3d R = Eigen::AngleAxisd(0.7, Vec3(1, 0.3, -0.2).normalized()).toRotationMatrix();
  const std::vector<std::pair<const char*, Vec3>> cases = {
      {"vtool:angle=90,h=0.1", Vec3(0.002, 0, -0.0004)},
      {"vtool:angle=60,h=0.05", Vec3(-0.003, 0.001, 0.001)},
      {"nose:r=0.05,angle=60", Vec3(0.01, 0.003, 0.008)},
  };
  const double h = 0.0005, w = 1.5 * h;
  int cubes = 0, positive = 0, past_end = 0;
  for (const auto& [spec, move] : cases)
    for (const Eigen::Matrix3d& frame : {Eigen::Matrix3d(Eigen::Matrix3d::Identity()), Eigen::Matrix3d(R)}) {
      const sweep::Sweep s = sweep::sweep_line(Vec3(0, 0, 0), move, frame, tool::parse_tool_spec(spec, "test"));
      ASSERT_EQ(s.prims.size(), 1u) << spec;
      const auto& p = s.prims[0];
      const Aabb b = sweep::bounds(p).expanded(0.004);
      std::uniform_real_distribution<double> ux(b.min.x(), b.max.x()), uy(b.min.y(), b.max.y()), uz(b.min.z(), b.max.z());
      for (int i = 0; i < 4000; ++i) {
        const Vec3 c(ux(rng), uy(rng), uz(rng));
        sweep::SectionPlane sp;
        ASSERT_TRUE(sweep::prism_section_plane(p, c, &sp)) << spec;
        const double least = sweep::section_bound_over(sp, w);
        double lowest = std::numeric_limits<double>::infinity();
        for (int q = 0; q < 64; ++q) {
          const Vec3 y = h * Vec3((q >> 4) - 1.5, ((q >> 2) & 3) - 1.5, (q & 3) - 1.5);
          const double at = sweep::section_bound(sp, y);
          lowest = std::min(lowest, at);
          EXPECT_GE(sweep::distance(p, c + y), least - 1e-12) << spec << " at " << (c + y).transpose();
        }
        EXPECT_LE(least, lowest + 1e-15) << spec << " at " << c.transpose();
        positive += least > 0;
        const double e = w * sp.axis.cwiseAbs().sum();
        past_end += std::max(sp.lo - (sp.px + e), (sp.px - e) - sp.hi) > least - 1e-15 && least > 0;
        ++cubes;
      }
    }
  EXPECT_EQ(cubes, 24000);
  EXPECT_GT(positive, 5000);
  EXPECT_GT(past_end, 500);
}

TEST(Sweep, VToolPrismIsItsPlanesInsideAndTheExtrusionOfItsSectionOutside) {
  // A 60 deg V tool lowering by 1 in 8 along its cutting direction: the
  // piece is a prism whose sides lean by the motion. Inside, its distance
  // is the largest of its five planes' (two sides, top, two ends), here
  // worked out from the geometry; the piece gives its side and top
  // factors once, and a wrong one shows as a different value.
  const double H = 0.05, L = 0.02, dz = -0.0025;
  const tool::Tool t = tool::parse_tool_spec("vtool:angle=60,h=0.05", "test");
  const sweep::Sweep s = sweep::sweep_line(Vec3(0, 0, 0), Vec3(L, 0, dz), Eigen::Matrix3d::Identity(), t);
  ASSERT_EQ(s.prims.size(), 1u);
  const double k = dz / L, sh = 0.5, ch = std::sqrt(0.75);  // sin and cos of the half angle
  const double side_n = std::sqrt(1 + k * k * sh * sh), top_n = std::sqrt(1 + k * k);
  auto planes = [&](const Vec3& p) {
    const double zp = p.z() - k * p.x();  // height above the tip's path
    const double side = (std::fabs(p.y()) * ch - zp * sh) / side_n;
    const double top = (zp - H) / top_n;
    return std::max({side, top, -p.x(), p.x() - L});
  };
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> ux(-0.005, 0.025), uy(-0.03, 0.03), uz(-0.01, 0.06);
  int inside = 0, outside = 0, boxed = 0;
  for (int i = 0; i < 100000; ++i) {
    const Vec3 p(ux(rng), uy(rng), uz(rng));
    const double d = sweep::distance(s.prims[0], p), want = planes(p);
    if (want < 0) {
      ++inside;
      EXPECT_NEAR(d, want, 1e-15) << p.transpose();
    } else if (const double along = std::fabs(p.y()) * sh + (p.z() - k * p.x()) * ch;
               p.x() > 0 && p.x() < L && along > 0 && along < H / ch) {
      // Beside a side face (between the normals at its ends, the apex and
      // the top corner) and within the piece's length: the side plane's,
      // or the way to the piece's box where that is more (near the ends,
      // where the leaning face's nearest point lies beyond them).
      ++outside;
      const Aabb& b = sweep::bounds(s.prims[0]);
      const double box = (b.min - p).cwiseMax(p - b.max).cwiseMax(0.0).norm();
      EXPECT_NEAR(d, std::max(want, box), 1e-15) << p.transpose();
      boxed += box > want;
    }
  }
  EXPECT_GT(inside, 10000);
  EXPECT_GT(outside, 10000);
  EXPECT_GT(boxed, 0);
  EXPECT_LT(boxed, outside / 10);
  // Level (no lean): below the tip the nearest point is on its path.
  const sweep::Sweep level = sweep::sweep_line(Vec3(0, 0, 0), Vec3(L, 0, 0), Eigen::Matrix3d::Identity(), t);
  EXPECT_NEAR(sweep::distance(level.prims[0], Vec3(0.01, 0.001, -0.002)), std::hypot(0.001, 0.002), 1e-15);
  EXPECT_NEAR(sweep::distance(level.prims[0], Vec3(L + 0.003, 0, 0.01)), 0.003, 1e-15);
}

}  // namespace cutsim::test

namespace cutsim::test {
namespace {
// Whether the ball of `radius` about `p` lies in the region `uni` is
// negative in, as far as 26 points of its surface tell.
::testing::AssertionResult ball_inside(const Vec3& p, double radius, const std::function<double(const Vec3&)>& uni) {
  for (int dx = -1; dx <= 1; ++dx)
    for (int dy = -1; dy <= 1; ++dy)
      for (int dz = -1; dz <= 1; ++dz) {
        if (dx == 0 && dy == 0 && dz == 0) continue;
        const Vec3 q = p + radius * (1 - 1e-9) * Vec3(dx, dy, dz).normalized();
        if (uni(q) > 1e-12)
          return ::testing::AssertionFailure() << "ball about " << p.transpose() << " radius " << radius << ": "
                                               << q.transpose() << " outside by " << uni(q);
      }
  return ::testing::AssertionSuccess();
}

// Straight moves of `tool` through `tips` at orientation R: their prisms,
// and the joint piece of prism `mid` with its neighbours, slab half width w.
struct Chain {
  std::vector<sweep::Primitive> prisms;
  sweep::Primitive joint;
};
Chain chain_of(const std::string& tool, const std::vector<Vec3>& tips, std::size_t mid, double w) {
  const tool::Tool t = tool::parse_tool_spec(tool, "test");
  Chain c;
  std::vector<sweep::ProfilePrim> pp;
  for (std::size_t i = 0; i + 1 < tips.size(); ++i) {
    c.prisms.push_back(sweep::sweep_line(tips[i], tips[i + 1], Eigen::Matrix3d::Identity(), t).prims[0]);
    pp.push_back(std::get<sweep::ProfilePrim>(c.prisms.back()));
  }
  for (std::size_t i = 0; i + 1 < pp.size(); ++i) EXPECT_TRUE(sweep::joinable(pp[i], pp[i + 1])) << tool << " " << i;
  const auto j = sweep::joint_prim(mid > 0 ? &pp[mid - 1] : nullptr, pp[mid], mid + 1 < pp.size() ? &pp[mid + 1] : nullptr,
                                   w, Aabb{});
  EXPECT_TRUE(j.has_value());
  c.joint = j ? sweep::Primitive(*j) : c.prisms[0];
  return c;
}
}  // namespace

TEST(Sweep, PrismDrawnBackOverACrestLiesInTheCut) {
  // Over a crest (the slope falls from move to move, as a V tool planes
  // over the snowflake's dome) the Joiner closes each joint by drawing the
  // next prism back 2 half widths along its own line instead of a
  // JointPrim. The longer prism must lie in the moves' cut: where it is
  // negative, the ball of that radius lies in the union of the prisms as
  // the moves made them (26 points of its surface), and outside it is no
  // nearer than that union.
  const double w = 0.001;  // the band's half width: 2 um drawn back
  const tool::Tool v = tool::parse_tool_spec("vtool:angle=90,h=0.05", "test");
  const Eigen::Matrix3d I = Eigen::Matrix3d::Identity();
  const Aabb reach{Vec3(-1, -1, -1), Vec3(1, 1, 0.01)};  // the V's top (50 um up) stays above it
  auto run = [&](auto z, int n, double step, const Aabb& r, std::vector<sweep::ProfilePrim>* made,
                 std::vector<sweep::ProfilePrim>* drawn) {
    sweep::Joiner join(w, r);
    for (int k = 0; k < n; ++k) {
      sweep::Sweep s = sweep::sweep_line(Vec3(step * k, 0, z(step * k)), Vec3(step * (k + 1), 0, z(step * (k + 1))), I, v);
      if (made) made->push_back(std::get<sweep::ProfilePrim>(s.prims[0]));
      join(s);
      if (drawn) drawn->push_back(std::get<sweep::ProfilePrim>(s.prims[0]));
    }
    join.finish();
    return std::make_pair(join.extended(), join.joints());
  };
  auto crest = [](double x) { return -0.01 - 0.5 * (x - 0.01) * (x - 0.01) - 0.02 * x; };  // slope falls
  std::vector<sweep::ProfilePrim> made, drawn;
  const auto [ext, joints] = run(crest, 10, 0.002, reach, &made, &drawn);
  EXPECT_EQ(ext, 9u);  // every joint: the first prism alone is 2 um, as far as is drawn back
  EXPECT_EQ(joints, 0u);
  auto uni = [&](const Vec3& p) {
    double d = std::numeric_limits<double>::infinity();
    for (const auto& q : made) d = std::min(d, sweep::distance(sweep::Primitive(q), p));
    return d;
  };
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-1, 1);
  int inside = 0;
  for (std::size_t k = 1; k < drawn.size(); ++k) {
    const sweep::Primitive ext_k(drawn[k]);
    EXPECT_NEAR((drawn[k].origin - made[k].origin).x(), -2 * w, 1e-12);
    const Vec3 at = made[k].origin;  // the joint
    for (int i = 0; i < 4000; ++i) {
      const Vec3 p = at + Vec3(0.003 * u(rng), 0.012 * u(rng), 0.006 + 0.008 * u(rng));
      const double d = sweep::distance(ext_k, p), un = uni(p);
      if (d >= 0) {
        ASSERT_GE(d, un - 1e-12) << "outside at " << p.transpose();
        continue;
      }
      ++inside;
      ASSERT_TRUE(ball_inside(p, -d, uni));
    }
  }
  EXPECT_GT(inside, 5000);
  // Drawn back over a valley it would stand below the path: JointPrims.
  auto valley = [](double x) { return -0.02 + 0.5 * (x - 0.01) * (x - 0.01) + 0.02 * x; };  // slope rises
  EXPECT_EQ(run(valley, 10, 0.002, reach, nullptr, nullptr), std::make_pair(std::size_t{0}, std::size_t{10}));
  // Moves of 1.5 um: the crest must have run 2 um behind a joint.
  EXPECT_EQ(run(crest, 10, 0.0015, reach, nullptr, nullptr).first, 8u);
  // Where the V's top reaches into the material, its lifted strip would
  // cut there: JointPrims (a straight line lifts nothing: drawn back).
  const Aabb deep{Vec3(-1, -1, -1), Vec3(1, 1, 0.1)};
  EXPECT_EQ(run(crest, 10, 0.002, deep, nullptr, nullptr).first, 0u);
  EXPECT_EQ(run([](double) { return -0.01; }, 10, 0.002, deep, nullptr, nullptr).first, 9u);
}

TEST(Sweep, CrestPieceLiesInThePrismsAndGivesTheFlanksDepth) {
  // Over a crest the cut is the union of the two prisms drawn on over the
  // joint (sweep::crest_prim): where the piece is negative, the ball of
  // that radius lies in the union of the moves' prisms (26 points of its
  // surface; the moves before and after close it, as on a path), outside
  // it is no nearer than that union, and it is 1-Lipschitz. Sharp crests,
  // gentle ones, a short move before the joint, and a crest that follows
  // a valley.
  const double w = 0.001;
  const tool::Tool v = tool::parse_tool_spec("vtool:angle=90,h=0.05", "test");
  const Eigen::Matrix3d I = Eigen::Matrix3d::Identity();
  const std::vector<std::vector<Vec3>> paths = {
      {Vec3(-0.01, 0, 0), Vec3(0, 0, 0), Vec3(0.0035, 0, 0.003), Vec3(0.0135, 0, 0.003), Vec3(0.02, 0, 0.003)},  // rise, flat
      {Vec3(-0.01, 0, 0), Vec3(0, 0, 0), Vec3(0.002, 0, 0.0002), Vec3(0.012, 0, 0.0005), Vec3(0.02, 0, 0.0005)},  // gentle
      {Vec3(-0.01, 0, 0.004), Vec3(0, 0, 0.004), Vec3(0.0035, 0, 0.004), Vec3(0.0135, 0, 0.001), Vec3(0.02, 0, 0.001)},  // fall
      {Vec3(-0.01, 0, 0), Vec3(0, 0, 0.003), Vec3(0.0015, 0, 0.0045), Vec3(0.0115, 0, 0.0), Vec3(0.02, 0, 0.0)},  // 1.5 um
  };
  std::mt19937 rng(17);
  std::uniform_real_distribution<double> u(-1, 1);
  for (std::size_t pi = 0; pi < paths.size(); ++pi) {
    const auto& tips = paths[pi];
    std::vector<sweep::Primitive> prisms;
    std::vector<sweep::ProfilePrim> pp;
    for (std::size_t i = 0; i + 1 < tips.size(); ++i) {
      prisms.push_back(sweep::sweep_line(tips[i], tips[i + 1], I, v).prims[0]);
      pp.push_back(std::get<sweep::ProfilePrim>(prisms.back()));
    }
    // The crest between the second and third moves.
    const auto c = sweep::crest_prim(pp[1], pp[2], w, Aabb{});
    ASSERT_TRUE(c.has_value()) << pi;
    const sweep::Primitive crest(*c);
    EXPECT_TRUE(sweep::lipschitz(crest));
    auto uni = [&](const Vec3& p) {
      double d = std::numeric_limits<double>::infinity();
      for (const auto& q : prisms) d = std::min(d, sweep::distance(q, p));
      return d;
    };
    const Vec3 at = tips[2];  // the joint
    int inside = 0;
    for (int i = 0; i < 20000; ++i) {
      const Vec3 p = at + Vec3(0.004 * u(rng), 0.01 * u(rng), 0.004 + 0.006 * u(rng));
      const double g = sweep::distance(crest, p), un = uni(p);
      if (g >= 0) {
        ASSERT_GE(g, un - 1e-12) << pi << " outside at " << p.transpose();
        continue;
      }
      ++inside;
      ASSERT_TRUE(ball_inside(p, -g, uni)) << pi;
    }
    EXPECT_GT(inside, 1000) << pi;
    double worst = 0;
    for (int i = 0; i < 20000; ++i) {
      const Vec3 p = at + Vec3(0.004 * u(rng), 0.01 * u(rng), 0.004 + 0.006 * u(rng));
      const Vec3 q = p + 0.001 * Vec3(u(rng), u(rng), u(rng));
      worst = std::max(worst, std::fabs(sweep::distance(crest, p) - sweep::distance(crest, q)) / (p - q).norm());
    }
    EXPECT_LE(worst, 1 + 1e-9) << pi;
  }
  // A rise of slope 6/7 then flat: 1 um before the joint, 2 um above the
  // path. Each prism says at most 1 um deep there (the rise's end cap);
  // the intersection of the two drawn on (a valley's piece) less still;
  // the crest's piece, the rise's flank: 2 um / sqrt 2, leaning by the
  // slope (its normal ~ (-6/7, -1, 1)), with its slab reaching 3 um back
  // (a 1.5 um band).
  const auto& tips = paths[0];
  const sweep::ProfilePrim rise = std::get<sweep::ProfilePrim>(sweep::sweep_line(tips[1], tips[2], I, v).prims[0]);
  const sweep::ProfilePrim flat = std::get<sweep::ProfilePrim>(sweep::sweep_line(tips[2], tips[3], I, v).prims[0]);
  const Vec3 p(0.0025, 0, 0.003 * 2.5 / 3.5 + 0.002);
  const double s = 0.003 / 0.0035, flank = 0.002 / std::sqrt(2.0) / std::sqrt(1 + s * s / 2);
  EXPECT_GE(sweep::distance(sweep::Primitive(rise), p), -0.001 - 1e-15);
  EXPECT_GE(sweep::distance(sweep::Primitive(flat), p), 0.0);
  EXPECT_GT(sweep::distance(sweep::Primitive(*sweep::joint_prim(nullptr, rise, &flat, 0.0015, Aabb{})), p), -0.001);
  EXPECT_NEAR(sweep::distance(sweep::Primitive(*sweep::crest_prim(rise, flat, 0.0015, Aabb{})), p), -flank, 1e-12);
}

TEST(Sweep, JointPieceLiesInThePrismsAndBoundsTheirUnionsDepth) {
  // Where moves of a V (or nose) tool follow each other at one orientation,
  // a prism's joint piece with its neighbours must hold (sweep::JointPrim):
  // where it is negative, the ball of that radius about the point lies in
  // the prisms' union (its depth a lower bound of the union's; checked on
  // 26 points of the ball's surface), and where it is not, it is no nearer
  // than the union. Three moves with kinks up and down, gentle and steep (a
  // convex kink's far prism comes nearer than the near one's end cap would
  // say), the first or last of two, a bend sideways and a round nose.
  const double w = 0.0015;
  struct Case {
    const char* tool;
    std::vector<Vec3> tips;
    std::size_t mid;
    bool lipschitz;
  };
  const char* v90 = "vtool:angle=90,h=0.05";
  const Case cases[] = {
      {v90, {Vec3(-0.01, 0, 0), Vec3(0, 0, 0), Vec3(0.002, 0, 0), Vec3(0.012, 0, 0)}, 1, true},  // straight
      {v90, {Vec3(-0.01, 0, 0), Vec3(0, 0, 0), Vec3(0.002, 0, 0.0006), Vec3(0.012, 0, 0)}, 1, true},  // up, down
      {v90, {Vec3(-0.01, 0, 0.003), Vec3(0, 0, 0), Vec3(0.002, 0, -0.0006), Vec3(0.012, 0, 0.002)}, 1, true},
      {"vtool:angle=60,h=0.05", {Vec3(-0.002, 0, 0.006), Vec3(0, 0, 0), Vec3(0.002, 0, 0.006)}, 0, true},  // steep
      {"vtool:angle=60,h=0.05", {Vec3(-0.002, 0, 0.006), Vec3(0, 0, 0), Vec3(0.002, 0, 0.006)}, 1, true},
      {v90, {Vec3(-0.01, 0, 0), Vec3(0, 0, 0), Vec3(0.01, 0.002, 0)}, 0, false},  // sideways
      {"nose:r=0.01", {Vec3(-0.01, 0, 0.001), Vec3(0, 0, 0), Vec3(0.01, 0, 0.002)}, 1, false},  // round nose
  };
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-1, 1);
  for (const Case& k : cases) {
    const Chain c = chain_of(k.tool, k.tips, k.mid, w);
    EXPECT_EQ(sweep::lipschitz(c.joint), k.lipschitz) << k.tool;
    auto uni = [&](const Vec3& p) {
      double d = std::numeric_limits<double>::infinity();
      for (const auto& q : c.prisms) d = std::min(d, sweep::distance(q, p));
      return d;
    };
    const Vec3 at = k.tips[k.mid];  // the middle prism's start
    int inside = 0;
    for (int i = 0; i < 20000; ++i) {
      const Vec3 p = at + Vec3(0.001 + 0.004 * u(rng), 0.01 * u(rng), 0.004 + 0.006 * u(rng));
      const double g = sweep::distance(c.joint, p), un = uni(p);
      if (g >= 0) {
        ASSERT_GE(g, un - 1e-12) << k.tool << " outside at " << p.transpose();
        continue;
      }
      ++inside;
      ASSERT_LE(un, 0.0) << k.tool << " at " << p.transpose();
      if (!k.lipschitz) continue;  // a first-order depth: the sign only
      ASSERT_TRUE(ball_inside(p, -g, uni)) << k.tool;
    }
    EXPECT_GT(inside, 1000) << k.tool;
    if (k.lipschitz) {
      double worst = 0;
      for (int i = 0; i < 20000; ++i) {
        const Vec3 p = at + Vec3(0.001 + 0.004 * u(rng), 0.01 * u(rng), 0.004 + 0.006 * u(rng));
        const Vec3 q = p + 0.001 * Vec3(u(rng), u(rng), u(rng));
        worst = std::max(worst, std::fabs(sweep::distance(c.joint, p) - sweep::distance(c.joint, q)) / (p - q).norm());
      }
      EXPECT_LE(worst, 1 + 1e-9) << k.tool;
    }
  }
  // Straight on, 3 um above the tip, in the middle of a 2 um move: each
  // prism's end cap says at most 1 um deep there; the joint piece, the
  // flanks' 2.1 um (3 / sqrt 2).
  const Chain s = chain_of(v90, {Vec3(-0.01, 0, 0), Vec3(0, 0, 0), Vec3(0.002, 0, 0), Vec3(0.012, 0, 0)}, 1, w);
  const Vec3 in(0.001, 0, 0.003);
  for (const auto& q : s.prisms) EXPECT_GE(sweep::distance(q, in), -0.001 - 1e-15);
  EXPECT_NEAR(sweep::distance(s.joint, in), -0.003 / std::sqrt(2.0), 1e-15);
  // Not joinable: turned, reversed, apart, or another edge.
  const tool::Tool v = tool::parse_tool_spec(v90, "test");
  const Eigen::Matrix3d I = Eigen::Matrix3d::Identity();
  const Eigen::Matrix3d turned = Eigen::AngleAxisd(0.1, Vec3::UnitZ()).toRotationMatrix();
  auto prism = [&](const Vec3& p0, const Vec3& p1, const Eigen::Matrix3d& R, const tool::Tool& t) {
    return std::get<sweep::ProfilePrim>(sweep::sweep_line(p0, p1, R, t).prims[0]);
  };
  const sweep::ProfilePrim first = prism(Vec3(-0.01, 0, 0), Vec3(0, 0, 0), I, v);
  EXPECT_TRUE(sweep::joinable(first, prism(Vec3(0, 0, 0), Vec3(0.01, 0, 0.001), I, v)));
  EXPECT_FALSE(sweep::joinable(first, prism(Vec3(0, 0, 0), Vec3(0.01, 0, 0), turned, v)));
  EXPECT_FALSE(sweep::joinable(first, prism(Vec3(0, 0, 0), Vec3(-0.005, 0, 0.001), I, v)));
  EXPECT_FALSE(sweep::joinable(first, prism(Vec3(0, 1e-6, 0), Vec3(0.01, 0, 0), I, v)));
  EXPECT_FALSE(sweep::joinable(first, prism(Vec3(0, 0, 0), Vec3(0.01, 0, 0), I, tool::parse_tool_spec("vtool:angle=60,h=0.05", "test"))));
  // A prism with no neighbour gets no piece.
  EXPECT_FALSE(sweep::joint_prim(nullptr, first, nullptr, w, Aabb{}));
}

}  // namespace cutsim::test
