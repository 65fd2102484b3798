// Diamond tools, tool libraries and contacts of the non-cutting regions,
// checked against the geometry of each case.
#include <gtest/gtest.h>

#include <cmath>
#include <initializer_list>
#include <random>
#include <set>
#include <sstream>

#include "cutsim/core/error.h"
#include "cutsim/io/tool_library.h"
#include "cutsim/sim/interference.h"
#include "cutsim/sweep/sweep.h"
#include "helpers.h"

#include <tbb/task_arena.h>

namespace cutsim::test {
namespace {

sim::SimResult run_with(const TempDir& dir, const std::string& program, const std::string& tool_spec, const Aabb& stock,
                        double voxel) {
  return run_program(dir, program, tool_spec, stock, voxel);
}

std::set<int> contact_lines(const sim::SimResult& r) {
  std::set<int> s;
  for (const auto& c : r.contacts) s.insert(c.line);
  return s;
}

// Two rows, each: enter horizontally, climb at `deg` in the cutting
// direction (+X) for 1.5 mm, then fall at `deg` and leave the stock.
std::string slope_program(double deg) {
  const double t = std::tan(deg * kPi / 180);
  std::ostringstream os;
  os.precision(10);
  for (double y : {-0.6, 0.6}) {
    os << "G0 X-1 Y" << y << " Z1\n"
       << "G0 Z-0.3\n"
       << "G1 X0.5 F200\n"
       << "G1 X2 Z" << -0.3 + 1.5 * t << "\n"
       << "G1 X5.5 Z" << -0.3 + 1.5 * t - 3.5 * t << "\n"
       << "G0 Z1\n";
  }
  os << "M30\n";
  return os.str();
}

// The same contacts (every field the report gives) and the same cut.
void expect_same_contacts(const sim::SimResult& want, const sim::SimResult& got, const std::string& what) {
  ASSERT_EQ(got.contacts.size(), want.contacts.size()) << what;
  for (std::size_t i = 0; i < want.contacts.size(); ++i) {
    const auto &a = want.contacts[i], &b = got.contacts[i];
    EXPECT_EQ(a.line, b.line) << what << ", contact " << i;
    EXPECT_EQ(a.region, b.region) << what << ", line " << a.line;
    EXPECT_EQ(a.rapid, b.rapid) << what << ", line " << a.line;
    EXPECT_EQ(a.depth_mm, b.depth_mm) << what << ", line " << a.line;
    EXPECT_EQ(a.where, b.where) << what << ", line " << a.line;
    EXPECT_EQ(a.at_least, b.at_least) << what << ", line " << a.line;
    EXPECT_EQ(a.poses, b.poses) << what << ", line " << a.line;
  }
  EXPECT_EQ(got.stock->removed_volume_mm3(), want.stock->removed_volume_mm3()) << what;
}

}  // namespace

// Where the path falls in the cutting direction, the surface the nose has
// just cut lies above the path behind the edge, by L tan(slope) at L behind;
// the clearance face rises only L tan(clearance). So the flank rubs exactly
// where the cut surface climbs behind the tool (the issue's "cutting up a
// slope": up the slope towards the tool's back) more steeply than the
// clearance angle, and never where the path climbs in the cutting direction.
TEST(Interference, RoundNoseFlankTouchesOnlyWhereTheSlopeBeatsTheClearance) {
  TempDir dir;
  const Aabb stock{Vec3(0, -1.5, -1), Vec3(4, 1.5, 0)};
  const std::string tool = "nose:r=0.5,clearance=5";
  const auto gentle = run_with(dir, slope_program(3), tool, stock, 0.02);
  EXPECT_TRUE(gentle.contacts.empty()) << sim::format_contact(gentle.contacts.front(), "prog.nc");

  const auto steep = run_with(dir, slope_program(8), tool, stock, 0.02);
  // Lines 5 and 11 fall at 8 deg; 4 and 10 climb; the rest are level or in air.
  EXPECT_EQ(contact_lines(steep), (std::set<int>{5, 11}));
  // One record per line: consecutive poses merge.
  ASSERT_EQ(steep.contacts.size(), 2u);
  // The overlap can be no thicker than the gap at the body's back,
  // L (tan 8 - tan 5) cos 5 with L = 1 mm (the body length): 52.9 um.
  const double bound = 1.0 * (std::tan(8 * kPi / 180) - std::tan(5 * kPi / 180)) * std::cos(5 * kPi / 180);
  for (const auto& c : steep.contacts) {
    EXPECT_EQ(c.region, "clearance-face");
    EXPECT_FALSE(c.rapid);
    EXPECT_GT(c.poses, 1);
    EXPECT_GT(c.depth_mm, 0.01);
    EXPECT_LE(c.depth_mm, bound + 0.02);  // + one voxel
    EXPECT_GT(c.where.x(), 2.0);           // on the falling part
    EXPECT_LE(c.where.x(), 4.0 + 0.02);
  }
}

// A 90 deg V tool planing a raster at 8 um pick feed, 10 um deep. Adjacent
// V grooves meet at p / (2 tan 45) = 4 um above their bottoms.
// The clearance faces do not touch the cusps here: on a level raster each
// flank lies behind its edge inside the groove that edge has just cut,
// shrunk by L tan(7 deg) at L behind, and a cusp is the meeting of this
// groove's wall (cut by the edge) with the last one's, so it is outside
// the flank. (They touch where the path falls faster than the clearance
// allows: see the slope test and the snowflake case.)
TEST(Interference, VToolRasterLeavesClosedFormCuspsAndNoFlankContact) {
  TempDir dir;
  std::ostringstream os;
  const double pick = 0.008, depth = 0.010;
  for (int j = 0; j < 10; ++j)
    os << "G0 X-0.05 Y" << j * pick << " Z0.01\nG1 Z" << -depth << " F50\nG1 X0.15\nG0 Z0.01\n";
  os << "M30\n";
  const double h = 0.0005;
  const auto r = run_with(dir, os.str(), "vtool:angle=90,clearance=7", Aabb{Vec3(0, -0.02, -0.05), Vec3(0.1, 0.09, 0)}, h);
  EXPECT_TRUE(r.contacts.empty()) << sim::format_contact(r.contacts.front(), "prog.nc");
  double bottoms = 0, tops = 0;
  int nb = 0, nt = 0;
  for (int j = 1; j <= 8; ++j) {
    // Lowest point near groove j, highest near the cusp after it.
    double lo = 1, hi = -1;
    for (double y = j * pick - 0.002; y <= j * pick + 0.002; y += h / 4)
      lo = std::min(lo, r.stock->surface_height(0.05, y, 0.005));
    for (double y = (j + 0.5) * pick - 0.002; y <= (j + 0.5) * pick + 0.002; y += h / 4)
      hi = std::max(hi, r.stock->surface_height(0.05, y, 0.005));
    EXPECT_NEAR(lo, -depth, 0.6 * h) << "groove " << j;
    bottoms += lo;
    ++nb;
    if (j < 8) {
      EXPECT_NEAR(hi, -depth + pick / 2, 0.8 * h) << "cusp after groove " << j;
      tops += hi;
      ++nt;
    }
  }
  const double cusp = tops / nt - bottoms / nb;
  EXPECT_NEAR(cusp, pick / 2 / std::tan(kPi / 4), 0.8 * h);
}

// The contact check measures a flank body with its angles' sines worked
// out once per pose: the same values as shape_distance, to the bit.
// The flank (clearance) bodies among a tool's contact regions.
std::vector<tool::FlankBody> flank_bodies(const char* spec) {
  std::vector<tool::FlankBody> out;
  for (const tool::Region& rg : tool::contact_regions(tool::parse_tool_spec(spec, "test")))
    if (const auto* f = std::get_if<tool::FlankBody>(&rg.shape)) out.push_back(*f);
  return out;
}

// Calls fn(spec, body, its sines) for each flank body of each tool spec;
// returns how many there were.
template <class Fn>
int for_each_flank_body(std::initializer_list<const char*> specs, Fn fn) {
  int n = 0;
  for (const char* spec : specs)
    for (const tool::FlankBody& f : flank_bodies(spec)) {
      ++n;
      fn(spec, f, tool::flank_trig(f));
    }
  return n;
}

TEST(Interference, FlankBodyWithItsSinesWorkedOutOnceIsTheShapesDistance) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-0.3, 0.3);
  const int flanks = for_each_flank_body(
      {"vtool:angle=90,clearance=7,h=0.1,body=0.3", "nose:r=0.5,clearance=5"},
      [&](const char* spec, const tool::FlankBody& f, const tool::FlankTrig& trig) {
        for (int i = 0; i < 20000; ++i) {
          const Vec3 p(u(rng), u(rng), u(rng) + 0.2);
          ASSERT_EQ(tool::flank_distance(f, trig, p), tool::shape_distance(tool::Shape(f), p))
              << spec << " " << p.transpose();
        }
      });
  EXPECT_EQ(flanks, 2);
}

