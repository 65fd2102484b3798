#pragma once
// The region a tool's cutting envelope sweeps along one move, as a signed
// distance function (mm, negative inside).
//
// Exactness: the sign is exact for every primitive (the zero set is the true
// swept boundary). The distance is exact outside; inside it is exact near
// the boundary of lines and G17 arcs, and a lower bound (never larger than
// the true depth) elsewhere. Lower bounds are what the stock update needs
// for its conservative culling.
#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <optional>
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
  bool axis_z = false;       ///< to_local is the identity (a 3-axis tool): no rotation to apply
  Vec3 d_local;     ///< the move in local coordinates
  tool::RevolvedEnvelope env;
  Aabb bounds;      ///< of the swept region
  enum class Case { vertical, horizontal, parallelogram, general } kind;
  /// A ball end's core sweep (detail::ball_core_offset), worked out once so
  /// that a voxel's distance takes products, not divisions: 1 / r2 and
  /// 1 / (L r2), r2 = d.x^2 + d.y^2 and L the core's length (0 where the
  /// parallelogram is a segment), and 1 / |e|^2 of its edges: e = d (the
  /// bottom and top), (0, 0, L) (the sides) and the vertical case's span.
  double inv_r2 = 0, inv_lr2 = 0, inv_dd = 0, inv_ll = 0, inv_span = 0;
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
  /// The move has a part along the cutting direction (a prism, not a sheet
  /// in the rake plane), and the edge's half angle's sine and cosine.
  bool prism = false;
  double sin_half = 0, cos_half = 1;
  /// A prism's factors from in-plane to 3-D distance (detail::prism_distance),
  /// worked out once: for the side faces (gradient (+-cos_half, -sin_half)
  /// in the rake plane, y >= 0 and y < 0) and for the top.
  double f_side[2] = {1, 1}, f_top = 1;
  /// 1 / d_local.x (a prism's): where along the move a point lies is a
  /// product, not a division, per voxel.
  double inv_dx = 0;
};

