// Machine kinematics: forward kinematics of the presets, the seeds/003
// assembly-error experiment, Edlen and the laser scale, slow-tool-servo axis
// limits (seeds/002) and the 5-axis sweep bound.
#include <algorithm>
#include <cmath>
#include <random>
#include <sstream>

#include <nlohmann/json.hpp>

#include "cutsim/core/error.h"
#include "cutsim/cases/cases.h"
#include "cutsim/machine/environment.h"
#include "cutsim/machine/kinematics.h"
#include "cutsim/sim/planner.h"
#include "cutsim/sim/report.h"
#include "cutsim/sim/simulate.h"
#include "cutsim/io/job.h"
#include "helpers.h"

namespace cutsim::test {
namespace {

using machine::JointValues;

constexpr double kDeg = kPi / 180;

void expect_pose(const machine::Kinematics& k, const JointValues& q, const Vec3& tip, const Vec3& axis) {
  const Pose p = k.tool_pose(q);
  EXPECT_NEAR((p.translation() - tip).norm(), 0, 1e-12) << p.translation().transpose() << " vs " << tip.transpose();
  EXPECT_NEAR((p.linear().col(2) - axis).norm(), 0, 1e-12) << p.linear().col(2).transpose();
}

TEST(Kinematics, PresetsMatchHandComputedPoses) {
  const machine::Kinematics xyz(machine::load_machine("xyz"));
  EXPECT_TRUE(xyz.is_identity());
  expect_pose(xyz, {1, 2, 3, 0, 0, 0}, Vec3(1, 2, 3), Vec3::UnitZ());

  // xyza: tip = Rx(A) (x, y, z). Rx(90) maps (1,2,3) to (1,-3,2) and Z to -Y.
  const machine::Kinematics xyza(machine::load_machine("xyza"));
  expect_pose(xyza, {1, 2, 3, 90 * kDeg, 0, 0}, Vec3(1, -3, 2), Vec3(0, -1, 0));

  // xyzbc: B turns the tool about Y through the pivot 50 mm above the tip.
  // B90: tip = Ry(90)(0,0,-50) + (0,0,50) = (-50,0,50), axis +X. With
  // X10 and C90: Rz(90)(10-50, 0, 50) = (0,-40,50), axis Rz(90)X = +Y.
  const machine::Kinematics bc(machine::load_machine("xyzbc"));
  expect_pose(bc, {0, 0, 0, 0, 90 * kDeg, 0}, Vec3(-50, 0, 50), Vec3::UnitX());
  expect_pose(bc, {10, 0, 0, 0, 90 * kDeg, 90 * kDeg}, Vec3(0, -40, 50), Vec3::UnitY());

  // xzc lathe: tip = Rz(C) (X, 0, Z).
  const machine::Kinematics xzc(machine::load_machine("xzc"));
  expect_pose(xzc, {5, 0, 1, 0, 0, 90 * kDeg}, Vec3(0, 5, 1), Vec3::UnitZ());

  const machine::Kinematics fly(machine::load_machine("flycut"));
  expect_pose(fly, {1, 2, 3, 0, 0, 0}, Vec3(1, 2, 3), Vec3::UnitZ());
}

TEST(Kinematics, AssemblyErrorOfAOnYShiftsBothSides) {
  machine::Machine m = machine::load_machine("xyza");
  sim::apply_joint_error(m, "A:dy=-0.5", "test");
  const machine::Kinematics k(m);
  EXPECT_FALSE(k.is_identity());
  // A0: (x, y + dy, z); A180: Rx(180)(x, y + dy, z) = (x, -(y + dy), -z).
  expect_pose(k, {1, -25, 2, 0, 0, 0}, Vec3(1, -25.5, 2), Vec3::UnitZ());
  expect_pose(k, {1, 25, 2, 180 * kDeg, 0, 0}, Vec3(1, -24.5, -2), -Vec3::UnitZ());
}

TEST(Kinematics, TipSolveInvertsTheChain) {
  const machine::Kinematics bc(machine::load_machine("xyzbc"));
  const JointValues q = bc.solve_tip(Vec3(1, 2, 3), {0, 0, 0, 0, 30 * kDeg, 45 * kDeg});
  EXPECT_NEAR((bc.tool_pose(q).translation() - Vec3(1, 2, 3)).norm(), 0, 1e-12);
  EXPECT_NEAR(q[4], 30 * kDeg, 0);
}

TEST(Kinematics, UnknownMachineAndBadFileAreConfigErrors) {
  EXPECT_THROW(machine::load_machine("xyzzy"), ConfigError);
  TempDir dir;
  const auto p = dir.write("m.toml", "name = \"m\"\n[[joint]]\naxis = \"Q\"\ntype = \"linear\"\ndirection = [1,0,0]\n");
  try {
    machine::load_machine(p);
    FAIL();
  } catch (const ConfigError& e) {
    EXPECT_EQ(e.where().line, 2);
  }
}

// Position of the level set's zero crossing on the segment a -> b.
double crossing(const stock::Stock& s, const Vec3& a, const Vec3& b) {
  const int n = 4000;
  double prev = s.sample(a);
  for (int i = 1; i <= n; ++i) {
    const Vec3 p = a + (b - a) * (static_cast<double>(i) / n);
    const double v = s.sample(p);
    if ((prev > 0) != (v > 0)) {
      const double t = (i - 1 + prev / (prev - v)) / n;
      return t * (b - a).norm();
    }
    prev = v;
  }
  return std::numeric_limits<double>::quiet_NaN();
}

TEST(Seeds003, FacesCutAtA0AndA180EndUpTwiceTheAssemblyErrorApart) {
  // Side milling with a 6 mm flat end mill: at A0 with the tool at Y-25,
  // then at A180 with the tool at Y+25 (seeds/003 fig. 5-6), each on its own
  // stretch of X. dy_AY = -0.5 mm puts the faces 2 |dy| = 1.00 mm apart.
  const std::string prog =
      "G21 G90 G94\nG0 X-4 Y-25 Z20 A0\nG0 Z-5\nG1 X9 F300\nG0 Z20\nG0 A180\nG0 X11 Y25 Z20\nG1 Z-5 F300\nG1 X24\nG0 Z20\n";
  auto faces = [&](const std::string& error) {
    TempDir dir;
    sim::SimOptions o;
    o.program = dir.write("p.nc", prog);
    o.tool = tool::parse_tool_spec("flat:d=6");
    o.stock_box = Aabb{Vec3(0, -24, -6), Vec3(20, 24, 6)};
    o.voxel_mm = 0.05;
    o.machine = "xyza";
    if (!error.empty()) o.joint_errors = {error};
    auto r = sim::simulate(o);
    // Along +Y from outside the stock into it, at Z0, one X on each face.
    const double y0 = -24.5;
    const double f1 = y0 + crossing(*r.stock, Vec3(4, y0, 0), Vec3(4, -20, 0));
    const double f2 = y0 + crossing(*r.stock, Vec3(16, y0, 0), Vec3(16, -20, 0));
    return std::make_pair(f1, f2);
  };
  const double h = 0.05;
  const auto with = faces("A:dy=-0.5");
  EXPECT_NEAR(with.first, -22.5, h);
  EXPECT_NEAR(with.second, -21.5, h);
  EXPECT_NEAR(with.second - with.first, 1.00, h);
  const auto without = faces("");
  EXPECT_NEAR(without.second - without.first, 0.0, h);
}

// The same experiment as the repository's reference case 5
// (ncprograms/fouraxis_faces.nc with its job): the faces 1.00 mm apart.
TEST(Seeds003, ReferenceCaseJobReproducesTheStep) {
  sim::SimOptions o;
  o.program = std::string(CUTSIM_SOURCE_DIR) + "/ncprograms/fouraxis_faces.nc";
  o.job = io::load_job(std::string(CUTSIM_SOURCE_DIR) + "/ncprograms/fouraxis_faces.toml");
  const auto r = sim::simulate(o);
  EXPECT_TRUE(r.contacts.empty());
  const double y0 = -24.5;
  const double f1 = y0 + crossing(*r.stock, Vec3(4, y0, 0), Vec3(4, -20, 0));
  const double f2 = y0 + crossing(*r.stock, Vec3(16, y0, 0), Vec3(16, -20, 0));
  EXPECT_NEAR(f2 - f1, 2 * 0.5, 0.05);
}

TEST(SettingError, WorkpieceSetHigherIsCutDeeper) {
  // The workpiece sits 10 um higher on the table than the job assumes: the
  // same pass cuts 10 um deeper into it.
  auto height = [](const std::string& setting) {
    TempDir dir;
    sim::SimOptions o;
    o.program = dir.write("p.nc", "G0 X-1 Y0 Z1\nG1 Z-0.05 F100\nG1 X1\nG0 Z1\n");
    o.tool = tool::parse_tool_spec("flat:d=1");
    o.stock_box = Aabb{Vec3(-2, -1, -1), Vec3(2, 1, 0)};
    o.voxel_mm = 0.002;
    if (!setting.empty()) o.workpiece_setting = setting;
    return sim::simulate(o).stock->surface_height(0, 0, 0.5);
  };
  EXPECT_NEAR(height(""), -0.05, 2e-4);
  EXPECT_NEAR(height("dz=0.01"), -0.06, 2e-4);
}

TEST(Cli, CheckWithAMachineFlagsTheLineAndExitsOne) {
  TempDir dir;
  // A 0.2 mm X step in 1/240 s between steady blocks on the xzc lathe.
  std::string prog = "G21 G90\nG0 X10 Z0 C0\nG93\n";
  for (int k = 1; k <= 20; ++k)
    prog += "G1 X" + std::to_string(10 - 0.001 * k + (k == 10 ? 0.2 : 0.0)) + " C" + std::to_string(3 * k) + " F14400\n";
  const auto p = dir.write("sts.nc", prog);
  std::string out;
  EXPECT_EQ(run_cli("check " + p + " --machine xzc", &out), 1);
  EXPECT_NE(out.find("sts.nc:13: X acceleration"), std::string::npos) << out;
  EXPECT_NE(out.find("sts.nc:14: X acceleration"), std::string::npos) << out;
  EXPECT_NE(out.find("sts.nc:15: X acceleration"), std::string::npos) << out << "the velocity steps back here";
  EXPECT_EQ(out.find("sts.nc:12: X"), std::string::npos) << out;
  EXPECT_EQ(out.find("sts.nc:16: X"), std::string::npos) << out;
  // Under the header, a line per axis and quantity: X's acceleration on
  // lines 13-15, against the xzc lathe's 2000 mm/s^2.
  EXPECT_NE(out.find("axis-limit violations\n  X acceleration: 3 on lines 13-15, the most "), std::string::npos) << out;
  EXPECT_NE(out.find("(limit 2000)\n"), std::string::npos) << out;
}

TEST(Edlen, StandardAirAndSensitivities) {
  // Reference values worked from seeds/000 eq. 2 outside cutsim.
  const double n0 = machine::edlen_refractive_index(20, 50, 1013.25);
  EXPECT_NEAR(n0, 1.0002712735578796, 1e-12);
  // About 0.1 ppm each for +0.1 degC, +10 % RH, +0.37 hPa (seeds/000).
  EXPECT_NEAR((machine::edlen_refractive_index(20.1, 50, 1013.25) - n0) * 1e6, -0.0960, 5e-4);
  EXPECT_NEAR((machine::edlen_refractive_index(20, 60, 1013.25) - n0) * 1e6, -0.0983, 5e-4);
  EXPECT_NEAR((machine::edlen_refractive_index(20, 50, 1013.62) - n0) * 1e6, 0.0993, 5e-4);
  // 25 hPa over 850 mm: about 5.7 um shorter (eq. 4).
  const double n1 = machine::edlen_refractive_index(20, 50, 1038.25);
  EXPECT_NEAR(machine::laser_position_error_mm(n0, n1, 0, 850) * 1000, -5.70035, 1e-4);
  // Dead path (eq. 5): at the counter's origin only L0 counts.
  EXPECT_DOUBLE_EQ(machine::laser_position_error_mm(n0, n1, 845, 0), machine::laser_position_error_mm(n0, n1, 0, 845));
}

TEST(Edlen, EnvironmentLogInterpolatesAndRefusesBadRows) {
  TempDir dir;
  const auto p = dir.write("env.csv", "time_s,temperature_c,humidity_pct,pressure_hpa\n0,20,50,1013.25\n100,20,50,1023.25\n");
  const auto log = machine::EnvironmentLog::load_csv(p);
  EXPECT_DOUBLE_EQ(log.at(25).pressure_hpa, 1015.75);
  EXPECT_DOUBLE_EQ(log.at(1e6).pressure_hpa, 1023.25);
  const auto bad = dir.write("bad.csv", "time_s,temperature_c,humidity_pct,pressure_hpa\n0,20,50,1013.25\n1,20,5O,1013\n");
  try {
    machine::EnvironmentLog::load_csv(bad);
    FAIL();
  } catch (const ParseError& e) {
    EXPECT_EQ(e.where().line, 3);
    EXPECT_EQ(e.where().column, 6);
  }
}

TEST(LaserScale, PressureRiseDeepensALaterCutByTheEdlenError) {
  // flycut preset: Z on a laser scale with an 845 mm dead path. The pressure
  // rises 25 hPa between two face passes: the second is cut deeper by
  // (n1 - n0)/n0 * (845 mm + z), about 5.7 um.
  TempDir dir;
  const auto env = dir.write("env.csv", "time_s,temperature_c,humidity_pct,pressure_hpa\n0,20,50,1013.25\n"
                                        "20,20,50,1013.25\n40,20,50,1038.25\n");
  const std::string prog = "G21 G90\nG0 X-0.5 Y0 Z1\nG1 Z-0.01 F600\nG1 X0.5\nG0 Z1\n"
                           "G1 X50 F60\nG0 X-0.5 Y1\nG1 Z-0.01 F600\nG1 X0.5\nG0 Z1\n";
  auto heights = [&](bool with_env) {
    sim::SimOptions o;
    o.program = dir.write("p.nc", prog);
    o.tool = tool::parse_tool_spec("flat:d=0.5");
    o.stock_box = Aabb{Vec3(-1, -0.5, -0.2), Vec3(1, 1.5, 0)};
    o.voxel_mm = 0.002;
    o.machine = "flycut";
    if (with_env) o.environment = env;
    auto r = sim::simulate(o);
    EXPECT_EQ(r.laser_error_applied, with_env);
    return std::make_pair(r.stock->surface_height(0, 0, 0.1), r.stock->surface_height(0, 1, 0.1));
  };
  const auto on = heights(true), off = heights(false);
  const double n0 = 1.0002712735578796;
  const double n1 = machine::edlen_refractive_index(20, 50, 1038.25);
  const double expected = (n0 - n1) / n1 * (845 - 0.01);
  EXPECT_NEAR(on.second - on.first, expected, 0.002) << "expected " << expected * 1000 << " um";
  EXPECT_LT(on.second - on.first, -0.004);
  EXPECT_NEAR(off.second - off.first, 0.0, 0.0005);
}

// seeds/002's lens array: the programs come from the reference case's
// generator (src/cases/lens.cpp), here at 50 um a revolution to stay short.
std::string sts_program(bool normal_compensation, std::vector<int>* edge_lines, double rpm) {
  return cases::lens::program(normal_compensation, rpm, 0.05, 120, edge_lines);
}

// X acceleration is estimated block by block (README): at the CASES.md
// conditions, 120 rpm and 120 points a revolution, the normal-compensated
// path peaks at about 1.86 m/s^2 at the lens edges, 93 % of the 2000 mm/s^2
// limit. The same program at 150 rpm (accelerations scale with the square of
// the speed) exceeds it there, and only there; keeping X steady never does.
// Past 20 axis-limit records the console gives a line per axis and
// quantity, then the 20 furthest over their limits in program order: the
// one far over at the end is shown, the mild ones after the first 19 not.
TEST(AxisLimits, ConsoleSummarisesManyRecordsAndShowsTheWorst) {
  TempDir dir;
  sim::SimResult r = run_program(dir, "G1 X1 F100\n", "flat:d=1", Aabb{Vec3(0, 0, -1), Vec3(2, 2, 0)}, 0.05);
  for (int line = 10; line < 40; ++line) {
    machine::AxisViolation v;
    v.line = line;
    v.axis = 'X';
    v.quantity = "acceleration";
    v.unit = "mm/s^2";
    v.limit = 2000;
    v.value = line == 39 ? 9000 : 2100 + line;  // line 39 far over; the others mildly, rising
    r.axis_limit_violations.push_back(v);
  }
  const std::string out = sim::report_text(r, {});
  EXPECT_NE(out.find("30 axis-limit violations:\n  X acceleration: 30 on lines 10-39, the most 9000 mm/s^2 at line 39 "
                     "(limit 2000)\nthe 20 furthest over their limits, in program order:\n"),
            std::string::npos)
      << out;
  EXPECT_NE(out.find(":39: X acceleration 9000 mm/s^2 over the limit 2000"), std::string::npos) << out;
  EXPECT_NE(out.find(":20: X acceleration 2120"), std::string::npos) << out;  // lines 20-39: the largest
  EXPECT_EQ(out.find(":19: X acceleration"), std::string::npos) << out;
  EXPECT_NE(out.find("... and 10 more axis-limit violations"), std::string::npos) << out;
  const auto j = nlohmann::json::parse(sim::report_json(r, {}));
  EXPECT_EQ(j["axis_limit_violations"].size(), 30u);
  ASSERT_EQ(j["axis_limit_summary"].size(), 1u);
  EXPECT_EQ(j["axis_limit_summary"][0]["records"], 30);
  EXPECT_EQ(j["axis_limit_summary"][0]["worst_line"], 39);
  EXPECT_EQ(j["axis_limit_summary"][0]["worst_value"], 9000.0);
  EXPECT_EQ(j["axis_limit_summary"][0]["first_line"], 10);
}

TEST(SlowToolServo, NormalCompensationPeaksInXAtLensEdges) {
  TempDir dir;
  std::vector<int> edges;
  const auto normal = dir.write("normal.nc", sts_program(true, &edges, 120));
  ASSERT_GT(edges.size(), 100u);
  // A machine whose X limit is low enough to report every edge peak.
  const std::string xzc = slurp(std::string(CUTSIM_SOURCE_DIR) + "/models/machines/xzc.toml");
  std::string low = xzc;
  low.replace(low.find("max_acceleration = 2000"), 23, "max_acceleration = 1000");
  const auto machine = dir.write("low.toml", low);
  const sim::AxisReport a = sim::analyze_axes(normal, {}, machine);
  double peak = 0;
  for (const auto& v : a.violations)
    if (v.axis == 'X' && v.quantity == "acceleration") {
      peak = std::max(peak, v.value);
      EXPECT_TRUE(std::any_of(edges.begin(), edges.end(), [&](int e) { return std::abs(e - v.line) <= 2; }))
          << "line " << v.line;
    }
  EXPECT_NEAR(peak, 1862, 50);
  // 1 + 330 * 120 blocks of 1/240 s after a rapid of 16.5 mm at 200 mm/s
  // and a 1 mm approach at 60 mm/min; the retract from about the surface at
  // the centre (where the lenses overlap) to Z1 at 200 mm/s.
  EXPECT_NEAR(a.program_time_s, (1 + 330 * 120) / 240.0 + 16.5 / 200 + 1.0 + (1 - cases::lens::z(0, 0)) / 200, 1e-5);
}

TEST(SlowToolServo, AtSpeedNormalCompensationExceedsXLimitAtLensEdgesKeepXSteadyDoesNot) {
  TempDir dir;
  std::vector<int> edges;
  const auto normal = dir.write("normal.nc", sts_program(true, &edges, 150));
  const auto steady = dir.write("steady.nc", sts_program(false, nullptr, 150));
  const sim::AxisReport a = sim::analyze_axes(normal, {}, "xzc");
  int x_acc = 0;
  for (const auto& v : a.violations) {
    if (v.axis != 'X' || v.quantity != "acceleration") continue;
    ++x_acc;
    EXPECT_GT(v.value, 2000);
    EXPECT_DOUBLE_EQ(v.limit, 2000);
    // Flagged where the contact moves from one surface piece to another.
    EXPECT_TRUE(std::any_of(edges.begin(), edges.end(), [&](int e) { return std::abs(e - v.line) <= 2; }))
        << "line " << v.line << " is not at a lens edge";
  }
  EXPECT_GT(x_acc, 10);
  // The summary of X's acceleration: its count, first and last lines, and
  // the furthest over; the worst 5 of all records are the 5 largest excesses
  // (the earlier of equal ones), in program order.
  {
    const auto kinds = machine::summarize_violations(a.violations);
    const auto x = std::find_if(kinds.begin(), kinds.end(),
                                [](const auto& k) { return k.axis == 'X' && k.quantity == "acceleration"; });
    ASSERT_NE(x, kinds.end());
    EXPECT_EQ(x->records, static_cast<std::size_t>(x_acc));
    EXPECT_EQ(x->unit, "mm/s^2");
    int first = 1 << 30, last = 0;
    double most = 0;
    for (const auto& v : a.violations)
      if (v.axis == 'X' && v.quantity == "acceleration") {
        first = std::min(first, v.line);
        last = std::max(last, v.line);
        most = std::max(most, v.value);
      }
    EXPECT_EQ(x->first_line, first);
    EXPECT_EQ(x->last_line, last);
    EXPECT_EQ(a.violations[x->worst].value, most);
    const std::vector<std::size_t> worst = machine::worst_violations(a.violations, 5);
    ASSERT_EQ(worst.size(), 5u);
    EXPECT_TRUE(std::is_sorted(worst.begin(), worst.end()));
    std::vector<double> ex;
    for (const auto& v : a.violations) ex.push_back(machine::excess(v));
    std::sort(ex.rbegin(), ex.rend());
    for (const std::size_t i : worst) EXPECT_GE(machine::excess(a.violations[i]), ex[4]) << "record " << i;
    EXPECT_EQ(machine::worst_violations(a.violations, a.violations.size() + 1).size(), a.violations.size());
  }

  const sim::AxisReport b = sim::analyze_axes(steady, {}, "xzc");
  for (const auto& v : b.violations) EXPECT_NE(v.axis, 'X') << "line " << v.line << " " << v.quantity;
  // The spindle turns at 2.5 Hz: X amplitude limited by its acceleration,
  // 2000 / (4 pi^2 2.5^2).
  bool found = false;
  for (const auto& al : b.amplitude_limits)
    if (al.axis == 'X') {
      found = true;
      EXPECT_NEAR(al.frequency_hz, 2.5, 1e-6);
      EXPECT_NEAR(al.amplitude_mm, 2000 / (4 * kPi * kPi * 6.25), 1e-6);
      EXPECT_EQ(al.limited_by, "acceleration");
    }
  EXPECT_TRUE(found);
}

TEST(FiveAxis, TurningBAtAFixedTipUnderTcpSweepsWithinTheStatedBound) {
  // xyzbc, Fanuc G43.4: B turns 30 deg while the tool tip stays at the
  // origin. The sampled sweep must stay within its tolerance of a dense
  // reference (2000 poses).
  TempDir dir;
  const auto p = dir.write("b.nc", "G21 G90\nG0 X0 Y0 Z5 B0 C0\nG43.4 H0\nG1 X0 Y0 Z0 F100\nG1 B30 F600\n");
  std::vector<motion::Move> moves;
  sim::ProgramOptions popt;
  popt.dialect = gcode::Dialect::fanuc;
  sim::check_program(p, popt, {}, [&](const motion::Move& m) { moves.push_back(m); });
  ASSERT_EQ(moves.size(), 3u);
  const machine::Kinematics kin(machine::load_machine("xyzbc"));
  const double tol = 0.001;
  sim::Planner::Options o;
  o.sweep_tolerance_mm = tol;
  sim::Planner planner(kin, {}, o);
  sim::PlannedMove last;
  for (const auto& m : moves) last = planner.plan(m);
  const auto& m = moves.back();
  EXPECT_NEAR((planner.pose_at(m, last, 0.5).translation()).norm(), 0, 1e-9) << "the tip stays put";
  const tool::Tool t = tool::parse_tool_spec("ball:d=1,l=2");
  const sweep::Sweep s = planner.sweep(m, last, t);
  std::vector<Pose> ref;
  for (int i = 0; i <= 2000; ++i) ref.push_back(planner.pose_at(m, last, i / 2000.0));
  std::mt19937_64 rng(3);
  const Aabb b = s.bounds.expanded(0.2);
  std::uniform_real_distribution<double> ux(b.min.x(), b.max.x()), uy(b.min.y(), b.max.y()), uz(b.min.z(), b.max.z());
  double worst = 0;
  int outside = 0;
  for (int i = 0; i < 1500; ++i) {
    const Vec3 x(ux(rng), uy(rng), uz(rng));
    double d_ref = std::numeric_limits<double>::infinity();
    for (const Pose& q : ref)
      d_ref = std::min(d_ref, sweep::sweep_line(q.translation(), q.translation(), q.linear(), t).distance(x));
    if (d_ref <= 0) continue;
    ++outside;
    worst = std::max(worst, std::fabs(s.distance(x) - d_ref));
  }
  EXPECT_GT(outside, 200);
  EXPECT_LT(worst, tol) << "worst deviation " << worst;
}

// Tool centre point control solves the joints with what the controller
// knows, the nominal machine: a workpiece set 10 um off in X moves the tip
// 10 um on the workpiece, as on a real machine (not compensated away).
TEST(FiveAxis, TcpDoesNotCompensateTheSettingErrorsItDoesNotKnow) {
  TempDir dir;
  const auto p = dir.write("b.nc", "G21 G90\nG0 X0. Y0. Z5. B20. C40.\nG43.4 H0\nG1 X1. Y0.5 Z0.2 C60. F100.\n");
  std::vector<motion::Move> moves;
  sim::ProgramOptions popt;
  popt.dialect = gcode::Dialect::fanuc;
  sim::check_program(p, popt, {}, [&](const motion::Move& m) { moves.push_back(m); });
  machine::Machine mc = machine::load_machine("xyzbc");
  mc.workpiece_setting = sim::parse_setting("dx=0.01", "test");
  const machine::Kinematics kin(mc);
  sim::Planner planner(kin, {}, {});
  sim::PlannedMove last;
  for (const auto& m : moves) last = planner.plan(m);
  const Vec3 tip = planner.pose_at(moves.back(), last, 1.0).translation();
  // W^-1 of a workpiece shifted +10 um in X: the tip lands 10 um lower in X.
  EXPECT_NEAR((tip - Vec3(1 - 0.01, 0.5, 0.2)).norm(), 0, 1e-9) << tip.transpose();
}

}  // namespace
}  // namespace cutsim::test