// The contact scan bounds a quarter's voxels by the flank body's tangent
// plane at its centre: the plane must lie below the body's distance
// everywhere (the body is convex), and the value must be flank_distance's.
TEST(Interference, FlankBodysTangentPlaneLiesBelowItsDistance) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-0.3, 0.3);
  int kinks = 0;
  std::set<int> terms;  // which of the four terms were largest at x
  const int flanks = for_each_flank_body(
      {"vtool:angle=90,clearance=7,h=0.1,body=0.3", "vtool:angle=60,clearance=12,h=0.05,body=0.2",
       "nose:r=0.5,clearance=5"},
      [&](const char* spec, const tool::FlankBody& fb, const tool::FlankTrig& trig) {
        const tool::FlankBody* f = &fb;
        for (int i = 0; i < 4000; ++i) {
          const Vec3 x(u(rng), u(rng), u(rng) + 0.1);
          Vec3 g = Vec3::Constant(std::nan(""));
          const double dx = tool::flank_distance(*f, trig, x, &g);
          ASSERT_EQ(dx, tool::flank_distance(*f, trig, x));
          ASSERT_LE(g.norm(), 1 + 1e-12);
          const Vec3 dxc(f->edge.cos_o, f->edge.sin_o, 0);
          terms.insert(g == Vec3::UnitZ()                                    ? 0   // top
                       : g == -dxc                                           ? 1   // back end
                       : g == Vec3(trig.c_rake * dxc + trig.s_rake * Vec3::UnitZ()) ? 2   // rake face
                                                                             : 3);  // flank
          // Near x (the scan's quarters) and far from it.
          for (int j = 0; j < 25; ++j) {
            const double r = j % 2 ? 0.002 : 0.3;
            const Vec3 y = x + r * Vec3(u(rng), u(rng), u(rng));
            ASSERT_GE(tool::flank_distance(*f, trig, y) + 1e-13, dx + g.dot(y - x))
                << spec << " at " << x.transpose() << " to " << y.transpose();
          }
          // And it is that term's gradient: along g a small step raises the
          // distance by |g|^2 times the step, up to the kinks.
          const double e = 1e-7;
          const double fd = (tool::flank_distance(*f, trig, x + e * g) - dx) / e;
          if (std::fabs(fd - g.squaredNorm()) > 1e-4) ++kinks;  // a kink within 1e-7 of x: rare
        }
      });
  EXPECT_EQ(flanks, 3);
  EXPECT_LT(kinks, 12);
  EXPECT_EQ(terms.size(), 4u) << "each of the four terms largest somewhere";
}

const char* const kVTool = "vtool:angle=90,clearance=7,h=0.1,body=0.3";

// A block planed by the V tool in five grooves along x, `pitch` apart and
// `depth` deep, from x = -`half_length` to +`half_length`: cusps for its
// flank body to touch.
stock::Stock grooved_block(const Aabb& box, double voxel, double pitch, double depth, double half_length) {
  stock::StockOptions so;
  so.voxel_mm = voxel;
  stock::Stock s(box, box, so);
  const tool::Tool vt = tool::parse_tool_spec(kVTool, "test");
  for (int k = 0; k < 5; ++k) {
    const double y = pitch * (k - 2.5);
    s.subtract(sweep::sweep_line(Vec3(-half_length, y, -depth), Vec3(half_length, y, -depth),
                                 Eigen::Matrix3d::Identity(), vt));
  }
  return s;
}

// The V tool's flank body at a pose: its distance, its tangent plane (as
// the contact check passes them to the scan) and its box.
struct FlankAt {
  const tool::FlankBody& f;
  tool::FlankTrig trig;
  Pose pose, inv;
  FlankAt(const tool::FlankBody& body, const Pose& at) : f(body), trig(tool::flank_trig(body)), pose(at), inv(at.inverse()) {}
  double operator()(const Vec3& x) const { return tool::flank_distance(f, trig, inv * x); }
  double plane(const Vec3& x, Vec3* g) const {
    Vec3 gl;
    const double d = tool::flank_distance(f, trig, inv * x, &gl);
    *g = pose.linear() * gl;
    return d;
  }
  Aabb bounds() const { return sweep::world_box(tool::shape_bounds(tool::Shape(f)), pose.linear(), pose.translation()); }
};

// A pose along or across the grooves, turned about Z and tilted a little.
Pose random_pose(std::mt19937& rng, const Vec3& centre, const Vec3& spread) {
  std::uniform_real_distribution<double> u(-1, 1);
  Pose pose = Pose::Identity();
  pose.translate(centre + Vec3(spread.x() * u(rng), spread.y() * u(rng), spread.z() * u(rng)));
  pose.rotate(Eigen::AngleAxisd(0.3 * u(rng), Vec3::UnitZ()) * Eigen::AngleAxisd(0.05 * u(rng), Vec3::UnitY()));
  return pose;
}

// With the region's tangent plane (a convex region), the scan passes over
// voxels without evaluating it, and must find the same deepest overlap.
TEST(Interference, OverlapWithTheRegionsTangentPlaneIsTheSame) {
  const stock::Stock s = grooved_block(Aabb{Vec3(-1, -1, -0.5), Vec3(1, 1, 0)}, 0.005, 0.04, 0.01, 0.8);
  const std::vector<tool::FlankBody> bodies = flank_bodies(kVTool);
  ASSERT_EQ(bodies.size(), 1u);
  int touched = 0;
  std::mt19937 rng(3);
  for (int i = 0; i < 40; ++i) {
    const FlankAt flank(bodies[0], random_pose(rng, Vec3(0, 0, -0.012), Vec3(0.5, 0.12, 0.004)));
    auto region = [&](const Vec3& x) { return flank(x); };
    auto plane = [&](const Vec3& x, Vec3* g) { return flank.plane(x, g); };
    const stock::Overlap a = s.overlap(flank.bounds(), region, nullptr, 0.0);
    const stock::Overlap b = s.overlap(flank.bounds(), region, nullptr, 0.0, plane);
    EXPECT_EQ(a.depth_mm, b.depth_mm) << "pose " << i;
    EXPECT_EQ(a.where, b.where) << "pose " << i;
    EXPECT_EQ(a.at_least, b.at_least);
    touched += a.depth_mm > 0;
  }
  EXPECT_GT(touched, 10);
  EXPECT_LT(touched, 40);
}

