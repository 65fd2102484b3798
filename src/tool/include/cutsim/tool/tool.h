#pragma once
// Tools as sets of named regions with exact distance queries.
//
// The tool frame: the control point (tool tip) at the origin, the tool axis
// (towards the spindle or the tool shank) along +Z. Rotating tools are
// solids of revolution about +Z, except the fly-cutter, whose spindle axis
// is the tool frame's +Y: its tip circle (radius `swing`) lies in the XZ
// plane and its lowest point is the tip. Non-rotating diamond tools cut
// in their cutting direction, the tool frame's +X turned about +Z by
// `orientation_deg`; their rake face faces the cutting direction and their
// body lies behind it.
#include <cmath>
#include <map>
#include <string>
#include <variant>
#include <vector>

#include "cutsim/core/geometry.h"

namespace cutsim::tool {

enum class ToolKind { ball, flat, bull, flycutter, nose, vtool };

/// "ball", "flat", "bull", "flycutter", "nose" or "vtool".
const char* kind_name(ToolKind k);

struct Tool {
  ToolKind kind = ToolKind::ball;
  std::string name;            ///< as specified, e.g. "ball:d=1"
  int number = 0;              ///< T number (0: not from a library)
  // End mills (ball, flat, bull).
  double diameter_mm = 1.0;
  double corner_radius_mm = 0;  ///< ball: d/2; flat: 0; bull: r; fly-cutter and nose: nose radius
  double flute_length_mm = 0;   ///< cutting length from the tip; default 2 d
  double neck_diameter_mm = 0, neck_length_mm = 0;      ///< 0: no neck
  double shank_diameter_mm = 0, shank_length_mm = 0;    ///< default: d and 30 mm
  double holder_diameter_mm = 0, holder_length_mm = 0;  ///< 0: no holder envelope
  // A fly-cutter's shank is its arbor and its holder the flywheel, both
  // about the spindle axis; it has no neck.
  // Fly-cutter.
  double swing_radius_mm = 0;   ///< spindle axis to the tip
  // Non-rotating diamond tools (nose, vtool).
  double included_angle_deg = 0;
  double rake_angle_deg = 0;
  double clearance_angle_deg = 0;
  double orientation_deg = 0;   ///< cutting direction: +X turned about +Z
  double edge_height_mm = 0;    ///< cutting edge (and body) height above the tip
  double body_length_mm = 0;    ///< body behind the rake face, along the cutting direction