/// The joints of a profile prism with the ones before and after it at the
/// same orientation (consecutive straight moves of a V or nose tool:
/// joint_prim). Each prism's flat end cap lies inside its neighbour's cut,
/// so near every joint both measure the voxels inside their union as no
/// deeper than the way to the cap: a sheet of near-zero values across the
/// cut (half a voxel of its section counted as material), and a band as
/// thick as the cut where moves are shorter than the band. This piece is
/// the intersection of the middle prism drawn on both ways (capped where
/// it has no neighbour), the one before drawn on past its end, the one
/// after drawn back before its start, a slab reaching `half_width` past
/// the middle one's ends and its box. Its part beside each prism's length
/// lies in that prism, so it lies in their union, and its depth (that of
/// an intersection: the largest of its parts' distances) bounds the
/// union's. Outside it is no nearer than one of the prisms (beside each
/// one's length, or beyond the first's start or the last's end, that
/// one's distance is one of its parts), so only its inside matters
/// (interior_only); its box term makes its distance no less than the way
/// to its box.
///
/// That is a valley's shape: where the path's slope rises at a joint, the
/// cut beside it is the intersection of the two prisms drawn on. Over a
/// crest (the slope falls) the cut is their union, and the intersection
/// lies below it by up to the slopes' difference times the way from the
/// joint: too shallow. A crest's piece (`crest`, crest_prim) is the union
/// of the middle prism drawn on past its end and the one after drawn
/// back before its start, within a slab about the joint no longer than
/// either prism (there each drawn-on part lies in the other prism's cut:
/// over a crest each line runs above the other beyond the joint), with
/// its box. Its depth, the larger of the two prisms', is the distance to
/// the nearer of their flank planes, which is the union's but where the
/// nearest point is on the crease itself.
struct JointPrim {
  /// One prism: its start and its move in the shared frame, with
  /// ProfilePrim's factors (so that each part is worked out as the prism's
  /// own distance is, to the bit).
  struct Side {
    Vec3 origin, d;
    double inv_dx = 0;
    double f_side[2] = {1, 1}, f_top = 1;
  };
  Eigen::Matrix3d to_local;  ///< the prisms' (the same)
  Side before, mid, after;   ///< before ends where mid starts, after starts where it ends
  bool has_before = false, has_after = false;
  tool::EdgeProfile edge;
  double sin_half = 0, cos_half = 1;
  double sign = 1;        ///< +1 where the moves run along the frame's +x, -1 along -x
  /// The slab, along the cut from the middle prism's start (sign * local x):
  /// a valley's piece reaches the band past the middle prism's ends, a
  /// crest's about the joint at its end.
  double slab_lo = 0, slab_hi = 0;
  bool crest = false;     ///< a crest's piece: the union of mid (drawn on) and after (drawn back)
  bool lipschitz = false; ///< the prisms' distances are (sweep::lipschitz)
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

using Primitive = std::variant<LinearPrim, ArcPrim, ProfilePrim, TorusPrim, HullPrim, JointPrim>;

double distance(const Primitive& p, const Vec3& x);
/// The same, with a profile prism's inlined: for the stock update's voxel
/// loop, where V tools spend their time (elsewhere, as in the binning's
/// loops, the inlined code only crowds out what the compiler inlines there).
inline double distance_inline(const Primitive& p, const Vec3& x);
const Aabb& bounds(const Primitive& p);
/// True when the piece's distance is 1-Lipschitz inside as well as outside
/// (|d(x) - d(y)| <= |x - y| everywhere), so a value at one point bounds it
/// nearby on both sides of the surface. Holds where it is the distance to
/// a convex core less a radius, or the exact distance of a capped prism or
/// a torus: lines that are vertical, horizontal or of a zero-radius core
/// (ball ends), G17 arcs, fly-cutter tori, and a pointed (V) edge moved in
/// the plane of its cutting direction and axis (planing, lifting and
/// lowering: its sides stay planes). Not for the general line (an
/// approximate minimisation) or other profile prisms (a first-order
/// estimate when sheared sideways or with a round nose).
bool lipschitz(const Primitive& p);
/// True where only the piece's inside matters: outside it is no nearer than
/// other pieces of the same sweeps (a joint: JointPrim), so the stock
/// update passes it over wherever it cannot be negative.
inline bool interior_only(const Primitive& p) { return std::holds_alternative<JointPrim>(p); }
/// Where the piece's distance is convex in x (a ball end's line: the
/// distance to the parallelogram or segment its core sweeps less the
/// ball's radius; a hull piece), or bounded below by a convex function
/// equal to it at x (a fly-cutter's torus on its cutting side), sets `d` to the
/// distance at `x` (the same value `distance` gives) and `g` to a
/// subgradient, so d(y) >= d(x) + g . (y - x) for every y; else returns
/// false and sets nothing.
inline bool convex_distance(const Primitive& p, const Vec3& x, double* d, Vec3* g);
/// Where the piece's distance is the distance to a set (its core: a ball
/// end's segment or the parallelogram it sweeps, a hull piece's
/// tetrahedron, a torus's core circle) less a radius: that radius; else
/// NaN. Where `convex_distance` gives d and g at x, g is the unit offset
/// from x's nearest core point s, and |y - s| bounds the core's distance
/// at y from above: with D = d(x) + radius > 0,
/// d(y) <= d(x) + g . (y - x) + |y - x|^2 / (2 D).
inline double core_radius(const Primitive& p);

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

/// The box of the part of `shape`, placed at `tip` with orientation `R`,
/// that is not higher along the tool axis than the top of `reach`
/// (tool::shape_bounds_below): it holds every point of the shape within `reach`.
Aabb world_box_within(const tool::Shape& shape, const Eigen::Matrix3d& R, const Vec3& tip, const Aabb& reach);

/// Tightens the pieces' boxes (and the sweep's) to what lies within `reach`:
/// a box may then hold less than the whole piece, but every point of the
/// piece within `reach`. For the one who knows nothing outside `reach`
/// matters (the stock: its box grown by more than its band): binning,
/// culling and "is anything near" tests then see a V tool's 10 um of cut,
/// not its 0.1 mm edge. A profile prism's box is that of the part of its
/// profile not higher along the tool axis than the top of `reach`, a
/// fly-cutter torus's that of its part below that top; other pieces'
/// boxes are cut to `reach`. `Sweep::distance` stays exact for
/// points within `reach` up to `reach`'s distance from their outside.
void clip_bounds(Sweep& s, const Aabb& reach);

/// True where `b` starts where `a` ends (within 1e-9 mm), both prisms of
/// one edge at one orientation running the same way along it: the two can
/// share a JointPrim.
bool joinable(const ProfilePrim& a, const ProfilePrim& b);

/// The piece for `mid` and its neighbours (JointPrim; each may be null, and
/// must be joinable with `mid` where it is not), with its slab reaching
/// `half_width` past `mid`'s ends (the stock's band: deeper values are
/// clamped alike) and its box within `reach` (empty: unbounded); nothing
/// where it has no neighbour or no box.
std::optional<JointPrim> joint_prim(const ProfilePrim* before, const ProfilePrim& mid, const ProfilePrim* after,
                                    double half_width, const Aabb& reach);

/// The piece for the crest where `after` starts at `mid`'s end (joinable,
/// the slope falling): the union of the two drawn on over the joint, in a
/// slab reaching up to twice `half_width` each way from it but no farther
/// than either prism's length, within its box in `reach`; nothing where it
/// has no box.
std::optional<JointPrim> crest_prim(const ProfilePrim& mid, const ProfilePrim& after, double half_width,
                                    const Aabb& reach);

/// Closes the joints of consecutive moves' prisms: the sweeps must come in
/// the program's order, every move's (an empty sweep breaks the chain).
///
/// Where the path turns over a crest (its slope along the cut falls, the
/// sideways part nil) and has run that way for twice `half_width` before
/// the joint, the new prism is drawn back that far along its own line
/// instead: behind the joint that line runs above the
/// path, and a V lifted along its own axis lies inside itself, so the
/// longer prism is still inside the cut (the strip its lifted top adds
/// must lie outside `reach`). Beside the joint each voxel then has a
/// prism whose cap is at least `half_width` away, deeper being clamped
/// alike, so no JointPrim is needed there: one prism distance a voxel,
/// where a joint took three (the snowflake's dome is all crests). The
/// drawn-back line runs above the path by up to the slopes' difference
/// times the way back, so a voxel it holds reads that much too shallow:
/// only where that is within 1 % of `half_width` at `half_width` back.
///
/// A sharper crest, or a shorter run, gets a crest's piece (crest_prim);
/// elsewhere (a valley, a sideways move) each prism gets its JointPrim.
/// Both need the move after the joint, so they are added to that move's
/// sweep, and the last prism's JointPrim to what `finish` returns.
class Joiner {
 public:
  Joiner(double half_width, const Aabb& reach) : half_width_(half_width), reach_(reach) {}
  void operator()(Sweep& s);
  /// The last prism's piece, once the moves have ended (empty if none).
  Sweep finish();
  /// Joints closed by drawing a prism back (no JointPrim), JointPrims made
  /// for valleys (and where a prism joins none), and crests' pieces.
  std::size_t extended() const { return extended_; }
  std::size_t joints() const { return joints_; }
  std::size_t crests() const { return crests_; }