// With what the move removed so far 1-Lipschitz (a V tool's sweep along its
// cutting direction), the scan passes over whole quarters lying deeper in
// it than their reach. The deepest overlap must be the same as without, and
// the deepest over every voxel by brute force.
TEST(Interference, OverlapPassingOverQuartersTheMoveRemovedIsTheSame) {
  // Grooves 30 um deep at a 30 um pitch, at 2.5 um voxels: quarters 10 um
  // wide lie whole inside the cuts below the top.
  const double h = 0.0025;
  const stock::Stock s = grooved_block(Aabb{Vec3(-0.4, -0.3, -0.15), Vec3(0.4, 0.3, 0)}, h, 0.03, 0.03, 0.35);
  const tool::Tool vt = tool::parse_tool_spec(kVTool, "test");
  const std::vector<tool::FlankBody> bodies = flank_bodies(kVTool);
  ASSERT_EQ(bodies.size(), 1u);
  const double cap = s.band_mm() * (1 - 1e-6);
  const Vec3 o = s.roi_lattice_origin();
  int touched = 0, changed = 0;
  std::mt19937 rng(5);
  for (int i = 0; i < 24; ++i) {
    const FlankAt flank(bodies[0], random_pose(rng, Vec3(0, 0, -0.03), Vec3(0.2, 0.08, 0.01)));
    const Pose& pose = flank.pose;
    // The cut up to this pose: 60 um along the tool's x, one way or the other.
    const Vec3 run = (i % 2 ? 0.06 : -0.06) * pose.linear().col(0);
    const sweep::Sweep cut = sweep::sweep_line(pose.translation() - run, pose.translation(), pose.linear(), vt);
    ASSERT_FALSE(cut.prims.empty());
    for (const sweep::Primitive& p : cut.prims) ASSERT_TRUE(sweep::lipschitz(p)) << "pose " << i;
    auto region = [&](const Vec3& x) { return flank(x); };
    auto plane = [&](const Vec3& x, Vec3* g) { return flank.plane(x, g); };
    auto removed = [&](const Vec3& x, double) { return cut.distance(x); };
    const Aabb bounds = flank.bounds();
    const stock::Overlap none = s.overlap(bounds, region, nullptr, 0.0, plane);
    const stock::Overlap a = s.overlap(bounds, region, removed, 0.0, plane);
    const stock::Overlap b = s.overlap(bounds, region, removed, 0.0, plane, removed);
    const stock::Overlap c = s.overlap(bounds, region, removed, 0.0, nullptr, removed);
    EXPECT_EQ(a.depth_mm, b.depth_mm) << "pose " << i;
    EXPECT_EQ(a.where, b.where) << "pose " << i;
    EXPECT_EQ(a.stock_value, b.stock_value) << "pose " << i;
    EXPECT_EQ(a.at_least, b.at_least) << "pose " << i;
    EXPECT_EQ(a.depth_mm, c.depth_mm) << "pose " << i;
    EXPECT_EQ(a.where, c.where) << "pose " << i;
    // Every voxel of the region's box.
    double deepest = 0;
    const Eigen::Vector3i lo = ((bounds.min - o) / h).array().floor().cast<int>().cwiseMax(0);
    const Eigen::Vector3i hi = ((bounds.max - o) / h).array().ceil().cast<int>();
    for (int x = lo.x(); x <= hi.x(); ++x)
      for (int y = lo.y(); y <= hi.y(); ++y)
        for (int z = lo.z(); z <= hi.z(); ++z) {
          const Vec3 p = o + h * Vec3(x, y, z);
          if (p.z() > h) continue;
          const double mat = std::max(s.sample(p), -cut.distance(p));
          double depth = std::min(-region(p), -mat);
          if (depth >= cap) depth = s.band_mm();
          deepest = std::max(deepest, depth);
        }
    EXPECT_NEAR(b.depth_mm, deepest, 1e-12) << "pose " << i;
    touched += b.depth_mm > 0;
    changed += b.depth_mm != none.depth_mm;
  }
  EXPECT_GT(touched, 4);
  EXPECT_GT(changed, 4) << "the cut must matter to the answer";
}

// The scan lists its leaves through 128^3, 32^3 and 16^3 cubes, each kept
// only where the region can reach it. A ball a few voxels across, deep in
// the material, reaches one to eight leaves wherever it lies (across the
// corners of the 16^3 cubes too): its deepest voxel must be found each time.
TEST(Interference, OverlapOfASmallRegionIsFoundWhereverItLies) {
  const Aabb box{Vec3(0, 0, -0.6), Vec3(0.6, 0.6, 0)};
  stock::StockOptions so;
  so.voxel_mm = 0.01;
  const stock::Stock s(box, box, so);
  const double h = so.voxel_mm, cap = s.band_mm() * (1 - 1e-6);
  const Vec3 o = s.roi_lattice_origin();
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(0, 1);
  for (int i = 0; i < 300; ++i) {
    // Every other ball centred on a corner of the 16^3 cubes (a voxel
    // centre plus half a voxel), the rest anywhere.
    Vec3 c(0.1 + 0.4 * u(rng), 0.1 + 0.4 * u(rng), -0.5 + 0.4 * u(rng));
    if (i % 2 == 0) c = o + h * (16 * ((c - o) / (16 * h)).array().round() - 0.5).matrix();
    const double r = (1 + 1.5 * u(rng)) * h;
    auto sd = [&](const Vec3& x) { return (x - c).norm() - r; };
    const Aabb bounds{c.array() - r, c.array() + r};
    const stock::Overlap ov = s.overlap(bounds, sd, nullptr, 0.0);
    double deepest = 0;
    const Eigen::Vector3i lo = ((bounds.min - o) / h).array().floor().cast<int>();
    const Eigen::Vector3i hi = ((bounds.max - o) / h).array().ceil().cast<int>();
    for (int x = lo.x(); x <= hi.x(); ++x)
      for (int y = lo.y(); y <= hi.y(); ++y)
        for (int z = lo.z(); z <= hi.z(); ++z) {
          const Vec3 p = o + h * Vec3(x, y, z);
          double depth = std::min(-sd(p), -s.sample(p));
          if (depth >= cap) depth = s.band_mm();
          deepest = std::max(deepest, depth);
        }
    ASSERT_GT(deepest, 0) << "ball " << i;
    EXPECT_NEAR(ov.depth_mm, deepest, 1e-12) << "ball " << i << " at (" << c.transpose() << ")";
  }
}

TEST(Interference, ShankContactWhereABallMillPlungesPastItsFlutes) {
  TempDir dir;
  // Flutes 1 mm long, a 3 mm shank above them: plunging 1.5 mm buries the
  // shank's lower end 0.5 mm in the material.
  const std::string prog = "G0 X0 Y0 Z1\nG1 Z-1.5 F100\nM30\n";
  const auto r = run_with(dir, prog, "ball:d=1,l=1,shank_d=3", Aabb{Vec3(-3, -3, -3), Vec3(3, 3, 0)}, 0.02);
  ASSERT_EQ(r.contacts.size(), 1u);
  EXPECT_EQ(r.contacts[0].line, 2);
  EXPECT_EQ(r.contacts[0].region, "shank");
  EXPECT_EQ(r.contacts[0].text, "G1 Z-1.5 F100");
  // The shank's end sits at z = -0.5 at the end of the move.
  EXPECT_LE(r.contacts[0].where.z(), 0.0);
  EXPECT_GE(r.contacts[0].where.z(), -0.5 - 0.02);

  // The same plunge within the flute length touches nothing.
  const auto ok = run_with(dir, "G0 X0 Y0 Z1\nG1 Z-0.9 F100\nM30\n", "ball:d=1,l=1,shank_d=3",
                           Aabb{Vec3(-3, -3, -3), Vec3(3, 3, 0)}, 0.02);
  EXPECT_TRUE(ok.contacts.empty());
}

// Moves are subtracted in batches; the check of a move must still see the
// material the batch's earlier moves removed. A slot 0.5 deep (line 3),
// then the tool goes down to 1.5 and back along it: the 0.8 mm shank above
// the 1 mm flutes (whose envelope, domed, reaches 1.5 above the tip) stays
// inside the 1 mm slot. Without the slot the same moves bury the shank.
TEST(Interference, MovesOfOneBatchSeeTheMaterialTheEarlierOnesRemoved) {
  TempDir dir;
  const std::string tool = "ball:d=1,l=1,shank_d=0.8";
  const Aabb box{Vec3(-2, -2, -2), Vec3(5, 2, 0)};
  const auto r = run_with(dir, "G0 X0 Y0 Z1\nG1 Z-0.5 F100\nG1 X3\nG1 Z-1.5\nG1 X0\nG1 Z1\nM30\n", tool, box, 0.02);
  EXPECT_TRUE(r.contacts.empty()) << r.contacts.size() << " contacts, the first on line " << r.contacts[0].line;
  const auto bare = run_with(dir, "G0 X3 Y0 Z1\nG1 Z-0.5 F100\nG1 Z-1.5\nG1 X0\nG1 Z1\nM30\n", tool, box, 0.02);
  ASSERT_FALSE(bare.contacts.empty());
  bool line4 = false;
  for (const auto& c : bare.contacts) line4 |= c.line == 4 && c.region == "shank";
  EXPECT_TRUE(line4);
}

