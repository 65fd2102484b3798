#pragma once
// Modal interpretation of RS274NGC blocks into moves (3-axis milling subset
// plus rotary axis words carried through).
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "cutsim/gcode/block.h"
#include "cutsim/motion/move.h"

namespace cutsim::motion {

struct InterpreterOptions {
  AxisValues initial;  ///< where the machine is when the program starts (mm, rad)
  /// Arc end-point check as LinuxCNC: an arc whose end radius differs from
  /// its start radius by more than both limits is an error.
  double arc_radius_tolerance_mm = 0.00127;  ///< 0.00005 in, LinuxCNC's RADIUS_TOLERANCE
  double arc_radius_tolerance_rel = 0.001;   ///< LinuxCNC's SPIRAL_RELATIVE_TOLERANCE
};

struct ModalState {
  MotionKind motion = MotionKind::rapid;
  bool motion_set = false;  ///< false until a G0-G3 appears
  int plane_axis = 2;       ///< 2 = G17 (XY), 1 = G18 (ZX), 0 = G19 (YZ)
  bool absolute = true;     ///< G90 / G91
  bool inches = false;      ///< G20 / G21
  double feed_mm_per_min = 0;
  double spindle_rpm = 0;
  int spindle_dir = 0;      ///< +1 M3, -1 M4, 0 M5
  int tool_in_spindle = 0;
  int tool_selected = 0;
  bool ended = false;       ///< M2 / M30 seen
};

/// Warnings are non-fatal remarks against a line (for `cutsim check`).
struct Warning {
  int line = 0;
  int column = 0;
  std::string message;
};

/// Interprets blocks in order. Each call to `execute` appends the block's
/// moves to `out` (usually zero or one).
/// @throw ParseError for an unknown G or M code, an unknown letter, two
///        words of one modal group, a bad arc (with the line and column).
class Interpreter {
public:
  Interpreter(std::string file_name, InterpreterOptions options = {});

  void execute(const gcode::Block& block, std::vector<Move>& out);

  const ModalState& state() const { return state_; }
  const AxisValues& position() const { return pos_; }
  const std::vector<Warning>& warnings() const { return warnings_; }

private:
  std::string file_;
  InterpreterOptions opt_;
  ModalState state_;
  AxisValues pos_;
  std::vector<Warning> warnings_;
};

}  // namespace cutsim::motion
