#pragma once
// Moves on a machine: joint values, durations on the program's time line,
// tool poses along the move, and the swept region they cut.
#include <atomic>
#include <memory>
#include <optional>

#include "cutsim/machine/axis_monitor.h"
#include "cutsim/machine/environment.h"
#include "cutsim/machine/kinematics.h"
#include "cutsim/motion/move.h"
#include "cutsim/sweep/sweep.h"
#include "cutsim/tool/tool.h"

namespace cutsim::sim {

struct PlannedMove {
  double t0 = 0, t1 = 0;               ///< seconds on the program's time line
  machine::JointValues q0{}, q1{};     ///< commanded joints at the ends
};

/// Turns moves into joint motion on one machine, in program order.
/// Without tool centre point control the joints move linearly between the
/// programmed values (arcs: the programmed arc in X Y Z); with G43.4/G43.5
/// the tool tip follows the programmed path in the workpiece frame and the
/// linear joints are solved for it.
class Planner {
public:
  struct Options {
    const machine::EnvironmentLog* environment = nullptr;  ///< laser-scale error on when set
    double sweep_tolerance_mm = 1e-4;  ///< sampled sweeps stay this close to the true one
    double chord_tolerance_mm = 1e-4;  ///< arcs swept as chords (exact path): sagitta bound
    /// Moves whose envelope cannot reach this box get an empty sweep
    /// (checked on a coarse bound before any sampling); empty box: no check.
    Aabb interest;
  };
  Planner(const machine::Kinematics& kin, const motion::AxisValues& start, Options opt);

  /// Plans the next move; checks that its axes exist on the machine.
  /// @throw ParseError (the move's line) for an axis the machine lacks.
  PlannedMove plan(const motion::Move& m);
  /// The tool pose (tip at origin, axis +Z) at parameter s of a planned move.
  Pose pose_at(const motion::Move& m, const PlannedMove& p, double s) const;
  /// The cutting envelope's swept region over the move. With an `interest`
  /// box, the pieces' boxes are cut to it (sweep::clip_bounds).
  sweep::Sweep sweep(const motion::Move& m, const PlannedMove& p, const tool::Tool& tool) const;
  /// The swept region over the part [s0, s1] of the move (a fly-cutter's
  /// revolutions that fall in it; other tools within the sweep tolerance).
  sweep::Sweep sweep_part(const motion::Move& m, const PlannedMove& p, const tool::Tool& tool, double s0,
                          double s1) const;
  /// Feeds the axis monitor (arcs and multi-axis moves in sub-steps).
  void monitor(const motion::Move& m, const PlannedMove& p, machine::AxisMonitor& mon) const;

  double time_s() const { return time_; }
  double max_laser_error_mm() const { return max_laser_.load(); }
  const std::string& file() const { return file_; }
  void set_file(std::string f) { file_ = std::move(f); }

private:
  // The two without the clipping (sweep and sweep_part apply it).
  sweep::Sweep whole_sweep(const motion::Move& m, const PlannedMove& p, const tool::Tool& tool) const;
  sweep::Sweep part_sweep(const motion::Move& m, const PlannedMove& p, const tool::Tool& tool, double s0,
                          double s1) const;
  machine::JointValues joints_at(const motion::Move& m, const PlannedMove& p, double s) const;
  machine::JointValues with_laser_error(machine::JointValues q, double t) const;

  const machine::Kinematics& kin_;
  /// What the controller knows: the machine without its assembly and
  /// setting errors. Tool centre point control solves the joints with it,
  /// so the errors act on the tip as they do on a real machine.
  machine::Kinematics nominal_;
  Options opt_;
  double time_ = 0;
  double n_ref_ = 1;
  /// (Atomic: the contact check scans moves side by side.)
  mutable std::atomic<double> max_laser_{0};
  bool exact_ = false;  // identity kinematics and no laser error
  std::string file_;
};

}  // namespace cutsim::sim