// Moves are scanned side by side in groups before they are checked in
// order; a scan stands only where nothing was subtracted since, or where
// it found no touch. The contacts (lines, regions, depths, points, poses)
// and the cut must be those of checking one move at a time: on a rapid
// retracting through the slot the moves before it cut (its first poses
// find the held-back cuts' material, whose subtraction must void the
// rest of its scans), a rapid back into that slot, a retract scanned
// before a batch was subtracted, and the nose tool's flank contacts.
TEST(Interference, MovesScannedSideBySideGiveTheContactsOfOneAtATime) {
  TempDir dir;
  struct Case {
    std::string program, tool;
    Aabb box;
  };
  const std::vector<Case> cases = {
      {"G0 X0 Y0 Z1\nG1 Z-0.5 F100\nG1 X3\nG1 Z-1.5\nG1 X0\nG0 Z1\nG0 Z-1\nG0 Z1\nG0 X3\nG1 Z-1.2\nG0 Z1\nM30\n",
       "ball:d=1,l=1,shank_d=0.8", Aabb{Vec3(-2, -2, -2), Vec3(5, 2, 0)}},
      // The batch of eight is subtracted after line 10, in the second group:
      // the retract on line 11 was scanned before that, on the material its
      // lines had not yet cut (and no cut is held back when it is checked).
      {"G0 X0 Y0 Z1\nG1 Z-0.5 F100\nG1 X1\nG1 X2\nG1 X3\nG1 X2.5\nG1 X2\nG1 X1.5\nG1 X1\nG0 Z1\nM30\n",
       "ball:d=1,l=1,shank_d=0.8", Aabb{Vec3(-2, -2, -2), Vec3(5, 2, 0)}},
      {slope_program(8), "nose:r=0.5,clearance=5", Aabb{Vec3(0, -1.5, -1), Vec3(4, 1.5, 0)}},
  };
  for (const Case& c : cases) {
    sim::SimOptions o;
    o.program = dir.write("prog.nc", c.program);
    o.tool = tool::parse_tool_spec(c.tool);
    o.stock_box = c.box;
    o.voxel_mm = 0.02;
    o.check_group = 1;
    const auto one = sim::simulate(o);
    for (const std::size_t group : {std::size_t(8), sim::SimOptions{}.check_group}) {
      o.check_group = group;
      const auto grouped = sim::simulate(o);
      expect_same_contacts(one, grouped, c.program);
    }
  }
}

// Cuts held back in a batch: where a pose's touch lies in material they
// take, the pose is tested again on the stock less the latest of them
// weighed voxel by voxel, and the older ones are subtracted only where
// they would change what that finds. The contacts must be those of
// subtracting every move before the next is checked: a V tool's raster
// whose passes overlap (the pitch is a third of the groove), each falling
// at 13 degrees against its 7 degree clearance (its flank rubs) and
// rising again; all held cuts weighed, the latest 3, and one at a time.
TEST(Interference, ContactsOnTheStockLessTheHeldCutsAreThoseOfMoveByMove) {
  TempDir dir;
  std::ostringstream prog;
  prog << std::fixed;
  prog.precision(6);
  const double fall = std::tan(13 * kPi / 180);
  int moves = 0;
  for (int pass = 0; pass < 6; ++pass) {
    const double y = -0.05 + 0.02 * pass;
    prog << "G0 X-0.16 Y" << y << " Z0.02\nG1 Z-0.01 F100\n";
    for (int i = -15; i <= 15; ++i, ++moves)
      if (const double x = 0.01 * i; true) prog << "G1 X" << x << " Z" << -0.01 - fall * (0.15 - std::abs(x)) << "\n";
    prog << "G0 Z0.02\n";
  }
  prog << "M30\n";
  sim::SimOptions o;
  o.program = dir.write("raster.nc", prog.str());
  o.tool = tool::parse_tool_spec("vtool:angle=90,clearance=7,h=0.1,body=0.3");
  o.stock_box = Aabb{Vec3(-0.2, -0.12, -0.1), Vec3(0.2, 0.12, 0)};
  o.voxel_mm = 0.002;
  o.hold_cuts = false;
  const auto each = sim::simulate(o);
  o.hold_cuts = true;
  const auto held = sim::simulate(o);
  o.latest_cuts = 3;
  const auto latest = sim::simulate(o);
  o.check_group = 1;
  const auto alone = sim::simulate(o);
  // (And every pose weighed, none cleared by its planing run.)
  o.check_group = 8;
  o.latest_cuts = sim::InterferenceChecker::kLatestCuts;
  o.planing_runs = false;
  const auto scanned = sim::simulate(o);
  EXPECT_GT(held.poses_cleared_by_runs, 0);
  EXPECT_EQ(scanned.poses_cleared_by_runs, 0);
  EXPECT_GT(moves, 150);
  // Every move subtracted at once, and the batches: 8, 16, 32, ...
  EXPECT_GT(each.stock->stats().grid_updates, held.stock->stats().grid_updates + 150);
  ASSERT_GT(each.contacts.size(), 50u);
  std::set<int> passes;
  for (const auto& c : each.contacts) passes.insert(c.line / 34);
  EXPECT_GE(passes.size(), 5u) << "every pass's flank rubs";
  expect_same_contacts(each, held, "held back, the latest 400 weighed");
  expect_same_contacts(each, latest, "the latest 3 weighed");
  expect_same_contacts(each, alone, "one move at a time");
  expect_same_contacts(each, scanned, "no planing runs");
}

// The contact check leaves a batch's cuts held back unless they would
// change the voxel where it found the deepest overlap (they only take
// material away, so nowhere else gets deeper). That answer may be yes
// where unsure, but never no where the update changes the voxel: checked
// on every voxel of a block cut by V-tool lines (planing, rising, across)
// and a ball line over a slot.
TEST(Interference, HeldBackCutsAreSaidToChangeEveryVoxelTheyChange) {
  const Aabb box{Vec3(-0.3, -0.3, -0.2), Vec3(0.3, 0.3, 0)};
  stock::StockOptions so;
  so.voxel_mm = 0.005;
  stock::Stock s(box, box, so);
  const Eigen::Matrix3d I = Eigen::Matrix3d::Identity();
  const tool::Tool ball = tool::parse_tool_spec("ball:d=0.2", "test");
  const tool::Tool vtool = tool::parse_tool_spec("vtool:angle=90,clearance=7,h=0.1,body=0.3", "test");
  s.subtract(sweep::sweep_line(Vec3(-0.4, 0.05, -0.04), Vec3(0.4, 0.05, -0.04), I, ball));  // a slot first
  std::vector<sweep::Sweep> cuts;
  cuts.push_back(sweep::sweep_line(Vec3(-0.4, -0.1, -0.02), Vec3(0.4, -0.1, -0.02), I, vtool));
  cuts.push_back(sweep::sweep_line(Vec3(-0.4, 0.0, -0.05), Vec3(0.4, 0.0, -0.01), I, vtool));
  cuts.push_back(sweep::sweep_line(Vec3(0.1, -0.4, -0.03), Vec3(0.1, 0.4, -0.03), I, vtool));
  cuts.push_back(sweep::sweep_line(Vec3(-0.4, -0.4, -0.06), Vec3(0.4, 0.4, -0.02), I, ball));
  auto values = [&] {
    std::vector<std::pair<Vec3, float>> v;
    s.for_each_roi_block([&](const stock::VoxelBlock& b) {
      for (int x = 0; x < b.n[0]; ++x)
        for (int y = 0; y < b.n[1]; ++y)
          for (int z = 0; z < b.n[2]; ++z)
            v.emplace_back(b.first_center + so.voxel_mm * Vec3(x, y, z),
                           b.uniform ? b.value : b.values[(x * 8 + y) * 8 + z]);
    });
    return v;
  };
  // (for_each_roi_block runs in parallel: one thread keeps the order.)
  std::vector<std::pair<Vec3, float>> before, after;
  tbb::task_arena(1).execute([&] { before = values(); });
  std::vector<char> said(before.size());
  for (std::size_t i = 0; i < before.size(); ++i) said[i] = sim::cuts_change_voxel(cuts, s, before[i].first, before[i].second);
  s.subtract(cuts);
  tbb::task_arena(1).execute([&] { after = values(); });
  ASSERT_EQ(after.size(), before.size());
  std::size_t changed = 0, missed = 0, yes = 0;
  for (std::size_t i = 0; i < before.size(); ++i) {
    ASSERT_EQ(after[i].first, before[i].first);
    yes += said[i];
    if (after[i].second == before[i].second) continue;
    ++changed;
    if (!said[i]) {
      if (++missed <= 5)
        ADD_FAILURE() << "voxel at (" << before[i].first.transpose() << ") went " << before[i].second << " -> "
                      << after[i].second << " but the cuts were said to leave it";
    }
  }
  EXPECT_EQ(missed, 0u);
  EXPECT_GT(changed, 20000u);
  // Not yes everywhere: about the voxels the cuts change (those they reach
  // without changing, at most a few in ten more).
  EXPECT_LT(yes, changed + changed / 4) << yes << " said to change, " << changed << " changed";
}

