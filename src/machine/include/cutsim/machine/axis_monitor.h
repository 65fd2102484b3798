#pragma once
// Axis capability along the program (seeds/002): velocity, acceleration and
// stroke of every joint against the machine's limits, by NC line.
//
// Estimate from discrete blocks: within a block each joint moves at the
// constant velocity dq/dt (dt from the feed, or the block's inverse time);
// at the junction of two feed blocks the acceleration is the velocity
// change divided by the mean of their durations. A rapid or a dwell starts
// from and ends at rest (the controller plans its own ramps), so the
// acceleration is not checked across it.
#include <memory>
#include <string>
#include <vector>

#include "cutsim/machine/kinematics.h"

namespace cutsim::machine {

struct AxisViolation {
  int line = 0;
  std::shared_ptr<const std::string> text;
  char axis = 'X';
  std::string quantity;  ///< "velocity", "acceleration" or "stroke"
  double value = 0;      ///< largest on that line: mm/s, mm/s^2, mm (deg for rotary)
  double limit = 0;
  std::string unit;
};

/// How far over its limit a record is: value / limit.
double excess(const AxisViolation& a);

/// The indices of the `n` records furthest over their limits (the earlier
/// of equal ones), in program order.
std::vector<std::size_t> worst_violations(const std::vector<AxisViolation>& v, std::size_t n);

/// The records of one axis and quantity.
struct ViolationKind {
  char axis = 'X';
  std::string quantity, unit;
  double limit = 0;
  std::size_t records = 0;
  std::size_t worst = 0;  ///< index of the furthest over (the first of equal ones)
  int first_line = 0, last_line = 0;
};

/// One entry per axis and quantity present, by axis, then quantity.
std::vector<ViolationKind> summarize_violations(const std::vector<AxisViolation>& v);

/// A ~ min{L/2, Vmax/(2 pi f), Amax/(4 pi^2 f^2)} for a sinusoid of frequency f.
struct AmplitudeLimit {
  char axis = 'X';
  double frequency_hz = 0;
  double amplitude_mm = 0;
  std::string limited_by;  ///< "stroke", "velocity" or "acceleration"
};

AmplitudeLimit amplitude_limit(const Joint& j, double frequency_hz);

class AxisMonitor {
public:
  AxisMonitor(const Machine& m, const JointValues& start);
  /// The joints reach `q` after `dt` seconds of NC line `line`. A block may
  /// come in several steps (arcs, TCP moves): `block_dt` is the whole
  /// block's duration and `first` marks its first step, where the change of
  /// velocity from the previous block is taken over the mean of the two
  /// blocks' durations (between steps, over the steps').
  void step(const JointValues& q, double dt, bool feed, int line, const std::shared_ptr<const std::string>& text,
            double block_dt = -1, bool first = true);
  /// Joints at rest (a dwell, a tool change).
  void rest();
  const std::vector<AxisViolation>& violations() const { return out_; }
  /// Turning rotary joints: full revolutions and the time spent turning.
  double revolutions(int joint) const { return revs_[static_cast<std::size_t>(joint)]; }
  double turning_time(int joint) const { return turn_time_[static_cast<std::size_t>(joint)]; }

private:
  void flag(std::size_t j, int line, const std::shared_ptr<const std::string>& text, const char* what, double v, double lim);
  const Machine& m_;
  JointValues q_;
  std::vector<double> v_;
  double dt_prev_ = 0;
  double block_dt_prev_ = 0;
  bool moving_ = false;
  std::vector<AxisViolation> out_;
  std::vector<double> revs_, turn_time_;
};

}  // namespace cutsim::machine
