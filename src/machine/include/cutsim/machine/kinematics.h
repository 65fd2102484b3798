#pragma once
// Forward kinematics of a machine's shape-generation function and the tool
// tip solve used by tool centre point control.
#include <array>
#include <vector>

#include "cutsim/machine/machine.h"
#include "cutsim/motion/move.h"

namespace cutsim::machine {

/// Joint values indexed X Y Z A B C: mm and radians.
using JointValues = std::array<double, 6>;

int axis_index(char axis);  ///< 'X' -> 0 ... 'C' -> 5
JointValues joints_of(const motion::AxisValues& v);

class Kinematics {
public:
  explicit Kinematics(Machine m);
  const Machine& machine() const { return m_; }

  /// The tool frame (tip at its origin, tool axis +Z) in the workpiece
  /// frame: W^-1 * prod_j (J_j(q) * E_j) * T, with W and T the setting errors.
  Pose tool_pose(const JointValues& q) const;

  /// The linear joints that put the tool tip at `tip` (workpiece frame)
  /// with the rotary joints of `q`. Exact: with the rotary joints fixed the
  /// tip is affine in the linear ones.
  /// @throw GeometryError when the linear joints cannot reach every direction.
  JointValues solve_tip(const Vec3& tip, const JointValues& q) const;

  /// True when the tool pose is the programmed point with +Z axis for every
  /// joint value (a 3-axis XYZ chain without errors).
  bool is_identity() const { return identity_; }

private:
  Machine m_;
  bool identity_ = false;
  // Constant parts of the chain, computed once: W^-1, each joint's axis
  // index and its error transform (when it has one).
  Pose workpiece_inverse_ = Pose::Identity();
  std::vector<int> axis_;
  std::vector<Pose> error_;
  std::vector<char> has_error_;
};

}  // namespace cutsim::machine