TEST(Interference, DeepestPointIsTheSameWhateverTheThreads) {
  // A region sunk into the block reaches the band's depth (the depth
  // saturates) in hundreds of blocks at once: the point reported must not
  // depend on which thread got there first, or reports do not repeat.
  const Aabb box{Vec3(0, 0, -1), Vec3(2, 2, 0)};
  stock::StockOptions so;
  so.voxel_mm = 0.01;
  const stock::Stock s(box, box, so);
  const Aabb region{Vec3(0.2, 0.2, -0.9), Vec3(1.8, 1.8, 0.1)};
  auto sd = [&](const Vec3& x) { return box_signed_distance(region, x); };
  stock::Overlap one;
  tbb::task_arena(1).execute([&] { one = s.overlap(region, sd, nullptr, 0.0); });
  ASSERT_TRUE(one.at_least);
  EXPECT_NEAR(one.depth_mm, s.band_mm(), 1e-6 * s.band_mm());
  for (int rep = 0; rep < 20; ++rep) {
    stock::Overlap two;
    tbb::task_arena(2).execute([&] { two = s.overlap(region, sd, nullptr, 0.0); });
    EXPECT_EQ(two.depth_mm, one.depth_mm);
    EXPECT_EQ(two.where, one.where) << "run " << rep << ": (" << two.where.transpose() << ") instead of ("
                                    << one.where.transpose() << ")";
  }
}

TEST(Interference, DeepestOverlapIsFoundInTheLastBlocksListed) {
  // The blocks are scanned in chunks as they are listed, each chunk from
  // the deepest depth found before it. A shallow slab, tilted so that it
  // reaches deeper along x and cut off at x = 1.5, lies across the top of
  // the block, shallower than the material under it: its overlap with the
  // material is deepest in the last of the some 500 blocks listed (x runs
  // slowest), below the band, so no chunk stops the listing. The answer must be the deepest over every
  // voxel, found by brute force.
  const Aabb box{Vec3(0, 0, -1), Vec3(2, 2, 0)};
  stock::StockOptions so;
  so.voxel_mm = 0.01;
  const stock::Stock s(box, box, so);
  const double h = so.voxel_mm, g = s.band_mm();
  const Vec3 n = Vec3(0.002, 0, 1).normalized();
  auto sd = [&](const Vec3& x) {
    const double t = n.dot(x);
    return std::max(std::max(t - 0.5, -0.016 - t), x.x() - 1.5);
  };
  stock::Overlap one;
  tbb::task_arena(1).execute([&] { one = s.overlap(box, sd, nullptr, 0.0); });
  double deepest = 0;
  const Vec3 o = s.roi_lattice_origin();
  int voxels = 0;
  for (int i = 0; o.x() + i * h < 2; ++i)
    for (int j = 0; o.y() + j * h < 2; ++j)
      for (int k = 0; o.z() + k * h < 0.01; ++k) {
        const Vec3 p = o + h * Vec3(i, j, k);
        if (p.z() < -0.05) continue;
        deepest = std::max(deepest, std::min(-sd(p), -s.sample(p)));
        ++voxels;
      }
  ASSERT_GT(voxels, 100000);
  ASSERT_GT(deepest, 0.008);
  ASSERT_LT(deepest, 0.9 * g);  // not saturated: every block is scanned
  EXPECT_FALSE(one.at_least);
  EXPECT_NEAR(one.depth_mm, deepest, 1e-9);
  EXPECT_GT(one.where.x(), 1.4);
  EXPECT_NEAR(std::min(-sd(one.where), -s.sample(one.where)), one.depth_mm, 1e-9);
  for (int rep = 0; rep < 10; ++rep) {
    stock::Overlap two;
    tbb::task_arena(2).execute([&] { two = s.overlap(box, sd, nullptr, 0.0); });
    EXPECT_EQ(two.depth_mm, one.depth_mm);
    EXPECT_EQ(two.where, one.where);
  }
}

TEST(Interference, SaturatedDepthsThatDifferInTheLastDigitsTie) {
  // As on the snowflake: the saturated depths differ from voxel to voxel in
  // the 7th digit (material a hair shallower than the band). Past the cap
  // the depth is only "at least the band", so they tie: the first saturated
  // voxel in block order is reported, at the band's depth, on any number of
  // threads (before, the deepest of them, and which thread found it first).
  const Aabb box{Vec3(0, 0, -1), Vec3(2, 2, 0)};
  stock::StockOptions so;
  so.voxel_mm = 0.01;
  const stock::Stock s(box, box, so);
  const double g = s.band_mm();
  const Aabb region{Vec3(0.2, 0.2, -0.9), Vec3(1.8, 1.8, 0.1)};
  // In [g (1 - 1e-7), g] deep, a different depth at every voxel.
  auto wobble = [&](const Vec3& x) {
    const double t = std::sin(x.x() * 7919.0 + x.y() * 104729.0 + x.z() * 1299709.0);
    return g * (1 - 0.5e-7 * (1 + t));
  };
  auto sd = [&](const Vec3& x) { return std::max(box_signed_distance(region, x), -wobble(x)); };
  stock::Overlap one;
  tbb::task_arena(1).execute([&] { one = s.overlap(region, sd, nullptr, 0.0); });
  ASSERT_TRUE(one.at_least);
  EXPECT_EQ(one.depth_mm, g);
  // The point lies at least the band deep inside the region (where the depth
  // saturates); the two-thread runs below must report the same point.
  EXPECT_LE(box_signed_distance(region, one.where), -g);
  int first_blocks = 0;
  for (int rep = 0; rep < 40; ++rep) {
    stock::Overlap two;
    tbb::task_arena(2).execute([&] { two = s.overlap(region, sd, nullptr, 0.0); });
    EXPECT_EQ(two.depth_mm, one.depth_mm);
    first_blocks += two.where == one.where;
  }
  EXPECT_EQ(first_blocks, 40) << "the point reported depends on the threads";
}

TEST(Interference, RapidThroughTheStockIsFlaggedAndARapidAboveIsNot) {
  TempDir dir;
  const std::string prog =
      "G0 X-5 Y0 Z1\n"   // 1: in the air
      "G0 X5\n"          // 2: above the stock
      "G0 Z-0.5\n"       // 3: beside it
      "G0 X-5\n"         // 4: through it
      "G0 Z1\n"          // 5
      "M30\n";
  const auto r = run_with(dir, prog, "ball:d=1", Aabb{Vec3(-2, -2, -1), Vec3(2, 2, 0)}, 0.02);
  ASSERT_EQ(r.contacts.size(), 1u);
  EXPECT_EQ(r.contacts[0].line, 4);
  EXPECT_TRUE(r.contacts[0].rapid);
  EXPECT_EQ(r.contacts[0].region, "cutter");
  EXPECT_TRUE(r.contacts[0].at_least);  // 0.5 mm deep: past the band
  EXPECT_EQ(sim::format_contact(r.contacts[0], "prog.nc").rfind("prog.nc:4: rapid contact (cutter) at least 40 um deep at (", 0), 0u);
}

// The contacts that matter most, out of many: a rapid first however
// shallow, then the holder, shank and neck, then the deepest rubs; in
// program order. The summary counts each kind and finds its deepest.
TEST(Interference, MostSevereContactsPutCrashesBeforeRubs) {
  std::vector<sim::Contact> cs;
  auto add = [&](int line, const char* region, bool rapid, double depth, bool at_least = false) {
    sim::Contact c;
    c.line = line;
    c.region = region;
    c.rapid = rapid;
    c.depth_mm = depth;
    c.at_least = at_least;
    cs.push_back(c);
  };
  for (int i = 0; i < 30; ++i) add(10 + i, "clearance-face", false, 1e-4 * (1 + i % 7));  // deepest 7e-4 at lines 16, 23, 30, 37
  add(50, "shank", false, 2e-4);
  add(60, "clearance-face", false, 1e-3, true);
  add(70, "cutter", true, 1e-5);  // a rapid grazing the stock: still first
  add(80, "holder", false, 1e-5);
  const std::vector<std::size_t> top = sim::most_severe_contacts(cs, 6);
  std::vector<int> lines;
  for (const std::size_t i : top) lines.push_back(cs[i].line);
  EXPECT_EQ(lines, (std::vector<int>{16, 23, 50, 60, 70, 80}));  // rapid, holder, shank, then 1e-3, 7e-4 twice (earliest)
  // Fewer than asked: all of them, in order.
  EXPECT_EQ(sim::most_severe_contacts(cs, 100).size(), cs.size());
  EXPECT_EQ(sim::most_severe_contacts(cs, 100)[33], 33u);

  const std::vector<sim::ContactKind> kinds = sim::summarize_contacts(cs);
  ASSERT_EQ(kinds.size(), 4u);
  EXPECT_EQ(kinds[0].region, "cutter");
  EXPECT_TRUE(kinds[0].rapid);
  EXPECT_EQ(kinds[1].region, "holder");
  EXPECT_EQ(kinds[2].region, "shank");
  EXPECT_EQ(kinds[3].region, "clearance-face");
  EXPECT_EQ(kinds[3].records, 31u);
  EXPECT_EQ(kinds[3].at_least, 1u);
  EXPECT_EQ(cs[kinds[3].deepest].line, 60);
  EXPECT_EQ(kinds[3].first_line, 10);
  EXPECT_EQ(kinds[3].last_line, 60);
}