 private:
  // last_'s JointPrim (with before_ and `after`, where joined), added to s.
  void emit(Sweep& s, const ProfilePrim* after);
  // `next` (joinable after last_) drawn back over the joint, where it may be.
  std::optional<ProfilePrim> drawn_back(const ProfilePrim& next) const;
  double half_width_;
  Aabb reach_;
  std::optional<ProfilePrim> before_, last_;  // the last prism and the one before it, where joined by a JointPrim
  // The crest run ending at last_'s end: its length along the cut, and its
  // steepest slope (its first prism's, as slopes fall along a crest).
  double run_ = 0, run_slope_ = 0;
  std::size_t extended_ = 0, joints_ = 0, crests_ = 0;
};

/// Fly-cutter revolutions: the swing torus at each pose.
Sweep sweep_tori(const std::vector<Pose>& poses, const tool::SwingTorus& torus);

/// A single tool pose (no motion): the envelope at `tip` with axis +Z.
Sweep tool_at(const Vec3& tip, const tool::Tool& tool);

// ---------------------------------------------------------------------------
// Inline: the distances the stock update evaluates per voxel, here so that
// it inlines them (forced: GCC otherwise keeps the calls, a fifth of the
// update). `distance` and `convex_distance` share this arithmetic, so both
// give the same value to the bit.
namespace detail {

[[gnu::always_inline]] inline double clamp01(double t) { return t < 0 ? 0 : (t > 1 ? 1 : t); }

// The squared distance from p to the box (0 inside): what the stock
// update's box tests, a prism's distance and a joint's box term take.
[[gnu::always_inline]] inline double box_distance2(const Aabb& b, const Vec3& p) {
  const double dx = std::max(std::max(b.min.x() - p.x(), p.x() - b.max.x()), 0.0);
  const double dy = std::max(std::max(b.min.y() - p.y(), p.y() - b.max.y()), 0.0);
  const double dz = std::max(std::max(b.min.z() - p.z(), p.z() - b.max.z()), 0.0);
  return dx * dx + dy * dy + dz * dz;
}

// Written on scalars (in Eigen's order of operations, so the values are
// those of the Eigen expressions to the bit): inlined, the Eigen
// expressions were not.
struct Off {
  double x, y, z;
  double norm2() const { return x * x + y * y + z * z; }
};

// A world point in a piece's frame: m (world to local) applied to w - origin.
[[gnu::always_inline]] inline Off to_frame(const Eigen::Matrix3d& m, const Vec3& origin, const Vec3& w) {
  const double rx = w.x() - origin.x(), ry = w.y() - origin.y(), rz = w.z() - origin.z();
  return {m(0, 0) * rx + m(0, 1) * ry + m(0, 2) * rz, m(1, 0) * rx + m(1, 1) * ry + m(1, 2) * rz,
          m(2, 0) * rx + m(2, 1) * ry + m(2, 2) * rz};
}

// A direction in a piece's frame back in the world's: m's transpose applied.
[[gnu::always_inline]] inline Vec3 from_frame(const Eigen::Matrix3d& m, double gx, double gy, double gz) {
  return Vec3(m(0, 0) * gx + m(1, 0) * gy + m(2, 0) * gz, m(0, 1) * gx + m(1, 1) * gy + m(2, 1) * gz,
              m(0, 2) * gx + m(1, 2) * gy + m(2, 2) * gz);
}

// p less its nearest point on the segment ab.
[[gnu::always_inline]] inline Off seg_offset(const Off& p, const Off& a, const Off& b) {
  const double abx = b.x - a.x, aby = b.y - a.y, abz = b.z - a.z;
  const double l2 = abx * abx + aby * aby + abz * abz;
  const double pax = p.x - a.x, pay = p.y - a.y, paz = p.z - a.z;
  const double t = l2 > 0 ? clamp01((pax * abx + pay * aby + paz * abz) / l2) : 0.0;
  return {pax - t * abx, pay - t * aby, paz - t * abz};
}

// The same for the segment from a along ab, given 1 / |ab|^2 (0 for a point).
[[gnu::always_inline]] inline Off seg_offset_inv(const Off& p, const Off& a, const Off& ab, double inv_l2) {
  const double pax = p.x - a.x, pay = p.y - a.y, paz = p.z - a.z;
  const double t = clamp01((pax * ab.x + pay * ab.y + paz * ab.z) * inv_l2);
  return {pax - t * ab.x, pay - t * ab.y, paz - t * ab.z};
}

// p less its nearest point on the parallelogram {s d + t u : s, t in
// [0,1]}, u = (0,0,L) (a ball end's core swept along d): its norm is the
// distance, and over the norm the gradient. The piece's reciprocals
// (LinearPrim::inv_r2 ...) stand for its divisions.
[[gnu::always_inline]] inline Off parallelogram_offset(const Off& p, const Off& d, double L, const LinearPrim& lp) {
  const Off o{0, 0, 0}, u{0, 0, L}, du{d.x, d.y, d.z + L}, e{0, 0, L};
  // u is vertical, so the plane's normal d x u is level: (d.y, -d.x, 0) L.
  if (lp.inv_lr2 == 0) return seg_offset(p, o, du);
  // In-plane coordinates (s, t) of p's projection: p = s d + t u + (normal).
  const double ph = p.x * d.x + p.y * d.y;
  const double s = ph * lp.inv_r2;
  const double t = (p.z * (d.x * d.x + d.y * d.y) - ph * d.z) * lp.inv_lr2;
  if (s >= 0 && s <= 1 && t >= 0 && t <= 1) {
    const double k = (p.x * d.y - p.y * d.x) * lp.inv_r2;
    return {k * d.y, -k * d.x, 0};
  }
  // Outside: the nearest point of a convex polygon lies on an edge whose
  // line separates the point from it, so only the violated edges count.
  Off best{0, 0, 0};
  double best2 = std::numeric_limits<double>::infinity();
  auto take = [&](const Off& v) {
    const double v2 = v.norm2();
    if (v2 < best2) best = v, best2 = v2;
  };
  // A side edge's nearest point to a point below its lower end is that
  // end, which the bottom edge holds too: then only the bottom edge (as
  // below a ball end's centre, where it cuts).
  if (t < 0) take(seg_offset_inv(p, o, d, lp.inv_dd));
  if (t > 1) take(seg_offset_inv(p, u, d, lp.inv_dd));
  if (s < 0 && !(t < 0 && p.z <= 0)) take(seg_offset_inv(p, o, e, lp.inv_ll));
  if (s > 1 && !(t < 0 && p.z <= d.z)) take(seg_offset_inv(p, d, e, lp.inv_ll));
  return best;
}

// A ball end's core (a segment on the axis) moved along a line: x less its
// nearest point on the parallelogram the core sweeps, in the piece's frame.
// The vertical case is the segment the core's ends span.
[[gnu::always_inline]] inline Off ball_core_offset(const LinearPrim& lp, const Off& p) {
  const Vec3& dl = lp.d_local;
  const Off d{dl.x(), dl.y(), dl.z()};
  const double L = lp.env.core_length;
  if (lp.kind == LinearPrim::Case::vertical) {
    const double z0 = std::min(0.0, d.z);
    return seg_offset_inv(p, Off{0, 0, z0}, Off{0, 0, std::max(0.0, d.z) + L - z0}, lp.inv_span);
  }
  return parallelogram_offset(p, d, L, lp);
}

/// A world point in the piece's frame.
[[gnu::always_inline]] inline Off to_piece(const LinearPrim& lp, const Vec3& x) {
  if (lp.axis_z) return {x.x() - lp.origin.x(), x.y() - lp.origin.y(), x.z() - lp.origin.z()};
  return to_frame(lp.to_local, lp.origin, x);
}

/// A ball end's line (LinearPrim with a zero disk radius): the distance to
/// the parallelogram its core sweeps, less the ball's radius.
[[gnu::always_inline]] inline double ball_line_distance(const LinearPrim& lp, const Vec3& x) {
  return std::sqrt(ball_core_offset(lp, to_piece(lp, x)).norm2()) - lp.env.corner_radius;
}

/// p less its nearest point on the hull (zero inside).
Vec3 hull_offset(const Vec3& p, const HullPrim& h);

// A fly-cutter's swing torus at a world point: the point in the torus's
// frame and its parts there (tool::torus_at).
[[gnu::always_inline]] inline tool::TorusAt torus_at(const TorusPrim& tp, const Vec3& w) {
  const Off q = to_frame(tp.to_local, tp.origin, w);
  return tool::torus_at(tp.torus, q.x, q.y, q.z);
}

// Signed distance of an extruded 2D region: `a` the signed in-plane distance,
// `b` the signed distance along the extrusion axis.
[[gnu::always_inline]] inline double prism_sd(double a, double b) {
  const double ao = std::max(a, 0.0), bo = std::max(b, 0.0);
  return std::sqrt(ao * ao + bo * bo) + std::min(std::max(a, b), 0.0);
}

// The factor from a prism's in-plane distance to its 3-D one, for a face
// whose in-plane gradient g meets the move d (ax = |d.x|, gd = g . d).
[[gnu::always_inline]] inline double prism_factor(double ax, double gd) { return ax / hypot2(ax, gd); }

// A prism's in-plane distance, scaled to 3-D: the edge's 2-D distance at
// (y, z) (the point's in-plane place less the cross-section's) times the
// lean of its nearest face, or the top's; `f_side` and `f_top` the faces'
// factors for the move d (ProfilePrim's).
[[gnu::always_inline]] inline double prism_section(const tool::EdgeProfile& e, double sin_half, double cos_half,
                                                   const Vec3& d, const double (&f_side)[2], double f_top, double y,
                                                   double z) {
  // The profile's two cases, with the factor worked into each.
  const double af = tool::profile_cases(
      e, sin_half, cos_half, y, z,
      [&](double r, double, double b) {
        // Nearest to the nose's centre: the gradient (y, b) / r turns with
        // the point. Its factor ax / hypot(ax, g . d), multiplied through
        // by r: one division where normalising the gradient first took three.
        const double ax = std::fabs(d.x());
        const double f = r > 0 ? ax * r / hypot2(ax * r, y * d.y() + b * d.z()) : prism_factor(ax, -d.z());
        return (r - e.nose_radius) * f;
      },
      // A side face: its factor is the piece's, worked out once.
      [&](double r) { return (r - e.nose_radius) * f_side[y < 0 ? 1 : 0]; });
  return std::max(af, (z - e.height) * f_top);
}

// A profile prism's distance (ProfilePrim::prism): the cross-section at
// the point's place along the cutting direction is the profile moved along
// the in-plane part of the move; the side faces lean by that motion, so the
// in-plane distance is scaled by the lean of the nearest face.
[[gnu::always_inline]] inline double prism_distance(const ProfilePrim& pp, const Vec3& w) {
  const Off q = to_frame(pp.to_local, pp.origin, w);
  const double px = q.x, py = q.y, pz = q.z;
  const Vec3& d = pp.d_local;
  const double s = clamp01(px * pp.inv_dx);
  const double a = prism_section(pp.edge, pp.sin_half, pp.cos_half, d, pp.f_side, pp.f_top, py - s * d.y(), pz - s * d.z());
  const double b = d.x() > 0 ? std::max(-px, px - d.x()) : std::max(px, d.x() - px);
  // prism_sd(a, b), without its root where b <= 0 (inside the piece's
  // length): sqrt(a * a) is a to the bit (round to nearest), above 1e-150.
  double r = b <= 0 && !(a > 0 && a < 1e-150) ? (a > 0 ? a : 0.0) + std::min(std::max(a, b), 0.0) : prism_sd(a, b);
  // Outside, no less than the way to the piece's box: a sheared prism's
  // first-order distance can fall a little below it (below the apex, in
  // the far band), where the stock update's box test, a true bound, would
  // then pass over a voxel the distance would lower, and the voxel would
  // depend on the order its pieces are tried in. (Still 1-Lipschitz: the
  // box's distance is 0 on the piece's surface.)
  if (r > 0) {
    const double b2 = box_distance2(pp.bounds, w);
    if (b2 > r * r) r = std::sqrt(b2);
  }
  return r;
}

// One prism of a JointPrim at w, drawn on past its ends but where
// `start_cap`, `end_cap`: the arithmetic of prism_distance, so that beside
// the prism's length it is that prism's distance to the bit.
[[gnu::always_inline]] inline double joint_part(const JointPrim& jp, const JointPrim::Side& sd, const Vec3& w,
                                                bool start_cap, bool end_cap) {
  const Off q = to_frame(jp.to_local, sd.origin, w);
  const double x = q.x, y = q.y, z = q.z;
  double s = x * sd.inv_dx;
  if (start_cap) s = std::max(s, 0.0);
  if (end_cap) s = std::min(s, 1.0);
  const double a =
      prism_section(jp.edge, jp.sin_half, jp.cos_half, sd.d, sd.f_side, sd.f_top, y - s * sd.d.y(), z - s * sd.d.z());
  constexpr double kOpen = -std::numeric_limits<double>::infinity();
  const double b = std::max(start_cap ? -jp.sign * x : kOpen, end_cap ? jp.sign * (x - sd.d.x()) : kOpen);
  return b == kOpen ? a : prism_sd(a, b);
}

// A JointPrim's distance, the largest of its box's, the slab's and its
// prisms' (the middle one's first; a crest's: the least of its two
// prisms'), where that is below `lim`; else a value
// no more than it and no less than `lim`, from the parts worked out until
// one reached `lim`.
[[gnu::always_inline]] inline double joint_distance_below(const JointPrim& jp, const Vec3& w, double lim) {
  // The box's signed distance: inside, the way to its nearest face.
  const Aabb& bx = jp.bounds;
  const double om = std::max(std::max(std::max(bx.min.x() - w.x(), w.x() - bx.max.x()),
                                      std::max(bx.min.y() - w.y(), w.y() - bx.max.y())),
                             std::max(bx.min.z() - w.z(), w.z() - bx.max.z()));
  double g = om <= 0 ? om : std::sqrt(box_distance2(bx, w));
  const Eigen::Matrix3d& m = jp.to_local;
  const double along = jp.sign * (m(0, 0) * (w.x() - jp.mid.origin.x()) + m(0, 1) * (w.y() - jp.mid.origin.y()) +
                                  m(0, 2) * (w.z() - jp.mid.origin.z()));
  g = std::max(g, std::max(jp.slab_lo - along, along - jp.slab_hi));  // the slab
  if (g >= lim) return g;
  if (jp.crest) {
    // The union: the larger depth of the two, where either is below g.
    // (mid keeps its start cap though the slab starts no earlier: without
    // it, outside the piece came nearer than the prisms' union.)
    const double a = joint_part(jp, jp.mid, w, true, false);
    if (a <= g) return g;
    return std::max(g, std::min(a, joint_part(jp, jp.after, w, false, true)));
  }
  g = std::max(g, joint_part(jp, jp.mid, w, !jp.has_before, !jp.has_after));
  if (g >= lim) return g;
  if (jp.has_before) g = std::max(g, joint_part(jp, jp.before, w, true, false));
  if (jp.has_after) g = std::max(g, joint_part(jp, jp.after, w, false, true));
  return g;
}

// A JointPrim's distance.
[[gnu::always_inline]] inline double joint_distance(const JointPrim& jp, const Vec3& w) {
  return joint_distance_below(jp, w, std::numeric_limits<double>::infinity());
}

}  // namespace detail

[[gnu::always_inline]] inline double distance_inline(const Primitive& p, const Vec3& x) {
  if (const auto* pp = std::get_if<ProfilePrim>(&p); pp && pp->prism) return detail::prism_distance(*pp, x);
  return distance(p, x);
}

/// For a piece whose inside only matters (interior_only): its distance
/// where that is below `lim`, else a value no less than `lim` and no more
/// than its distance (a bound, for less work). Not inlined: in the stock
/// update's loops the three prisms' code crowded out the rest (raster40k,
/// which has no joints, lost 8 % of its voxel step to it).
double distance_below(const Primitive& p, const Vec3& x, double lim);

/// A fly-cutter torus's distance (what `distance` gives for it).
[[gnu::always_inline]] inline double torus_distance(const TorusPrim& tp, const Vec3& x) {
  return detail::torus_at(tp, x).D - tp.torus.nose_radius;
}

[[gnu::always_inline]] inline bool convex_distance(const Primitive& p, const Vec3& x, double* d, Vec3* g) {
  if (const auto* hp = std::get_if<HullPrim>(&p)) {
    const Vec3 v = detail::hull_offset(x, *hp);
    const double n = v.norm();
    *d = n - hp->radius;
    *g = n > 0 ? Vec3(v / n) : Vec3::Zero();
    return true;
  }
  if (const auto* tp = std::get_if<TorusPrim>(&p)) {
    // A fly-cutter's torus is not convex, but where u >= a (the cutting
    // side: not nearer the spindle axis than the tube's core circle) its
    // distance equals H - r, H = hypot(max(u - a, 0), y), and H is convex
    // everywhere: u is a norm, max(u - a, 0) convex and >= 0, and hypot is
    // convex and growing in a non-negative argument. D >= H everywhere
    // (|u - a| >= max(u - a, 0)), so H's tangent plane at x bounds the
    // distance everywhere: d(y) >= H(y) - r >= d(x) + g . (y - x). Nearer
    // the axis than a (far above the tip) the plane would not hold: no.
    const tool::TorusAt t = detail::torus_at(*tp, x);
    if (!(t.q >= 0 && t.u > 0)) return false;
    *d = t.D - tp->torus.nose_radius;
    if (!(t.D > 0)) {
      *g = Vec3::Zero();  // on the core circle: H's least value, 0 a subgradient
    } else {
      const double gu = t.q / (t.D * t.u);
      const double gx = gu * t.x, gy = t.y / t.D, gz = gu * (t.z - tp->torus.swing);
      *g = detail::from_frame(tp->to_local, gx, gy, gz);
    }
    return true;
  }
  const auto* lp = std::get_if<LinearPrim>(&p);
  if (!lp || lp->env.disk_radius != 0) return false;
  // A ball end: the distance to a convex set (the core's sweep) less a
  // radius, so convex, and the unit offset from the nearest point is its
  // gradient (0 on the core, a subgradient there). The same arithmetic as
  // linear_distance.
  const detail::Off v = detail::ball_core_offset(*lp, detail::to_piece(*lp, x));
  const double n = std::sqrt(v.norm2());
  *d = n - lp->env.corner_radius;
  if (!(n > 0)) {
    *g = Vec3::Zero();
  } else {
    const double gx = v.x / n, gy = v.y / n, gz = v.z / n;
    if (lp->axis_z) {
      *g = Vec3(gx, gy, gz);
    } else {
      *g = detail::from_frame(lp->to_local, gx, gy, gz);
    }
  }
  return true;
}

/// A lower bound for a profile prism that is not 1-Lipschitz (a round
/// nose, a sideways move), worked out at a point x (prism_section_plane)
/// and taken at x + y (section_bound).
///
/// Its parts: A, the edge's 2-D signed distance at a point's place in the
/// section with the move's shear not clamped to the prism's length; the
/// profile is convex (a wedge no wider than a half plane, rounded), so A is
/// convex, and so is A composed with the (affine) shear: its tangent plane
/// P at x lies below it. And the point's place along the move, px, linear.
/// Within the prism's length its distance is A scaled by the lean of the
/// nearest face, a factor in [f_min, 1] (f_min from the move's sideways
/// part), or a larger term (the top's, the box's): so at least P where P
/// < 0 and f_min P where P >= 0; and inside, no deeper than the way to
/// its nearer end (a voxel deep in a turn's sweep but near the end of one
/// of its pieces). Beyond its ends it is at least the way
/// past the end along the move, b; and its section there is the end's,
/// which lies within b shear of the section drawn on (shear = |(d.y,
/// d.z)| / |d.x|; A is 1-Lipschitz in the plane): so at least f_min (P -
/// b shear) too. (Between a turn's consecutive pieces a voxel is past the
/// end of one and within the next: the way past the end alone let five
/// in six of a lens's distances worked out past an end lower nothing.)
struct SectionPlane {
  double c = 0;              ///< A at x
  Vec3 g = Vec3::Zero();     ///< A's gradient at x (world)
  double px = 0;             ///< the place along the move at x (the prism's frame)
  Vec3 axis = Vec3::Zero();  ///< px's gradient (world): the prism's cutting direction
  double lo = 0, hi = 0;     ///< the prism's length: px in [lo, hi]
  double f_min = 1;          ///< the least lean factor
  double shear = 0;          ///< |(d.y, d.z)| / |d.x|: the section's drift per unit along the move
};

/// A profile prism's SectionPlane at `x`; false for other pieces.
[[gnu::always_inline]] inline bool prism_section_plane(const Primitive& p, const Vec3& x, SectionPlane* out) {
  const auto* pp = std::get_if<ProfilePrim>(&p);
  if (!pp || !pp->prism || !(pp->edge.half_angle <= kPi / 2)) return false;
  const detail::Off q = detail::to_frame(pp->to_local, pp->origin, x);
  const double px = q.x, py = q.y, pz = q.z;
  const Eigen::Matrix3d& m = pp->to_local;
  const Vec3& d = pp->d_local;
  const double s = px * pp->inv_dx;  // (not clamped)
  double gy = 0, gz = 0;
  out->c = tool::profile_distance_2d(pp->edge, pp->sin_half, pp->cos_half, py - s * d.y(), pz - s * d.z(), &gy, &gz);
  // The section's place (py - s d.y, pz - s d.z) moves with px by -d.y/d.x
  // and -d.z/d.x: the gradient in the piece's frame, then the world's.
  const double gx = -(gy * d.y() + gz * d.z()) * pp->inv_dx;
  out->g = detail::from_frame(m, gx, gy, gz);
  out->px = px;
  out->axis = Vec3(m(0, 0), m(0, 1), m(0, 2));
  out->lo = std::min(0.0, d.x());
  out->hi = std::max(0.0, d.x());
  // A face's factor is |d.x| / hypot(|d.x|, g . d) for its unit in-plane
  // gradient g (prism_factor): never below this.
  out->f_min = std::fabs(d.x()) / std::sqrt(d.x() * d.x() + d.y() * d.y() + d.z() * d.z());
  out->shear = std::sqrt(d.y() * d.y() + d.z() * d.z()) * std::fabs(pp->inv_dx);
  return true;
}

/// The prism's distance at x + y is at least this (see SectionPlane).
[[gnu::always_inline]] inline double section_bound(const SectionPlane& sp, const Vec3& y) {
  const double px = sp.px + sp.axis.dot(y);
  const double a = sp.c + sp.g.dot(y);
  // The way past the nearer end (negative within the length).
  const double b = std::max(sp.lo - px, px - sp.hi);
  if (b > 0) return std::max(b, sp.f_min * (a - b * sp.shear));
  return a >= 0 ? sp.f_min * a : std::max(a, b);
}

/// section_bound's least over the cube of half width `w` around the plane's
/// point (x + y, |y_i| <= w): with a and px at their extremes there, the
/// way past the ends at its least, and where it is positive the least of
/// max(b, f_min (a - b shear)) over b.
[[gnu::always_inline]] inline double section_bound_over(const SectionPlane& sp, double w) {
  const double a = sp.c - w * sp.g.cwiseAbs().sum();
  const double e = w * sp.axis.cwiseAbs().sum();
  const double b = std::max(sp.lo - (sp.px + e), (sp.px - e) - sp.hi);
  const double inside = a >= 0 ? sp.f_min * a / (1 + sp.f_min * sp.shear) : a;
  return b > 0 ? std::max(b, inside) : inside;
}

inline double core_radius(const Primitive& p) {
  if (const auto* hp = std::get_if<HullPrim>(&p)) return hp->radius;
  if (const auto* tp = std::get_if<TorusPrim>(&p)) return tp->torus.nose_radius;
  if (const auto* lp = std::get_if<LinearPrim>(&p); lp && lp->env.disk_radius == 0) return lp->env.corner_radius;
  return std::numeric_limits<double>::quiet_NaN();
}

}  // namespace cutsim::sweep
