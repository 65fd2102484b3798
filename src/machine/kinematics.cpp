#include "cutsim/machine/kinematics.h"

#include <Eigen/LU>

#include "cutsim/core/error.h"

namespace cutsim::machine {

int axis_index(char axis) {
  switch (axis) {
    case 'X': return 0; case 'Y': return 1; case 'Z': return 2;
    case 'A': return 3; case 'B': return 4; case 'C': return 5;
    default: return -1;
  }
}

JointValues joints_of(const motion::AxisValues& v) {
  return {v.xyz.x(), v.xyz.y(), v.xyz.z(), v.abc.x(), v.abc.y(), v.abc.z()};
}

Kinematics::Kinematics(Machine m) : m_(std::move(m)) {
  // Identity: exactly X, Y, Z along their own axes, no errors, no settings.
  identity_ = m_.chain.size() == 3 && m_.tool_setting.isApprox(Pose::Identity(), 0) &&
              m_.workpiece_setting.isApprox(Pose::Identity(), 0);
  for (const Joint& j : m_.chain) {
    const int i = axis_index(j.axis);
    if (j.type != JointType::linear || i > 2 || !j.direction.isApprox(Vec3::Unit(i), 0) || !j.error.zero())
      identity_ = false;
  }
}

Pose Kinematics::tool_pose(const JointValues& q) const {
  Pose p = m_.workpiece_setting.inverse();
  for (const Joint& j : m_.chain) {
    const double v = q[static_cast<std::size_t>(axis_index(j.axis))];
    Pose jt = Pose::Identity();
    if (j.type == JointType::linear) {
      jt.translation() = v * j.direction;
    } else {
      jt.linear() = Eigen::AngleAxisd(v, j.direction).toRotationMatrix();
      jt.translation() = j.origin - jt.linear() * j.origin;
    }
    p = p * jt;
    if (!j.error.zero()) p = p * j.error.transform();
  }
  return p * m_.tool_setting;
}

JointValues Kinematics::solve_tip(const Vec3& tip, const JointValues& q) const {
  JointValues base = q;
  Eigen::Matrix3d J = Eigen::Matrix3d::Zero();
  int cols[3] = {-1, -1, -1};
  int n = 0;
  for (const Joint& j : m_.chain)
    if (j.type == JointType::linear && n < 3) cols[n++] = axis_index(j.axis);
  if (n == 0) throw GeometryError({}, "machine " + m_.name + " has no linear axis to place the tool tip with");
  for (int k = 0; k < n; ++k) base[static_cast<std::size_t>(cols[k])] = 0;
  const Vec3 p0 = tool_pose(base).translation();
  for (int k = 0; k < n; ++k) {
    JointValues e = base;
    e[static_cast<std::size_t>(cols[k])] = 1.0;
    J.col(k) = tool_pose(e).translation() - p0;
  }
  JointValues out = q;
  if (n == 3) {
    Eigen::FullPivLU<Eigen::Matrix3d> lu(J);
    if (!lu.isInvertible()) throw GeometryError({}, "the linear axes cannot reach every direction at this pose");
    const Vec3 s = lu.solve(tip - p0);
    for (int k = 0; k < 3; ++k) out[static_cast<std::size_t>(cols[k])] = s[k];
  } else {
    // Two linear axes (a lathe): least squares in their plane.
    const Eigen::MatrixXd A = J.leftCols(n);
    const Eigen::VectorXd s = A.colPivHouseholderQr().solve(tip - p0);
    for (int k = 0; k < n; ++k) out[static_cast<std::size_t>(cols[k])] = s[k];
  }
  return out;
}

}  // namespace cutsim::machine
