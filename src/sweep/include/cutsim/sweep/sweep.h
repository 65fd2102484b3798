#pragma once
// The region a tool's cutting envelope sweeps along one move, as a signed
// distance function (mm, negative inside).
//
// Exactness: the sign is exact for every primitive (the zero set is the true
// swept boundary). The distance is exact outside; inside it is exact near
// the boundary of lines and G17 arcs, and a lower bound (never larger than
// the true depth) elsewhere. Lower bounds are what the stock update needs
// for its conservative culling.
#include <functional>
#include <variant>
#include <vector>

#include "cutsim/core/geometry.h"
#include "cutsim/motion/move.h"
#include "cutsim/tool/tool.h"

namespace cutsim::sweep {

/// Envelope moved along a straight line with a fixed tool axis.
struct LinearPrim {
  Vec3 origin;      ///< core base at the start (tip + core_offset * axis)
  Eigen::Matrix3d to_local;  ///< rows: u, v, w (w = tool axis)
  Vec3 d_local;     ///< the move in local coordinates
  tool::RevolvedEnvelope env;
  Aabb bounds;      ///< of the swept region
  enum class Case { vertical, horizontal, parallelogram, general } kind;
};

/// Envelope moved along a circular arc in the plane normal to the tool axis
/// (G17 arcs with a Z tool), constant radius and height.
struct ArcPrim {
  Vec3 centre;      ///< arc centre at the core base height
  double radius = 0;
  double start_angle = 0;  ///< radians, about +Z
  double sweep_angle = 0;  ///< signed; |sweep| >= 2 pi means a full circle
  tool::RevolvedEnvelope env;
  Aabb bounds;
};

/// A non-rotating tool's cutting edge profile moved along a straight line
/// at a fixed orientation: a prism (sheared when the move leaves the
/// cutting direction). Sign exact; distance exact for moves along the
/// cutting direction, a first-order estimate for sheared prisms.
struct ProfilePrim {
  Vec3 origin;                ///< tip at the start
  Eigen::Matrix3d to_local;   ///< rows: cutting direction, across, tool axis
  Vec3 d_local;               ///< the move in local coordinates
  tool::EdgeProfile edge;     ///< orientation folded into to_local
  Aabb bounds;
};

/// A fly-cutter's revolution at one place: the swing torus at a pose. Exact.
struct TorusPrim {
  Vec3 origin;                ///< tip
  Eigen::Matrix3d to_local;
  tool::SwingTorus torus;
  Aabb bounds;
};

/// A ball end turning while it moves: the convex hull of its axial core
/// (ball centre to the top of the flutes) at the two ends of the piece,
/// grown by the ball's radius. Where the turn keeps the axis in the plane
/// of the motion, as a tool held on a wall's normal does, the hull is flat
/// and the true sweep departs from it only by the curvature of the
/// points' paths (the sweep's bisection holds that and the hull's
/// thickness to its tolerance): many fewer pieces than holding an
/// orientation, whose error grows with the turn itself. Exact distance to
/// the hull; convex.
struct HullPrim {
  Vec3 p[4];        ///< core ends: centre and top at the start, centre and top at the end
  double radius = 0;
  Aabb bounds;
  /// Per face (the three points other than p[3 - f]): its normal pointing
  /// away from the fourth point (zero length for a flat hull's face set:
  /// then it is always measured) and its offset n . (a point of it).
  Vec3 normal[4];
  double offset[4] = {0, 0, 0, 0};
};

/// The hull piece of four core points grown by `radius` (normals and bounds set).
HullPrim hull_prim(const Vec3& p0, const Vec3& p1, const Vec3& p2, const Vec3& p3, double radius);

using Primitive = std::variant<LinearPrim, ArcPrim, ProfilePrim, TorusPrim, HullPrim>;

double distance(const Primitive& p, const Vec3& x);
const Aabb& bounds(const Primitive& p);
/// True when the piece's distance is 1-Lipschitz inside as well as outside
/// (|d(x) - d(y)| <= |x - y| everywhere), so a value at one point bounds it
/// nearby on both sides of the surface. Holds where it is the distance to
/// a convex core less a radius, or the exact distance of a capped prism or
/// a torus: lines that are vertical, horizontal or of a zero-radius core
/// (ball ends), G17 arcs, fly-cutter tori. Not for the general line (an
/// approximate minimisation) or a profile prism (a first-order estimate
/// when sheared).
bool lipschitz(const Primitive& p);
/// Where the piece's distance is convex in x (a ball end's line: the
/// distance to a flat convex core less the ball's radius), sets `d` to the
/// distance at `x` (the same value `distance` gives) and `g` to a
/// subgradient, so d(y) >= d(x) + g . (y - x) for every y; else returns
/// false and sets nothing.
bool convex_distance(const Primitive& p, const Vec3& x, double* d, Vec3* g);

struct SweepOptions {
  /// Largest distance between an arc and the chords that stand for it where
  /// an arc cannot be swept exactly (G18/G19 arcs, helices, spirals), mm.
  double chord_tolerance_mm = 1e-4;
};

/// The swept cutting region of one move: a union of primitives.
struct Sweep {
  std::vector<Primitive> prims;
  Aabb bounds;
  double distance(const Vec3& x) const;
};

/// Box of a tool-frame box placed at `tip` with orientation `R`.
Aabb world_box(const Aabb& local, const Eigen::Matrix3d& R, const Vec3& tip);

/// Builds the sweep of `move` for a rotating end mill whose axis is +Z (3-axis milling).
/// Straight moves and G17 arcs of constant radius and height are exact;
/// other arcs become chords within `opt.chord_tolerance_mm`.
Sweep sweep_move(const motion::Move& move, const tool::Tool& tool, const SweepOptions& opt = {});

/// A straight move of the tool tip from `tip0` to `tip1` with the tool frame
/// rotated by `R` (the tool axis is R's third column). Exact for envelopes
/// and profiles; a fly-cutter's torus is placed at steps whose scallop
/// stays below 0.1 um.
Sweep sweep_line(const Vec3& tip0, const Vec3& tip1, const Eigen::Matrix3d& R, const tool::Shape& shape);
Sweep sweep_line(const Vec3& tip0, const Vec3& tip1, const Eigen::Matrix3d& R, const tool::Tool& tool);

/// A move whose tool pose (tip at the origin, axis +Z) is `pose_at(t)`,
/// t in [0, 1], bisected until the tip and the top of the envelope stay
/// within `tolerance_mm` of the chords. A ball end's pieces are hulls of
/// its core at their two ends (HullPrim), bisected also until a hull is
/// no thicker than `tolerance_mm`; other shapes' are exact straight sweeps
/// holding the orientation at the piece's middle, bisected also until that
/// moves the top by at most `tolerance_mm`. Starts from `min_pieces`.
/// With `region` (where the sweep can cut: the stock), an envelope's
/// "top" is its farthest point inside the region.
Sweep sweep_poses(const std::function<Pose(double)>& pose_at, const tool::Shape& shape, double tolerance_mm,
                  int min_pieces = 4, const Aabb* region = nullptr);

/// Fly-cutter revolutions: the swing torus at each pose.
Sweep sweep_tori(const std::vector<Pose>& poses, const tool::SwingTorus& torus);

/// A single tool pose (no motion): the envelope at `tip` with axis +Z.
Sweep tool_at(const Vec3& tip, const tool::Tool& tool);

}  // namespace cutsim::sweep
