#pragma once
// Rotating end mills. The control point is the tool tip on the tool axis:
// the lowest point of a ball end mill, the centre of a flat end.
#include <string>

namespace cutsim::tool {

enum class ToolKind { ball, flat, bull };

struct Tool {
  ToolKind kind = ToolKind::ball;
  std::string name;            ///< as specified, e.g. "ball:d=1"
  double diameter_mm = 1.0;
  double corner_radius_mm = 0;  ///< ball: d/2; flat: 0; bull: r
  double flute_length_mm = 0;   ///< cutting length from the tip; default 2 d

  double radius() const { return diameter_mm / 2; }
};

/// The cutting envelope of a rotating tool as a Minkowski sum:
/// disk(radius disk_radius, normal to the axis) + ball(corner_radius) +
/// axial segment [0, core_length], placed with its core base at
/// `core_offset` along the axis above the tip.
struct RevolvedEnvelope {
  double disk_radius = 0;
  double corner_radius = 0;
  double core_length = 0;
  double core_offset = 0;
};

RevolvedEnvelope cutting_envelope(const Tool& t);

/// Parses `kind:key=value,...`: `ball:d=1`, `flat:d=6,l=12`, `bull:d=2,r=0.2`.
/// Keys: d (diameter, mm), r (corner radius, mm; bull only), l (flute length).
/// @throw ConfigError naming the spec and what is wrong (unknown kind, key,
///        or a non-positive size). `origin` names where the spec came from.
Tool parse_tool_spec(const std::string& spec, const std::string& origin = "--tool");

}  // namespace cutsim::tool
