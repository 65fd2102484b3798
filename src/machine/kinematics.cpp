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
    axis_.push_back(i);
    has_error_.push_back(j.error.zero() ? 0 : 1);
    error_.push_back(j.error.zero() ? Pose::Identity() : j.error.transform());
  }
  workpiece_inverse_ = m_.workpiece_setting.inverse();
}

namespace {
// p * (rotation about the axis through `origin`), without the 4 x 4 product.
void turn(Pose& p, const Eigen::Matrix3d& R, const Vec3& origin) {
  p.translation() += p.linear() * (origin - R * origin);
  p.linear() = p.linear() * R;
}
}  // namespace

// The chain walked once per call; a linear joint only moves the frame along
// its direction, so it costs a matrix-vector product, not a transform product.
Pose Kinematics::tool_pose(const JointValues& q) const {
  Pose p = workpiece_inverse_;
  for (std::size_t i = 0; i < m_.chain.size(); ++i) {
    const Joint& j = m_.chain[i];
    const double v = q[static_cast<std::size_t>(axis_[i])];
    if (j.type == JointType::linear) p.translation() += p.linear() * (v * j.direction);
    else turn(p, Eigen::AngleAxisd(v, j.direction).toRotationMatrix(), j.origin);
    if (has_error_[i]) p = p * error_[i];
  }
  return p * m_.tool_setting;
}

JointValues Kinematics::solve_tip(const Vec3& tip, const JointValues& q) const {
  // With the rotary joints held the tip is affine in the linear ones: walk
  // the chain once with them at 0; a linear joint's column is its direction
  // in the frame the chain has reached there.
  Eigen::Matrix3d J = Eigen::Matrix3d::Zero();
  int cols[3] = {-1, -1, -1};
  int n = 0;
  Pose p = workpiece_inverse_;
  for (std::size_t i = 0; i < m_.chain.size(); ++i) {
    const Joint& j = m_.chain[i];
    if (j.type == JointType::linear) {
      if (n < 3) {
        J.col(n) = p.linear() * j.direction;
        cols[n++] = axis_[i];
      } else {
        p.translation() += p.linear() * (q[static_cast<std::size_t>(axis_[i])] * j.direction);
      }
    } else {
      turn(p, Eigen::AngleAxisd(q[static_cast<std::size_t>(axis_[i])], j.direction).toRotationMatrix(), j.origin);
    }
    if (has_error_[i]) p = p * error_[i];
  }
  if (n == 0) throw GeometryError({}, "machine " + m_.name + " has no linear axis to place the tool tip with");
  const Vec3 p0 = (p * m_.tool_setting).translation();
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