// A fly-cutter (spindle along Y) fed along X leaves one swing-radius arc
// per revolution: the face is flat to within the scallop
// R - sqrt(R^2 - f^2/4) (R = 5 mm, f = 1 mm/rev: 25.06 um).
TEST(Interference, FlyCutterFaceIsFlatToTheFeedPerRevolutionScallop) {
  TempDir dir;
  const std::string prog = "G0 X-6 Y0 Z0.5\nG0 Z-0.05\nS1000 M3\nG1 X10 F1000\nG0 Z1\nM30\n";
  const double h = 0.002;
  const auto r = run_with(dir, prog, "flycutter:swing=5,r=1", Aabb{Vec3(0, -0.3, -0.5), Vec3(2, 0.3, 0)}, h);
  EXPECT_TRUE(r.contacts.empty());
  const double R = 5, f = 1;
  const double scallop = R - std::sqrt(R * R - f * f / 4);
  double lo = 1, hi = -1;
  for (double x = 0.2; x <= 1.8; x += 0.005) {
    const double z = r.stock->surface_height(x, 0, 0.01);
    lo = std::min(lo, z);
    hi = std::max(hi, z);
  }
  EXPECT_NEAR(lo, -0.05, h / 2);
  EXPECT_NEAR(hi - lo, scallop, h);
  // Marks one feed per revolution apart, cusps halfway (the phase follows
  // the time line from the program's start, rapids included).
  double x_lo = 0.2;
  for (double x = 0.2; x <= 1.0; x += 0.001)
    if (r.stock->surface_height(x, 0, 0.01) < r.stock->surface_height(x_lo, 0, 0.01)) x_lo = x;
  EXPECT_NEAR(r.stock->surface_height(x_lo + f, 0, 0.01), lo, h / 2);
  EXPECT_NEAR(r.stock->surface_height(x_lo + f / 2, 0, 0.01), lo + scallop, h);
}

// The fly-cutter's flywheel (default: 2 nose radii inside the tip circle,
// one nose radius thick) and its arbor (a third of the swing across, along +Y
// behind the flywheel). Fed along X in its swing plane, the tip circle's
// front clears everything the flywheel will occupy, however deep: only
// the arbor, outside that plane, can meet material (cuts deeper than
// swing - arbor radius = 3.33 mm). Fed along Y, the flywheel enters
// material the circle never swept once the cut is deeper than 2 r.
TEST(Interference, FlyCutterFlywheelAndArborTouchWhereTheSwingDoesNotClear) {
  TempDir dir;
  const Aabb stock{Vec3(0, -3, -5), Vec3(2, 3, 0)};
  const std::string tool = "flycutter:swing=5,r=1";
  auto run = [&](const std::string& p) { return run_with(dir, p, tool, stock, 0.02); };
  EXPECT_TRUE(run("G0 X-6 Y0 Z-3\nS1000 M3\nG1 X8 F1000\nG0 Z1\nM30\n").contacts.empty());
  const auto arbor = run("G0 X-6 Y0 Z-4\nS1000 M3\nG1 X8 F1000\nG0 Z1\nM30\n");
  ASSERT_FALSE(arbor.contacts.empty());
  EXPECT_EQ(arbor.contacts[0].line, 3);
  EXPECT_EQ(arbor.contacts[0].region, "shank");
  EXPECT_GE(arbor.contacts[0].where.y(), 0.5);  // behind the flywheel (its back face at holder_l / 2)
  EXPECT_LE(arbor.contacts[0].where.z(), 0.0);
  EXPECT_GE(arbor.contacts[0].where.z(), -4 + 5 - 5.0 / 3 - 0.02);  // above the arbor's underside
  EXPECT_TRUE(run("G0 X1 Y-8 Z-1.5\nS1000 M3\nG1 Y8 F1000\nG0 Z1\nM30\n").contacts.empty());
  const auto wheel = run("G0 X1 Y-8 Z-2.5\nS1000 M3\nG1 Y8 F1000\nG0 Z1\nM30\n");
  ASSERT_FALSE(wheel.contacts.empty());
  EXPECT_EQ(wheel.contacts[0].line, 3);
  EXPECT_EQ(wheel.contacts[0].region, "holder");
  // The flywheel's rim is 2 mm above the tip: in the material from z = -0.5 up.
  EXPECT_GE(wheel.contacts[0].where.z(), -0.5 - 0.02);
  // A flywheel that reaches into the nose is refused.
  EXPECT_THROW(tool::parse_tool_spec("flycutter:swing=5,r=1,holder_d=9,holder_l=1"), ConfigError);
}

// Facing on the xzc lathe with a non-rotating round-nose tool: the tool
// frame turns with C, and the cutting direction (orient 90: the tool
// frame's +Y) follows the rotation, so the tool cuts tangentially. A
// 10 um face over the 2 x 2 mm block, 0.1 mm feed per revolution with a
// 0.5 mm nose: removed = area (depth - f^2 / (24 r)), the mean height of the
// nose-radius scallops subtracted.
TEST(Interference, NoseToolFacesOnTheLatheWithItsOrientationInThePose) {
  TempDir dir;
  std::ostringstream os;
  os.precision(10);
  const double feed = 0.1, depth = 0.01, r = 0.5;
  os << "G0 X3 Z1 C0\nG0 Z" << -depth << "\n";
  const int per_rev = 18;
  const int steps = static_cast<int>(3.0 / feed) * per_rev;
  for (int i = 1; i <= steps; ++i)
    os << "G1 X" << 3.0 - feed * i / per_rev << " C" << 360.0 * i / per_rev << " F1000\n";
  os << "G0 Z1\nM30\n";
  sim::SimOptions o;
  o.program = dir.write("face.nc", os.str());
  o.tool = tool::parse_tool_spec("nose:r=0.5,clearance=7,orient=90");
  o.machine = "xzc";
  o.stock_box = Aabb{Vec3(-1, -1, -1), Vec3(1, 1, 0)};
  o.voxel_mm = 0.005;
  const auto res = sim::simulate(o);
  EXPECT_TRUE(res.contacts.empty()) << sim::format_contact(res.contacts.front(), "face.nc");
  const double expected = 4 * (depth - feed * feed / (24 * r));
  // Volume accuracy of the grid: 0.05 h per mm^2 of cut surface (4 mm^2).
  EXPECT_NEAR(res.stock->removed_volume_mm3(), expected, 0.05 * 0.005 * 4 + 2e-4);
  // The face is at -depth under the nose's passes, the scallop above it.
  const double z = res.stock->surface_height(0.5, 0.3, 0.01);
  EXPECT_GE(z, -depth - 0.003);
  EXPECT_LE(z, -depth + feed * feed / (8 * r) + 0.003);
}

TEST(Interference, StopAtFirstContactEndsTheRunThere) {
  TempDir dir;
  sim::SimOptions o;
  o.program = dir.write("prog.nc", "G0 X-5 Y0 Z-0.5\nG0 X5\nG0 Y1\nG0 X-5\nM30\n");
  o.tool = tool::parse_tool_spec("ball:d=1");
  o.stock_box = Aabb{Vec3(-2, -2, -1), Vec3(2, 2, 0)};
  o.voxel_mm = 0.02;
  o.stop_at_first_contact = true;
  const auto r = sim::simulate(o);
  EXPECT_TRUE(r.stopped_at_contact);
  ASSERT_EQ(r.contacts.size(), 1u);
  EXPECT_EQ(r.contacts[0].line, 2);
  EXPECT_EQ(r.last_line_cut, 2);
}

