#include "cutsim/sim/planner.h"

#include <cmath>

#include "cutsim/core/error.h"

namespace cutsim::sim {

using machine::JointValues;
using machine::JointType;

namespace {
machine::Machine without_errors(machine::Machine m) {
  for (auto& j : m.chain) j.error = machine::JointError{};
  m.tool_setting = Pose::Identity();
  m.workpiece_setting = Pose::Identity();
  return m;
}
}  // namespace

Planner::Planner(const machine::Kinematics& kin, const motion::AxisValues&, Options opt)
    : kin_(kin), nominal_(without_errors(kin.machine())), opt_(opt) {
  if (opt_.environment && !opt_.environment->empty()) n_ref_ = opt_.environment->refractive_index(0.0);
  bool laser = false;
  for (const auto& j : kin_.machine().chain) laser |= j.laser.has_value();
  exact_ = kin_.is_identity() && !(laser && opt_.environment);
}

PlannedMove Planner::plan(const motion::Move& m) {
  const auto& mach = kin_.machine();
  PlannedMove p;
  p.q0 = machine::joints_of(m.start);
  p.q1 = machine::joints_of(m.end);
  // Axes the program moves must exist on the machine.
  for (int i = 0; i < 6; ++i) {
    const char axis = "XYZABC"[i];
    const std::size_t k = static_cast<std::size_t>(i);
    if (mach.joint_of(axis) < 0 && (p.q1[k] != 0 || p.q0[k] != 0) && (i >= 3 || p.q1[k] != p.q0[k]))
      throw ParseError(SourceLocation{file_, m.line, 1, m.text ? *m.text : std::string()},
                       std::string("axis ") + axis + " is not on machine " + mach.name);
  }
  if ((m.tool_axis - Vec3::UnitZ()).norm() > 1e-12)
    throw ParseError(SourceLocation{file_, m.line, 1, m.text ? *m.text : std::string()},
                     "G53.1 tool axis control needs the rotary axes solved for the tool axis: not supported yet "
                     "(program the rotary axes)");
  if (m.tcp) {
    p.q0 = nominal_.solve_tip(m.start.xyz, p.q0);
    p.q1 = nominal_.solve_tip(m.end.xyz, p.q1);
  }
  double dt = 0;
  if (m.duration_s > 0) {
    dt = m.duration_s;
  } else if (m.kind == motion::MotionKind::rapid) {
    for (const auto& j : mach.chain) {
      const std::size_t i = static_cast<std::size_t>(machine::axis_index(j.axis));
      const double v = j.max_velocity > 0 ? j.max_velocity * mach.rapid_fraction
                                          : (j.type == JointType::linear ? 100.0 : 2 * kPi);
      dt = std::max(dt, std::fabs(p.q1[i] - p.q0[i]) / v);
    }
  } else {
    // Feed on the programmed path; a pure rotary move feeds in deg/min.
    double len = m.length();
    if (len < 1e-12) len = rad_to_deg((m.end.abc - m.start.abc).norm());
    dt = m.feed_mm_per_min > 0 ? len / (m.feed_mm_per_min / 60.0) : 0.0;
  }
  p.t0 = time_;
  p.t1 = time_ + dt;
  time_ = p.t1;
  return p;
}

JointValues Planner::with_laser_error(JointValues q, double t) const {
  if (!opt_.environment || opt_.environment->empty()) return q;
  const double n = opt_.environment->refractive_index(t);
  for (const auto& j : kin_.machine().chain)
    if (j.laser) {
      const std::size_t i = static_cast<std::size_t>(machine::axis_index(j.axis));
      const double e = machine::laser_position_error_mm(n_ref_, n, j.laser->dead_path_mm, q[i] - j.laser->origin_mm);
      for (double was = max_laser_.load(); std::fabs(e) > was && !max_laser_.compare_exchange_weak(was, std::fabs(e));) {
      }
      q[i] += e;
    }
  return q;
}

JointValues Planner::joints_at(const motion::Move& m, const PlannedMove& p, double s) const {
  JointValues q;
  for (std::size_t i = 0; i < 6; ++i) q[i] = p.q0[i] + s * (p.q1[i] - p.q0[i]);
  if (m.tcp) {
    q = nominal_.solve_tip(m.point_at(s), q);
  } else if (m.is_arc()) {
    const Vec3 x = m.point_at(s);
    q[0] = x.x(); q[1] = x.y(); q[2] = x.z();
  }
  return with_laser_error(q, p.t0 + s * (p.t1 - p.t0));
}

Pose Planner::pose_at(const motion::Move& m, const PlannedMove& p, double s) const {
  return kin_.tool_pose(joints_at(m, p, s));
}

namespace {
bool per_revolution(const motion::Move& m, const PlannedMove& p, const tool::Tool& tool) {
  return tool.kind == tool::ToolKind::flycutter && m.spindle_rpm > 0 && m.kind != motion::MotionKind::rapid &&
         p.t1 > p.t0;
}
}  // namespace

sweep::Sweep Planner::part_sweep(const motion::Move& m, const PlannedMove& p, const tool::Tool& tool, double s0,
                                 double s1) const {
  const tool::Shape shape = tool::cutting_shape(tool);
  if (per_revolution(m, p, tool)) {
    const double rev_s = 60.0 / m.spindle_rpm, ta = p.t0 + s0 * (p.t1 - p.t0), tb = p.t0 + s1 * (p.t1 - p.t0);
    std::vector<Pose> poses;
    for (double k = std::floor(ta / rev_s) + 1; k * rev_s <= tb; k += 1)
      poses.push_back(pose_at(m, p, (k * rev_s - p.t0) / (p.t1 - p.t0)));
    return sweep::sweep_tori(poses, std::get<tool::SwingTorus>(shape));
  }
  if (m.is_straight()) {
    const Pose a = pose_at(m, p, s0), b = pose_at(m, p, s1);
    return sweep::sweep_line(a.translation(), b.translation(), a.linear(), shape);
  }
  return sweep::sweep_poses([&](double u) { return pose_at(m, p, s0 + u * (s1 - s0)); }, shape,
                            opt_.sweep_tolerance_mm, 4, opt_.interest.empty() ? nullptr : &opt_.interest);
}

sweep::Sweep Planner::sweep_part(const motion::Move& m, const PlannedMove& p, const tool::Tool& tool, double s0,
                                 double s1) const {
  sweep::Sweep s = s0 <= 0 && s1 >= 1 ? whole_sweep(m, p, tool) : part_sweep(m, p, tool, s0, s1);
  if (!opt_.interest.empty()) sweep::clip_bounds(s, opt_.interest);
  return s;
}

sweep::Sweep Planner::sweep(const motion::Move& m, const PlannedMove& p, const tool::Tool& tool) const {
  return sweep_part(m, p, tool, 0.0, 1.0);
}

sweep::Sweep Planner::whole_sweep(const motion::Move& m, const PlannedMove& p, const tool::Tool& tool) const {
  const tool::Shape shape = tool::cutting_shape(tool);
  if (per_revolution(m, p, tool)) {
    // One swing torus per revolution, at the instants the program's time
    // line puts them (phase continuous from program start).
    const double rev_s = 60.0 / m.spindle_rpm;
    std::vector<Pose> poses;
    for (double k = std::floor(p.t0 / rev_s) + 1; k * rev_s <= p.t1; k += 1)
      poses.push_back(pose_at(m, p, (k * rev_s - p.t0) / (p.t1 - p.t0)));
    return sweep::sweep_tori(poses, std::get<tool::SwingTorus>(shape));
  }
  if (exact_ && std::holds_alternative<tool::RevolvedEnvelope>(shape))
    return sweep::sweep_move(m, tool, sweep::SweepOptions{opt_.chord_tolerance_mm});
  if (m.is_straight()) {
    // Rotary joints held: the tool pose is an affine image of the straight
    // joint motion, so the tip runs a straight line at a fixed orientation.
    const Pose a = pose_at(m, p, 0.0), b = pose_at(m, p, 1.0);
    return sweep::sweep_line(a.translation(), b.translation(), a.linear(), shape);
  }
  const int pieces = m.is_arc() ? std::max(4, static_cast<int>(std::ceil(std::fabs(m.arc_sweep_angle()) / (kPi / 8)))) : 4;
  if (!opt_.interest.empty()) {
    // Coarse bound: tips at 64 points, grown by the shape's reach and the
    // largest chord sagitta those points can leave.
    const Aabb lb = tool::shape_bounds(shape);
    const double reach = std::max(lb.min.cwiseAbs().maxCoeff(), lb.max.cwiseAbs().maxCoeff()) * std::sqrt(3.0);
    Aabb b;
    double step = 0;
    Vec3 prev = pose_at(m, p, 0.0).translation();
    b.extend(prev);
    for (int i = 1; i <= 64; ++i) {
      const Vec3 t = pose_at(m, p, i / 64.0).translation();
      step = std::max(step, (t - prev).norm());
      b.extend(t);
      prev = t;
    }
    if (!b.expanded(reach + step).overlaps(opt_.interest)) return {};
  }
  return sweep::sweep_poses([&](double s) { return pose_at(m, p, s); }, shape, opt_.sweep_tolerance_mm, pieces,
                            opt_.interest.empty() ? nullptr : &opt_.interest);
}

void Planner::monitor(const motion::Move& m, const PlannedMove& p, machine::AxisMonitor& mon) const {
  const bool feed = m.kind != motion::MotionKind::rapid;
  const bool rotary = m.turns_rotary();
  int steps = 1;
  if (m.is_arc()) steps = std::max(1, static_cast<int>(std::ceil(std::fabs(m.arc_sweep_angle()) / (kPi / 32))));
  else if (m.tcp && rotary) steps = 8;
  const double dt = (p.t1 - p.t0) / steps;
  for (int k = 1; k <= steps; ++k) {
    JointValues q;
    const double s = static_cast<double>(k) / steps;
    for (std::size_t i = 0; i < 6; ++i) q[i] = p.q0[i] + s * (p.q1[i] - p.q0[i]);
    if (m.tcp) q = nominal_.solve_tip(m.point_at(s), q);
    else if (m.is_arc()) {
      const Vec3 x = m.point_at(s);
      q[0] = x.x(); q[1] = x.y(); q[2] = x.z();
    }
    mon.step(q, dt, feed, m.line, m.text, p.t1 - p.t0, k == 1);
  }
  if (!feed) mon.rest();
}

}  // namespace cutsim::sim
