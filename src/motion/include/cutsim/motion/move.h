#pragma once
// A resolved move in the workpiece frame: mm and radians inside, with the NC
// line that caused it.
#include <memory>
#include <string>

#include "cutsim/core/geometry.h"

namespace cutsim::motion {

enum class MotionKind { rapid, linear, arc_cw, arc_ccw };

/// "G0", "G1", "G2" or "G3".
const char* motion_name(MotionKind k);

/// Machine axis values: X, Y, Z in mm; A, B, C in radians.
struct AxisValues {
  Vec3 xyz = Vec3::Zero();
  Vec3 abc = Vec3::Zero();
};

struct Move {
  int line = 0;                       ///< 1-based NC line
  std::shared_ptr<const std::string> text;  ///< the NC line as written
  MotionKind kind = MotionKind::linear;
  AxisValues start, end;
  // Arcs only:
  Vec3 centre = Vec3::Zero();  ///< arc centre, in the arc's plane through the start
  Vec3 normal = Vec3::UnitZ(); ///< unit normal of the arc plane; G3 turns positively about it
  int turns = 1;               ///< full turns for P>1 (1 = the ordinary arc)
  double feed_mm_per_min = 0;  ///< 0 for rapids and for inverse-time moves without length
  double duration_s = 0;       ///< inverse time (G93): the move's time; else 0
  int tool = 0;                ///< T number in the spindle
  double spindle_rpm = 0;      ///< S word in force
  bool tcp = false;            ///< tool centre point control (G43.4/G43.5) active
  Vec3 tool_axis = Vec3::UnitZ();  ///< requested tool axis in the workpiece frame (G53.1)

  bool is_arc() const { return kind == MotionKind::arc_cw || kind == MotionKind::arc_ccw; }
  /// Some rotary axis moves.
  bool turns_rotary() const { return (end.abc - start.abc).cwiseAbs().maxCoeff() > 0; }
  /// Not an arc and no rotary axis moving: the tool pose is then an affine
  /// image of straight joint motion, a straight tip path at one orientation.
  bool is_straight() const { return !is_arc() && !turns_rotary(); }
  bool is_cutting_feed() const { return kind != MotionKind::rapid; }

  /// Signed sweep angle of an arc in radians about `normal` (negative for
  /// clockwise), including extra turns; a full circle is +-2 pi.
  double arc_sweep_angle() const;
  /// Arc radius at the start and at the end (they may differ slightly).
  double arc_start_radius() const;
  double arc_end_radius() const;
  /// Point on the path at parameter t in [0,1] (arcs: angle and radius
  /// interpolated linearly, the component along the normal linearly: helix).
  Vec3 point_at(double t) const;
  /// Bounding box of the tool control point over the whole move.
  Aabb path_bounds() const;
  /// Path length, mm (arcs: the helix length).
  double length() const;
};

}  // namespace cutsim::motion