  bool rotating() const { return kind != ToolKind::nose && kind != ToolKind::vtool; }
  /// Half the width the tool cuts across its axis (fly-cutter: the swing).
  double radius() const;
};

/// The cutting envelope of a rotating tool as a Minkowski sum:
/// disk(radius disk_radius, normal to the axis) + ball(corner_radius) +
/// axial segment [0, core_length], placed with its core base at
/// `core_offset` along the axis above the tip. With corner_radius 0 it is a
/// cylinder: neck, shank and holder are such envelopes.
struct RevolvedEnvelope {
  double disk_radius = 0;
  double corner_radius = 0;
  double core_length = 0;
  double core_offset = 0;
};

/// A non-rotating tool's cutting edge: the region Q in its rake plane
/// (x = 0 of the cutting frame) bounded by the edge: a wedge of half angle
/// `half_angle` opening along +Z, rounded by `nose_radius` (0: pointed),
/// tip at the origin, cut off at `height`. Zero thickness: it removes what
/// it sweeps through.
struct EdgeProfile {
  double nose_radius = 0;
  double half_angle = kPi / 4;
  double height = 0.5;
  double cos_o = 1, sin_o = 0;  ///< cutting direction in the tool frame
};

/// A non-rotating tool's body behind its rake face: the edge profile Q
/// drawn back along -x, its cross-section shrinking by tan(clearance) per
/// unit length (the clearance faces), bounded by the rake face (tilted back
/// by the rake angle), the top at `height` and the back at `length`.
struct FlankBody {
  EdgeProfile edge;
  double clearance = 0;  ///< rad
  double rake = 0;       ///< rad
  double length = 1;
};

/// A fly-cutter's cutting region over one revolution: a torus about the
/// tool frame's Y axis through (0, 0, swing), tube radius `nose_radius`.
struct SwingTorus {
  double swing = 0;
  double nose_radius = 0;
};

using Shape = std::variant<RevolvedEnvelope, EdgeProfile, FlankBody, SwingTorus>;

/// A point (x, y, z) in the swing torus's frame, with its distance u from
/// the spindle axis, q = u - a (a = swing - nose radius, the radius of the
/// tube's core circle) and D = hypot(q, y), its distance to that circle:
/// the torus's distance is D - nose radius. Inline: the stock update
/// measures tori per voxel.
struct TorusAt {
  double x, y, z, u, q, D;
};
inline TorusAt torus_at(const SwingTorus& t, double x, double y, double z) {
  const double u = hypot2(x, z - t.swing);
  const double q = u - (t.swing - t.nose_radius);
  return {x, y, z, u, q, hypot2(q, y)};
}

/// Signed distance (mm, negative inside) from a point in the tool frame to
/// a shape at rest. Exact for envelopes, the torus and the profile; for the
/// flank body exact inside along the plane faces and a lower bound elsewhere.
double shape_distance(const Shape& s, const Vec3& p);
/// Box of the shape in the tool frame.
Aabb shape_bounds(const Shape& s);
/// Bounds of the part of a shape not higher than `top` along the tool axis
/// (local z): a V tool's edge and flank body are 0.1 mm high, and a
/// fly-cutter's torus 2 swings, but only their lowest micrometres reach
/// into the stock. Other shapes: all of it.
Aabb shape_bounds_below(const Shape& s, double top);

/// Signed distance in the rake plane to the edge profile Q (no height cap):
/// negative inside. Also gives the unit outward gradient (gy, gz).
double profile_distance_2d(const EdgeProfile& e, double y, double z, double* gy = nullptr, double* gz = nullptr);
/// The edge profile's two cases at a point of the rake plane, each with
/// the way r from the point to the profile before the nose radius is
/// taken off (the signed distance is r - nose radius): `round(r, a, b)`
/// where the point is nearest the nose's centre (a = |y|, b = z - nose
/// radius, r = hypot(a, b)), else `side(r)` (r from the side face's line
/// through that centre). Inline, given sin and cos of the half angle (sb,
/// cb): the stock update's prisms fold their lean into each case.
template <class Round, class Side>
[[gnu::always_inline]] inline double profile_cases(const EdgeProfile& e, double sb, double cb, double y, double z,
                                                   Round round, Side side) {
  const double a = std::fabs(y), b = z - e.nose_radius;
  if (a * sb + b * cb <= 0) return round(hypot2(a, b), a, b);
  return side(a * cb - b * sb);
}
/// profile_distance_2d given sin and cos of the half angle (sb, cb):
/// inline, for the flank body.
[[gnu::always_inline]] inline double profile_distance_2d(const EdgeProfile& e, double sb, double cb, double y,
                                                         double z, double* gy, double* gz) {
  double ga = cb, gb = -sb;  // (a side face's)
  const double r = profile_cases(
      e, sb, cb, y, z,
      [&](double r, double a, double b) {
        ga = r > 0 ? a / r : 0;
        gb = r > 0 ? b / r : -1;
        return r;
      },
      [](double r) { return r; });
  if (gy) *gy = y < 0 ? -ga : ga;
  if (gz) *gz = gb;
  return r - e.nose_radius;
}

/// A flank body's angles' sines and cosines (half angle, clearance, rake).
struct FlankTrig {
  double s_half, c_half, s_clear, c_clear, s_rake, c_rake;
};
FlankTrig flank_trig(const FlankBody& f);
/// A flank body's distance given its angles' sines and cosines: what
/// shape_distance gives for it, to the bit. Inline, with the sines worked
/// out once: the contact check measures one body at thousands of voxels a pose.
///
/// The distance is convex: the largest of three planes (rake face, back
/// end, top) and the flank term, the edge profile's signed distance in the
/// rake plane (convex: the profile is) scaled by cos(clearance) > 0 less a
/// linear term. With `g`, also sets a subgradient there (the largest
/// term's gradient; the profile's outward unit gradient in its apex
/// region), so distance(q) >= distance(p) + g . (q - p) for every q.
[[gnu::always_inline]] inline double flank_distance(const FlankBody& f, const FlankTrig& t, const Vec3& p,
                                                    Vec3* g = nullptr) {
  const EdgeProfile& e = f.edge;
  const double xc = e.cos_o * p.x() + e.sin_o * p.y();
  const double yc = -e.sin_o * p.x() + e.cos_o * p.y();
  double gy = 0, gz = 0;
  const double flank =
      profile_distance_2d(e, t.s_half, t.c_half, yc, p.z(), g ? &gy : nullptr, g ? &gz : nullptr) * t.c_clear -
      xc * t.s_clear;
  const double rake = xc * t.c_rake + p.z() * t.s_rake;
  const double d = std::max(std::max(flank, rake), std::max(-f.length - xc, p.z() - e.height));
  if (g) {
    // d/dp of xc is (cos_o, sin_o, 0), of yc (-sin_o, cos_o, 0).
    const Vec3 dxc(e.cos_o, e.sin_o, 0), dyc(-e.sin_o, e.cos_o, 0);
    if (d == flank) *g = t.c_clear * (gy * dyc + gz * Vec3::UnitZ()) - t.s_clear * dxc;
    else if (d == rake) *g = t.c_rake * dxc + t.s_rake * Vec3::UnitZ();
    else if (d == -f.length - xc) *g = -dxc;
    else *g = Vec3::UnitZ();
  }
  return d;
}

struct Region {
  std::string name;  ///< "clearance-face", "neck", "shank", "holder"
  Shape shape;
  /// Where the shape's own frame sits in the tool frame (a fly-cutter's
  /// parts turn about its spindle axis, the tool frame's Y).
  Pose frame = Pose::Identity();
};

/// The part that removes material.
Shape cutting_shape(const Tool& t);
/// The parts that only touch material (empty when the tool has none).
std::vector<Region> contact_regions(const Tool& t);

/// The cutting envelope of a rotating tool (not for non-rotating tools).
RevolvedEnvelope cutting_envelope(const Tool& t);

/// Parses `kind:key=value,...`, for example `ball:d=1`, `flat:d=6,l=12`,
/// `bull:d=2,r=0.2`, `flycutter:swing=18,r=2`, `nose:r=0.9789,clearance=10`,
/// `vtool:angle=90,clearance=7`. The keys are listed in the README.
/// @throw ConfigError naming the spec and what is wrong (unknown kind, key,
///        or a size out of range). `origin` names where the spec came from.
Tool parse_tool_spec(const std::string& spec, const std::string& origin = "--tool");

/// Builds a tool of `kind` from short keys (the spec's) with defaults filled
/// in and every size checked. @throw ConfigError naming `origin` and `what`.
Tool make_tool(const std::string& kind, const std::map<std::string, double>& keys, const std::string& what,
               const std::string& origin);

}  // namespace cutsim::tool