// A pointed V tool's planing run clears a pose, or the body's stretch
// behind the edge outside its span, only where every point of the
// clearance body there deeper than the tolerance lies in the groove the
// run cut (the wedge along the path, up to the edge's height) or above the
// stock's top: checked on random paths at points sampled in the body.
// And it does clear the level and gently falling paths, not the steep ones.
TEST(Interference, PlaningRunClearsOnlyBodiesInsideItsGroove) {
  const tool::Tool vt = tool::parse_tool_spec("vtool:angle=90,clearance=7,h=0.1,body=0.3", "test");
  const std::vector<tool::Region> regions = tool::contact_regions(vt);
  const auto& flank = std::get<tool::FlankBody>(regions.front().shape);
  const tool::FlankTrig trig = tool::flank_trig(flank);
  const double top = 0, tol = 0.000125, y0 = 0.01;
  const double k = std::tan(7 * kPi / 180) / std::sin(kPi / 4);
  // A run of tips along +X at y0, and a pose on its next move.
  auto view_of = [&](const std::vector<Vec3>& tips) {
    return sim::PlaningRun::View{std::make_shared<const std::vector<Vec3>>(tips), tips.size(), Eigen::Matrix3d::Identity()};
  };
  auto at = [](const Vec3& tip) {
    Pose p = Pose::Identity();
    p.translation() = tip;
    return p;
  };
  // The path's height at x (tips and then the pose), and whether q lies in
  // the groove.
  auto in_groove = [&](const std::vector<Vec3>& path, const Vec3& q) {
    if (q.x() < path.front().x() || q.x() > path.back().x()) return false;
    std::size_t i = 1;
    while (path[i].x() < q.x()) ++i;
    const Vec3 &a = path[i - 1], &b = path[i];
    const double c = b.x() > a.x() ? a.z() + (b.z() - a.z()) * (q.x() - a.x()) / (b.x() - a.x()) : b.z();
    const double u = q.z() - c;
    return u >= std::fabs(q.y() - y0) && u <= flank.edge.height;
  };
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> uni(0, 1);
  int cleared = 0, partial = 0, checked = 0;
  for (int trial = 0; trial < 1000; ++trial) {
    // Steps of 1-20 um, slopes up to +-0.3 (the clearance line's is 0.174).
    std::vector<Vec3> path{Vec3(0, y0, -0.02 * uni(rng))};
    const int n = 5 + static_cast<int>(uni(rng) * 200);
    const double bias = 0.3 * (2 * uni(rng) - 1);
    for (int i = 0; i < n; ++i) {
      const double dx = 0.001 + 0.019 * uni(rng);
      const double slope = std::clamp(bias + 0.1 * (2 * uni(rng) - 1), -0.3, 0.3);
      path.push_back(path.back() + Vec3(dx, 0, slope * dx));
      path.back().z() = std::clamp(path.back().z(), -0.08, -0.001);
    }
    const Vec3 pose = path.back();
    path.pop_back();
    const auto v = view_of(path);
    path.push_back(pose);  // (the pose's own move cut up to it too)
    const sim::PlaningRun::Span span = sim::PlaningRun::flank_span(v, flank, at(pose), top, tol);
    EXPECT_EQ(span.clear(), sim::PlaningRun::flank_clear(v, flank, at(pose), top, tol));
    if (!span.known) continue;
    ++(span.clear() ? cleared : partial);
    const Aabb b = tool::shape_bounds(flank);
    for (int s = 0; s < 4000; ++s) {
      const Vec3 l(b.min.x() + uni(rng) * b.size().x(), b.min.y() + uni(rng) * b.size().y(),
                   b.min.z() + uni(rng) * std::min(b.size().z(), top - pose.z() + 0.001));
      if (tool::flank_distance(flank, trig, l) >= -tol) continue;
      if (-l.x() >= span.lo && -l.x() <= span.hi) continue;  // (t behind the edge: where it may touch)
      const Vec3 q = pose + l;
      ++checked;
      ASSERT_TRUE(q.z() > top || in_groove(path, q)) << "trial " << trial << " point " << q.transpose();
    }
  }
  EXPECT_GT(cleared, 40);
  EXPECT_GT(partial, 40);
  EXPECT_GT(checked, 40000);
  // Level, falling at 0.15 (under the clearance line's 0.174) and at 0.2
  // (over it), 0.5 mm of 2 um steps ending 30 um deep.
  auto ends_cleared = [&](double fall) {
    std::vector<Vec3> path;
    for (int i = 0; i <= 250; ++i) path.emplace_back(0.002 * i, y0, -0.03 + fall * (0.5 - 0.002 * i));
    const Vec3 pose = path.back() + Vec3(0.002, 0, -fall * 0.002);
    return sim::PlaningRun::flank_clear(view_of(path), flank, at(pose), top, tol);
  };
  EXPECT_TRUE(ends_cleared(0));
  EXPECT_TRUE(ends_cleared(0.15));
  EXPECT_FALSE(ends_cleared(0.2));
  EXPECT_GT(k, 0.17);
  EXPECT_LT(k, 0.18);
  // A run shorter than the body reaches below the top: not cleared.
  std::vector<Vec3> short_run{Vec3(0, y0, -0.03), Vec3(0.05, y0, -0.03)};
  EXPECT_FALSE(sim::PlaningRun::flank_clear(view_of(short_run), flank, at(Vec3(0.06, y0, -0.03)), top, tol));
  // Off the run's plane, or with no tolerance: not cleared.
  std::vector<Vec3> level{Vec3(0, y0, -0.01), Vec3(0.3, y0, -0.01)};
  EXPECT_TRUE(sim::PlaningRun::flank_clear(view_of(level), flank, at(Vec3(0.31, y0, -0.01)), top, tol));
  EXPECT_FALSE(sim::PlaningRun::flank_clear(view_of(level), flank, at(Vec3(0.31, y0 + 1e-6, -0.01)), top, tol));
  EXPECT_FALSE(sim::PlaningRun::flank_clear(view_of(level), flank, at(Vec3(0.31, y0, -0.01)), top, 0));
}

// Poses a planing run clears are not scanned: the contacts (lines, depths,
// points, poses) and the cut are those of scanning every pose, on V-tool
// lines that plunge into the stock (rubbing as they fall) and then follow
// a wave.
TEST(Interference, PlaningRunsGiveTheContactsOfScanningEveryPose) {
  TempDir dir;
  std::ostringstream os;
  os << std::fixed;
  os.precision(6);
  for (double y : {-0.008, 0.0, 0.008}) {
    os << "G0 X-0.03 Y" << y << " Z0.01\nG1 Z0 F30\n";
    for (double x = -0.028; x <= 0.19; x += 0.002) {
      const double z = x < 0 ? -0.008 * (x + 0.03) / 0.03 : -0.008 - 0.004 * std::sin(2 * kPi * x / 0.1);
      os << "G1 X" << x << " Z" << z << "\n";
    }
    os << "G0 Z0.01\n";
  }
  os << "M30\n";
  sim::SimOptions o;
  o.program = dir.write("prog.nc", os.str());
  o.tool = tool::parse_tool_spec("vtool:angle=90,clearance=7,h=0.1,body=0.3");
  o.stock_box = Aabb{Vec3(-0.02, -0.03, -0.05), Vec3(0.2, 0.03, 0)};
  o.voxel_mm = 0.001;
  const auto runs = sim::simulate(o);
  o.planing_runs = false;
  const auto every = sim::simulate(o);
  EXPECT_EQ(every.poses_cleared_by_runs, 0);
  EXPECT_EQ(runs.contact_poses, every.contact_poses);
  // Of the lines' 333 feed poses (one per 2 um move; the rapids have the
  // rest), those on the wave's rises and gentle falls.
  EXPECT_GT(runs.poses_cleared_by_runs, 150);
  ASSERT_FALSE(every.contacts.empty());
  expect_same_contacts(every, runs, "planing runs");
}

TEST(ToolSpec, EveryKindParsesWithItsDefaults) {
  const auto v = tool::parse_tool_spec("vtool:angle=90,clearance=7");
  EXPECT_EQ(v.kind, tool::ToolKind::vtool);
  EXPECT_DOUBLE_EQ(v.included_angle_deg, 90);
  EXPECT_DOUBLE_EQ(v.clearance_angle_deg, 7);
  EXPECT_DOUBLE_EQ(v.corner_radius_mm, 0);
  const auto n = tool::parse_tool_spec("nose:r=0.9789,clearance=10");
  EXPECT_DOUBLE_EQ(n.corner_radius_mm, 0.9789);
  EXPECT_DOUBLE_EQ(n.rake_angle_deg, 0);
  const auto b = tool::parse_tool_spec("bull:d=2,r=0.2");
  EXPECT_DOUBLE_EQ(b.corner_radius_mm, 0.2);
  EXPECT_DOUBLE_EQ(b.shank_diameter_mm, 2);
  const auto f = tool::parse_tool_spec("flycutter:swing=18,r=2");
  EXPECT_DOUBLE_EQ(f.swing_radius_mm, 18);
  EXPECT_DOUBLE_EQ(f.radius(), 18);
  for (const char* bad : {"vtool:r=0.1", "nose:clearance=5", "flycutter:swing=1,r=2", "nose:r=1,angle=180",
                          "ball:d=1,neck_d=0.5", "drill:d=3", "ball:d=1,holder_d=5"})
    EXPECT_THROW(tool::parse_tool_spec(bad), ConfigError) << bad;
}

