#pragma once
// Modal interpretation of blocks into moves, as the controller of the
// chosen dialect would (see the README's dialect table).
#include <array>
#include <string>
#include <vector>

#include "cutsim/gcode/block.h"
#include "cutsim/motion/move.h"

namespace cutsim::motion {

struct InterpreterOptions {
  AxisValues initial;  ///< where the machine is when the program starts (mm, rad)
  gcode::Dialect dialect = gcode::Dialect::rs274ngc;
  /// Arc end-point check as LinuxCNC: an arc whose end radius differs from
  /// its start radius by more than both limits is an error.
  double arc_radius_tolerance_mm = 0.00127;  ///< 0.00005 in, LinuxCNC's RADIUS_TOLERANCE
  double arc_radius_tolerance_rel = 0.001;   ///< LinuxCNC's SPIRAL_RELATIVE_TOLERANCE
  /// Work offsets G54..G59, G59.1..G59.3 (index 0..8), mm and radians.
  std::array<AxisValues, 9> work_offsets{};
};

enum class FeedMode { per_minute, inverse_time, per_revolution };

struct ModalState {
  MotionKind motion = MotionKind::rapid;
  bool motion_set = false;  ///< false until a G0-G3 appears (or after G80)
  Vec3 plane_normal = Vec3::UnitZ();  ///< G17 +Z, G18 +Y, G19 +X
  int plane = 17;
  bool absolute = true;     ///< G90 / G91
  bool arc_absolute = false;  ///< G90.1 / G91.1
  bool inches = false;      ///< G20 / G21
  bool diameter_mode = false;  ///< G7 / G8 (X is a diameter)
  FeedMode feed_mode = FeedMode::per_minute;
  double feed = 0;          ///< F as programmed, converted to mm (per min or per rev)
  double spindle_rpm = 0;
  int spindle_dir = 0;      ///< +1 M3, -1 M4, 0 M5
  int tool_in_spindle = 0;
  int tool_selected = 0;
  int length_offset_h = -1; ///< H of G43 / G43.4 / G43.5; -1 when cancelled (G49)
  bool tcp = false;         ///< G43.4 / G43.5
  int coord_system = 0;     ///< 0 = G54 ... 8 = G59.3
  bool tilted = false;      ///< G68.2 active
  Pose tilt = Pose::Identity();  ///< G68.2 frame in work coordinates
  bool tool_axis_control = false;  ///< G53.1 after G68.2
  bool ended = false;       ///< M2 / M30 seen
};

/// Warnings are non-fatal remarks against a line (for `cutsim check`).
struct Warning {
  int line = 0;
  int column = 0;
  std::string message;
};

/// Interprets blocks in order. Each call to `execute` appends the block's
/// moves to `out` (zero or one).
/// @throw ParseError for an unknown or unsupported code, an unknown letter,
///        two words of one modal group, a bad arc, a feed move without a
///        feed (with the line and column).
class Interpreter {
public:
  Interpreter(std::string file_name, InterpreterOptions options = {});

  void execute(const gcode::Block& block, std::vector<Move>& out);

  const ModalState& state() const { return state_; }
  const AxisValues& position() const { return pos_; }
  const std::vector<Warning>& warnings() const { return warnings_; }
  const std::array<AxisValues, 9>& work_offsets() const { return opt_.work_offsets; }

private:
  Vec3 to_program(const Vec3& machine) const;
  Vec3 to_machine(const Vec3& program) const;

  std::string file_;
  InterpreterOptions opt_;
  ModalState state_;
  AxisValues pos_;          // machine position
  std::vector<Warning> warnings_;
};

}  // namespace cutsim::motion