// The V tool's regions, exactly: the edge profile's width at height z is
// 2 z tan 45; the flank at L behind the rake face is shrunk by L tan 7.
TEST(ToolSpec, VToolRegionsHaveTheirClosedFormGeometry) {
  const auto t = tool::parse_tool_spec("vtool:angle=90,clearance=7");
  const tool::Shape edge = tool::cutting_shape(t);
  // On the edge line at height 0.1: y = 0.1.
  EXPECT_NEAR(tool::shape_distance(edge, Vec3(0, 0.1, 0.1)), 0, 1e-12);
  EXPECT_NEAR(tool::shape_distance(edge, Vec3(0.003, 0.05, 0.1)), 0.003, 1e-12);
  const auto regions = tool::contact_regions(t);
  ASSERT_EQ(regions.size(), 1u);
  EXPECT_EQ(regions[0].name, "clearance-face");
  // 0.2 behind, at height 0.1: the flank's edge is at y = 0.1 - 0.2 tan7 / cos45.
  const double y = 0.1 - 0.2 * std::tan(7 * kPi / 180) / std::cos(kPi / 4);
  EXPECT_NEAR(tool::shape_distance(regions[0].shape, Vec3(-0.2, y, 0.1)), 0, 1e-12);
  EXPECT_LT(tool::shape_distance(regions[0].shape, Vec3(-0.2, y - 0.001, 0.1)), 0);
  EXPECT_GT(tool::shape_distance(regions[0].shape, Vec3(-0.2, y + 0.001, 0.1)), 0);
  // A ball mill: shank from the flute length up.
  const auto b = tool::parse_tool_spec("ball:d=1,l=1,shank_d=3,shank_l=20");
  const auto br = tool::contact_regions(b);
  ASSERT_EQ(br.size(), 1u);
  EXPECT_NEAR(tool::shape_distance(br[0].shape, Vec3(0, 0, 0.9)), 0.1, 1e-12);
  EXPECT_NEAR(tool::shape_distance(br[0].shape, Vec3(1.6, 0, 5)), 0.1, 1e-12);
}

TEST(ToolLibrary, TomlToolsByNumber) {
  const auto lib = io::parse_tool_library_toml(
      "[[tool]]\nnumber = 1\nkind = \"ball\"\ndiameter = 1.0\nflute_length = 1.5\nshank_diameter = 4\n"
      "[[tool]]\nnumber = 5\nspec = \"vtool:angle=90,clearance=7\"\nname = \"snowflake V\"\n"
      "[[tool]]\nnumber = 7\nkind = \"nose\"\nnose_radius = 0.9789\nclearance_angle = 10\n",
      "lib.toml");
  ASSERT_EQ(lib.tools.size(), 3u);
  EXPECT_DOUBLE_EQ(lib.find(1)->shank_diameter_mm, 4);
  EXPECT_DOUBLE_EQ(lib.find(1)->flute_length_mm, 1.5);
  EXPECT_EQ(lib.find(5)->name, "snowflake V");
  EXPECT_EQ(lib.find(7)->kind, tool::ToolKind::nose);
  EXPECT_EQ(lib.find(2), nullptr);
  try {
    io::parse_tool_library_toml("[[tool]]\nnumber = 1\nkind = \"ball\"\ndiameter = 1\ndiamter = 2\n", "lib.toml");
    FAIL();
  } catch (const ConfigError& e) {
    EXPECT_EQ(e.where().line, 5);
    EXPECT_EQ(e.where().column, 1);
  }
  EXPECT_THROW(io::parse_tool_library_toml("[[tool]]\nnumber = 1\nkind = \"ball\"\ndiameter = -1\n", "l"), ConfigError);
  EXPECT_THROW(io::parse_tool_library_toml("[[tool]]\nnumber = 1\nspec = \"ball:d=1\"\n[[tool]]\nnumber = 1\nspec = \"flat:d=1\"\n", "l"),
               ConfigError);
}

TEST(ToolLibrary, LinuxCncTableImportsEndMills) {
  std::istringstream in(
      ";LinuxCNC tool table\n"
      "T1 P1 D6.0 Z+12.5 ;6 mm flat end mill\n"
      "T2 P2 X0 D1.0 Z0 ;ball end mill l=2 shank_d=4\n"
      "t3 p3 d2 ;bull r=0.2\n");
  const auto lib = io::parse_linuxcnc_tbl(in, "t.tbl");
  ASSERT_EQ(lib.tools.size(), 3u);
  EXPECT_EQ(lib.find(1)->kind, tool::ToolKind::flat);
  EXPECT_DOUBLE_EQ(lib.find(1)->diameter_mm, 6);
  EXPECT_EQ(lib.find(2)->kind, tool::ToolKind::ball);
  EXPECT_DOUBLE_EQ(lib.find(2)->flute_length_mm, 2);
  EXPECT_DOUBLE_EQ(lib.find(2)->shank_diameter_mm, 4);
  EXPECT_EQ(lib.find(3)->kind, tool::ToolKind::bull);
  EXPECT_DOUBLE_EQ(lib.find(3)->corner_radius_mm, 0.2);
  struct Bad { const char* text; int line, col; };
  for (const Bad& b : {Bad{"T1 D6\nT2 D1x\n", 2, 5}, Bad{"T1 P1 Z0\n", 1, 9}, Bad{"T1 D1\nT1 D2\n", 2, 1},
                       Bad{"T1 D1 K5\n", 1, 7}, Bad{"P1 D1\n", 1, 1}, Bad{"T1 D1 ;bull r=\n", 1, 13}}) {
    std::istringstream s(b.text);
    try {
      io::parse_linuxcnc_tbl(s, "t.tbl");
      ADD_FAILURE() << b.text;
    } catch (const ParseError& e) {
      EXPECT_EQ(e.where().line, b.line) << b.text;
      EXPECT_EQ(e.where().column, b.col) << b.text;
    }
  }
}

TEST(ToolLibrary, ProgramPicksToolsByTNumberAndNamesAMissingOne) {
  TempDir dir;
  const std::string lib = dir.write("tools.toml",
                                    "[[tool]]\nnumber = 1\nspec = \"flat:d=2\"\n[[tool]]\nnumber = 2\nspec = \"ball:d=0.5\"\n");
  sim::SimOptions o;
  o.program = dir.write("prog.nc", "T1 M6\nG0 X-2 Y0 Z-0.1\nG1 X2 F100\nT2 M6\nG0 Y1\nG1 X-2\nT9 M6\nG1 Y2\nM30\n");
  o.tools_file = lib;
  o.stock_box = Aabb{Vec3(-1, -1, -1), Vec3(1, 3, 0)};
  o.voxel_mm = 0.02;
  try {
    sim::simulate(o);
    FAIL();
  } catch (const ConfigError& e) {
    EXPECT_EQ(e.where().line, 8);
    EXPECT_NE(e.message().find("T9 is not in the tool library"), std::string::npos) << e.message();
  }
  o.program = dir.write("prog2.nc", "T1 M6\nG0 X-2 Y0 Z-0.1\nG1 X2 F100\nT2 M6\nG0 Y2\nG1 X-2\nM30\n");
  const auto r = sim::simulate(o);
  ASSERT_EQ(r.tools_used.size(), 2u);
  EXPECT_EQ(r.tools_used[0].number, 1);
  EXPECT_EQ(r.tools_used[1].number, 2);
  // The 2 mm flat slot is 0.1 deep and 2 wide over 2 mm of stock; the
  // 0.5 mm ball's slot 0.1 deep has the circular segment's cross-section.
  const double seg = 0.25 * 0.25 * std::acos(0.15 / 0.25) - 0.15 * std::sqrt(0.25 * 0.25 - 0.15 * 0.15);
  EXPECT_NEAR(r.stock->removed_volume_mm3(), 2 * 2 * 0.1 + 2 * seg, 0.01);
}

}  // namespace cutsim::test
