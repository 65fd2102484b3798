#include "cutsim/sweep/sweep.h"

#include <array>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace cutsim::sweep {

namespace {

using detail::clamp01;
using detail::prism_sd;

// p less its nearest point on the segment ab (detail::seg_offset on Vec3s).
Vec3 seg_offset(const Vec3& p, const Vec3& a, const Vec3& b) {
  const detail::Off v =
      detail::seg_offset({p.x(), p.y(), p.z()}, {a.x(), a.y(), a.z()}, {b.x(), b.y(), b.z()});
  return Vec3(v.x, v.y, v.z);
}

// Distance from p to segment [a, b] in 2D.
double seg_dist2(double px, double py, double bx, double by) {
  const double bb = bx * bx + by * by;
  const double t = bb > 0 ? clamp01((px * bx + py * by) / bb) : 0.0;
  return hypot2(px - t * bx, py - t * by);
}


// p less its nearest point on the triangle abc (by the Voronoi regions of
// its vertices, edges and face).
Vec3 triangle_offset(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return ap;
  const Vec3 bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return bp;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return ap - (d1 / (d1 - d3)) * ab;
  const Vec3 cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return cp;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return ap - (d2 / (d2 - d6)) * ac;
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && d4 - d3 >= 0 && d5 - d6 >= 0) return bp - ((d4 - d3) / ((d4 - d3) + (d5 - d6))) * (c - b);
  const double den = va + vb + vc;
  if (!(den > 0)) {  // degenerate (collinear): the nearest of its edges
    Vec3 best = seg_offset(p, a, b);
    for (const Vec3& v : {seg_offset(p, b, c), seg_offset(p, a, c)})
      if (v.squaredNorm() < best.squaredNorm()) best = v;
    return best;
  }
  return ap - (vb / den) * ab - (vc / den) * ac;
}

// The face opposite point k of a hull: its three other points.
constexpr int kHullFace[4][3] = {{1, 2, 3}, {0, 2, 3}, {0, 1, 3}, {0, 1, 2}};

// Golden-section minimum of a unimodal function on [0,1].
template <class F>
double golden_min(F f) {
  const double g = 0.6180339887498949;
  double a = 0, b = 1;
  double x1 = b - g * (b - a), x2 = a + g * (b - a);
  double f1 = f(x1), f2 = f(x2);
  for (int i = 0; i < 60; ++i) {
    if (f1 < f2) { b = x2; x2 = x1; f2 = f1; x1 = b - g * (b - a); f1 = f(x1); }
    else { a = x1; x1 = x2; f1 = f2; x2 = a + g * (b - a); f2 = f(x2); }
  }
  return std::min(std::min(f(0.0), f(1.0)), std::min(f1, f2));
}

double linear_distance(const LinearPrim& lp, const Vec3& x) {
  const auto& e = lp.env;
  if (e.disk_radius == 0) return detail::ball_line_distance(lp, x);
  const detail::Off pl = detail::to_piece(lp, x);
  const Vec3 p(pl.x, pl.y, pl.z);
  const Vec3& d = lp.d_local;
  double core;
  switch (lp.kind) {
    case LinearPrim::Case::vertical: {
      const double zlo = std::min(0.0, d.z()), zhi = std::max(0.0, d.z()) + e.core_length;
      const double a = hypot2(p.x(), p.y()) - e.disk_radius;
      const double b = std::max(zlo - p.z(), p.z() - zhi);
      core = prism_sd(a, b);
      break;
    }
    case LinearPrim::Case::horizontal: {
      const double a = seg_dist2(p.x(), p.y(), d.x(), d.y()) - e.disk_radius;
      const double b = std::max(-p.z(), p.z() - e.core_length);
      core = prism_sd(a, b);
      break;
    }
    case LinearPrim::Case::parallelogram:  // a ball end's (measured above); the general case holds it too
    case LinearPrim::Case::general:
    default: {
      // K = disk(r) + [0,L] z + [0,1] d. Outside: distance is the minimum
      // over s of the distance to the translated cylinder (convex in s).
      const double r = e.disk_radius, L = e.core_length;
      auto cyl = [&](double s) {
        const double a = hypot2(p.x() - s * d.x(), p.y() - s * d.y()) - r;
        const double b = std::max(s * d.z() - p.z(), p.z() - s * d.z() - L);
        return prism_sd(a, b);
      };
      const double out = golden_min([&](double s) { return std::max(cyl(s), 0.0); });
      if (out > 0) { core = out; break; }
      // Inside: the deepest single-cylinder depth, a lower bound on the
      // depth in the hull (concave in s).
      core = golden_min(cyl);
      break;
    }
  }
  return core - e.corner_radius;
}

double arc_distance(const ArcPrim& ap, const Vec3& x) {
  const double px = x.x() - ap.centre.x(), py = x.y() - ap.centre.y();
  const double rho = hypot2(px, py);
  const double two_pi = 2 * kPi;
  bool in_range = std::fabs(ap.sweep_angle) >= two_pi;
  if (!in_range) {
    const double phi = std::atan2(py, px);
    double rel = ap.sweep_angle > 0 ? phi - ap.start_angle : ap.start_angle - phi;
    rel = std::fmod(rel, two_pi);
    if (rel < 0) rel += two_pi;
    in_range = rel <= std::fabs(ap.sweep_angle);
  }
  double hd;
  if (in_range) {
    hd = std::fabs(rho - ap.radius);
  } else {
    const double a0 = ap.start_angle, a1 = ap.start_angle + ap.sweep_angle;
    hd = std::min(hypot2(px - ap.radius * std::cos(a0), py - ap.radius * std::sin(a0)),
                  hypot2(px - ap.radius * std::cos(a1), py - ap.radius * std::sin(a1)));
  }
  const double a = hd - ap.env.disk_radius;
  const double z = x.z() - ap.centre.z();
  const double b = std::max(-z, z - ap.env.core_length);
  return prism_sd(a, b) - ap.env.corner_radius;
}

Aabb envelope_box_z(const Vec3& base, const tool::RevolvedEnvelope& e) {
  const double R = e.disk_radius + e.corner_radius;
  return Aabb{base + Vec3(-R, -R, -e.corner_radius),
              base + Vec3(R, R, e.core_length + e.corner_radius)};
}

// World box of the envelope with its core base at `base` and axis `w`.
Aabb envelope_box(const Vec3& base, const Vec3& w, const tool::RevolvedEnvelope& e) {
  Aabb b;
  b.extend(base);
  b.extend(base + e.core_length * w);
  Vec3 pad;
  for (int k = 0; k < 3; ++k) pad[k] = e.disk_radius * std::sqrt(std::max(0.0, 1 - w[k] * w[k])) + e.corner_radius;
  return Aabb{b.min - pad, b.max + pad};
}

LinearPrim make_linear(const Vec3& base0, const Vec3& base1, const tool::RevolvedEnvelope& env,
                       const Eigen::Matrix3d& R = Eigen::Matrix3d::Identity()) {
  LinearPrim lp;
  lp.origin = base0;
  lp.to_local = R.transpose();  // rows: the tool frame's axes; the tool axis is local +Z
  lp.axis_z = R == Eigen::Matrix3d::Identity();
  lp.d_local = lp.to_local * (base1 - base0);
  lp.env = env;
  const Vec3& d = lp.d_local;
  const double len = d.norm();
  const double h = hypot2(d.x(), d.y());
  if (h <= 1e-12 * std::max(len, 1.0)) lp.kind = LinearPrim::Case::vertical;
  else if (std::fabs(d.z()) <= 1e-12 * len) lp.kind = LinearPrim::Case::horizontal;
  else if (env.disk_radius == 0) lp.kind = LinearPrim::Case::parallelogram;
  else lp.kind = LinearPrim::Case::general;
  // The ball core's reciprocals (detail::parallelogram_offset).
  const double L = env.core_length, r2 = d.x() * d.x() + d.y() * d.y();
  auto inv = [](double x) { return x > 0 ? 1 / x : 0.0; };
  if (L * L * r2 >= 1e-30) {
    lp.inv_r2 = 1 / r2;
    lp.inv_lr2 = 1 / (L * r2);
  }
  lp.inv_dd = inv(d.squaredNorm());
  lp.inv_ll = inv(L * L);
  const double span = std::max(0.0, d.z()) + L - std::min(0.0, d.z());
  lp.inv_span = inv(span * span);
  const Vec3 w = R.col(2);
  lp.bounds = envelope_box(base0, w, env);
  lp.bounds.extend(envelope_box(base1, w, env));
  return lp;
}

double profile_distance(const ProfilePrim& pp, const Vec3& x) {
  if (pp.prism) return detail::prism_distance(pp, x);
  const Vec3 p = pp.to_local * (x - pp.origin);
  const Vec3& d = pp.d_local;
  const tool::EdgeProfile& e = pp.edge;
  // Motion within the rake plane: a sheet of no thickness.
  const double a = golden_min([&](double s) {
    const double y = p.y() - s * d.y(), z = p.z() - s * d.z();
    return std::max(std::max(tool::profile_distance_2d(e, y, z), z - e.height), 0.0);
  });
  return hypot2(p.x(), a);
}

Eigen::Matrix3d turn_z(double c, double s) {
  Eigen::Matrix3d Rz;
  Rz << c, -s, 0, s, c, 0, 0, 0, 1;
  return Rz;
}

ProfilePrim make_profile(const Vec3& tip0, const Vec3& tip1, const tool::EdgeProfile& edge, const Eigen::Matrix3d& R) {
  ProfilePrim pp;
  pp.origin = tip0;
  const Eigen::Matrix3d Rl = R * turn_z(edge.cos_o, edge.sin_o);
  pp.to_local = Rl.transpose();
  pp.d_local = pp.to_local * (tip1 - tip0);
  pp.edge = edge;
  pp.edge.cos_o = 1;
  pp.edge.sin_o = 0;
  pp.prism = std::fabs(pp.d_local.x()) > 1e-9 * std::max(pp.d_local.norm(), 1e-12);
  pp.sin_half = std::sin(edge.half_angle);
  pp.cos_half = std::cos(edge.half_angle);
  const Vec3& d = pp.d_local;
  const double ax = std::fabs(d.x());
  pp.f_side[0] = detail::prism_factor(ax, pp.cos_half * d.y() + -pp.sin_half * d.z());
  pp.f_side[1] = detail::prism_factor(ax, -pp.cos_half * d.y() + -pp.sin_half * d.z());
  pp.f_top = detail::prism_factor(ax, d.z());
  if (pp.prism) pp.inv_dx = 1 / d.x();
  const Aabb local = tool::shape_bounds(pp.edge);
  pp.bounds = world_box(local, Rl, tip0);
  pp.bounds.extend(world_box(local, Rl, tip1));
  return pp;
}

TorusPrim make_torus(const Pose& pose, const tool::SwingTorus& t) {
  TorusPrim tp;
  tp.origin = pose.translation();
  tp.to_local = pose.linear().transpose();
  tp.torus = t;
  tp.bounds = world_box(tool::shape_bounds(tool::Shape(t)), pose.linear(), tp.origin);
  return tp;
}

// The ball end's core at two poses, hulled and grown by the ball.
HullPrim make_hull(const Pose& p0, const Pose& p1, const tool::RevolvedEnvelope& env) {
  const Vec3 a0 = p0.linear().col(2), a1 = p1.linear().col(2);
  const Vec3 c0 = p0.translation() + env.core_offset * a0, c1 = p1.translation() + env.core_offset * a1;
  return hull_prim(c0, c0 + env.core_length * a0, c1, c1 + env.core_length * a1, env.corner_radius);
}

// The least height of the tetrahedron of four points: 0 when they are flat.
double hull_thickness(const std::array<Vec3, 4>& q) {
  const double vol6 = std::fabs((q[1] - q[0]).cross(q[2] - q[0]).dot(q[3] - q[0]));
  double area2 = 0;  // the largest face, twice its area
  static constexpr int kFace[4][3] = {{0, 1, 2}, {0, 1, 3}, {0, 2, 3}, {1, 2, 3}};
  for (const auto& f : kFace) area2 = std::max(area2, (q[f[1]] - q[f[0]]).cross(q[f[2]] - q[f[0]]).norm());
  return area2 > 0 ? vol6 / area2 : 0.0;
}

// Appends the straight sweep of `shape` from tip0 to tip1 at orientation R.
void append_line(Sweep& s, const Vec3& tip0, const Vec3& tip1, const Eigen::Matrix3d& R, const tool::Shape& shape) {
  if (const auto* env = std::get_if<tool::RevolvedEnvelope>(&shape)) {
    const Vec3 lift = env->core_offset * R.col(2);
    s.prims.emplace_back(make_linear(tip0 + lift, tip1 + lift, *env, R));
  } else if (const auto* edge = std::get_if<tool::EdgeProfile>(&shape)) {
    s.prims.emplace_back(make_profile(tip0, tip1, *edge, R));
  } else if (const auto* torus = std::get_if<tool::SwingTorus>(&shape)) {
    // Steps whose scallop (swing - sqrt(swing^2 - step^2/4)) stays below 0.1 um.
    const double step = std::sqrt(8 * torus->swing * 1e-4);
    const int n = std::max(1, static_cast<int>(std::ceil((tip1 - tip0).norm() / step)));
    for (int i = 0; i <= n; ++i) {
      Pose p = Pose::Identity();
      p.linear() = R;
      p.translation() = tip0 + (tip1 - tip0) * (static_cast<double>(i) / n);
      s.prims.emplace_back(make_torus(p, *torus));
    }
  } else {
    throw std::logic_error("a flank body is not a cutting shape");
  }
}

}  // namespace

// p less its nearest point on the hull (a tetrahedron, possibly flat):
// zero inside. The nearest point of a convex solid lies on a face whose
// plane has the point outside: only those are measured (a flat hull's
// faces always); none measured means inside.
Vec3 detail::hull_offset(const Vec3& p, const HullPrim& h) {
  Vec3 best = Vec3::Zero();
  double best2 = std::numeric_limits<double>::infinity();
  for (int k = 0; k < 4; ++k) {
    const Vec3& n = h.normal[k];
    const double side = n.dot(p) - h.offset[k];  // > 0 outside; 0 for a flat face
    if (side < 0 || (side == 0 && n != Vec3::Zero())) continue;
    const auto& f = kHullFace[k];
    const Vec3 v = triangle_offset(p, h.p[f[0]], h.p[f[1]], h.p[f[2]]);
    if (v.squaredNorm() < best2) {
      best = v;
      best2 = v.squaredNorm();
    }
  }
  return best;
}

HullPrim hull_prim(const Vec3& p0, const Vec3& p1, const Vec3& p2, const Vec3& p3, double radius) {
  HullPrim hp;
  hp.p[0] = p0;
  hp.p[1] = p1;
  hp.p[2] = p2;
  hp.p[3] = p3;
  hp.radius = radius;
  for (int k = 0; k < 4; ++k) {
    const auto& f = kHullFace[k];
    const Vec3 &a = hp.p[f[0]], &b = hp.p[f[1]], &c = hp.p[f[2]];
    Vec3 n = (b - a).cross(c - a);
    const double apex = n.dot(hp.p[k] - a);
    if (apex > 0) n = -n;
    // The fourth point within 1e-9 mm of the face's plane: the side is
    // rounding noise (a piece that does not turn), so the face counts as
    // flat and is always measured. A wrong side would call points beside
    // the piece inside it.
    if (!(std::fabs(apex) > 1e-9 * n.norm())) n = Vec3::Zero();
    hp.normal[k] = n;
    hp.offset[k] = n.dot(a);
  }
  Aabb b;
  for (const Vec3& q : hp.p) b.extend(q);
  hp.bounds = b.expanded(radius);
  return hp;
}

double distance(const Primitive& p, const Vec3& x) {
  return std::visit([&](const auto& q) -> double {
    using T = std::decay_t<decltype(q)>;
    if constexpr (std::is_same_v<T, LinearPrim>) return linear_distance(q, x);
    else if constexpr (std::is_same_v<T, ArcPrim>) return arc_distance(q, x);
    else if constexpr (std::is_same_v<T, ProfilePrim>) return profile_distance(q, x);
    else if constexpr (std::is_same_v<T, HullPrim>) return detail::hull_offset(x, q).norm() - q.radius;
    else if constexpr (std::is_same_v<T, JointPrim>) return detail::joint_distance(q, x);
    else return torus_distance(q, x);
  }, p);
}

double distance_below(const Primitive& p, const Vec3& x, double lim) {
  if (const auto* jp = std::get_if<JointPrim>(&p)) return detail::joint_distance_below(*jp, x, lim);
  return distance(p, x);
}

const Aabb& bounds(const Primitive& p) {
  return std::visit([](const auto& q) -> const Aabb& { return q.bounds; }, p);
}

namespace {
// A pointed edge (a V tool) moved in the plane of its cutting direction and
// its axis (planing, lifting and lowering).
bool planing(const ProfilePrim& p) {
  const Vec3& d = p.d_local;
  return p.edge.nose_radius == 0 && p.prism && std::fabs(d.y()) <= 1e-12 * d.norm();
}
}  // namespace

bool lipschitz(const Primitive& p) {
  if (const auto* lp = std::get_if<LinearPrim>(&p)) return lp->kind != LinearPrim::Case::general;
  if (const auto* pp = std::get_if<ProfilePrim>(&p)) {
    // A pointed edge (a V tool) moved in the plane of its cutting direction
    // and its axis: the sides stay planes leaning alike, and the distance
    // is the largest of their plane distances inside. A sideways component
    // leans the two sides differently (a jump inside, on the bisector); a
    // round nose leans its tangent planes differently too.
    return planing(*pp);
  }
  // The largest of 1-Lipschitz distances (the prisms', a slab's, a box's).
  if (const auto* jp = std::get_if<JointPrim>(&p)) return jp->lipschitz;
  return true;
}

bool joinable(const ProfilePrim& a, const ProfilePrim& b) {
  if (!a.prism || !b.prism) return false;
  if (a.to_local != b.to_local || a.edge.nose_radius != b.edge.nose_radius ||
      a.edge.half_angle != b.edge.half_angle || a.edge.height != b.edge.height)
    return false;
  if ((a.d_local.x() > 0) != (b.d_local.x() > 0)) return false;
  return (a.origin + a.to_local.transpose() * a.d_local - b.origin).norm() <= 1e-9;
}

namespace {
// A JointPrim's frame, edge and factors, from `mid` (the others joinable
// with it), its slab and box left to the caller.
JointPrim joint_base(const ProfilePrim* before, const ProfilePrim& mid, const ProfilePrim* after) {
  JointPrim jp;
  jp.to_local = mid.to_local;
  auto side = [](const ProfilePrim& p) {
    JointPrim::Side s;
    s.origin = p.origin;
    s.d = p.d_local;
    s.inv_dx = p.inv_dx;
    s.f_side[0] = p.f_side[0];
    s.f_side[1] = p.f_side[1];
    s.f_top = p.f_top;
    return s;
  };
  jp.mid = side(mid);
  jp.has_before = before != nullptr;
  jp.has_after = after != nullptr;
  if (before) jp.before = side(*before);
  if (after) jp.after = side(*after);
  jp.edge = mid.edge;
  jp.sin_half = mid.sin_half;
  jp.cos_half = mid.cos_half;
  jp.sign = mid.d_local.x() > 0 ? 1.0 : -1.0;
  jp.lipschitz = lipschitz(Primitive(mid)) && (!before || lipschitz(Primitive(*before))) &&
                 (!after || lipschitz(Primitive(*after)));
  return jp;
}

// The box of the profile's cross-sections with their tips at `tips` (each
// prism's part moves linearly, so those at its part's ends hold the rest),
// of the part of the profile that reaches into `reach`; empty where none.
Aabb sections_box(const JointPrim& jp, std::initializer_list<Vec3> tips, const Aabb& reach) {
  const Eigen::Matrix3d Rl = jp.to_local.transpose();
  const tool::Shape shape(jp.edge);
  Aabb box;
  for (const Vec3& t : tips)
    box.extend(reach.empty() ? world_box(tool::shape_bounds(shape), Rl, t) : world_box_within(shape, Rl, t, reach));
  return reach.empty() ? box : box.intersected(reach);
}
}  // namespace

std::optional<JointPrim> joint_prim(const ProfilePrim* before, const ProfilePrim& mid, const ProfilePrim* after,
                                    double half_width, const Aabb& reach) {
  if ((!before && !after) || !(half_width > 0)) return std::nullopt;
  JointPrim jp = joint_base(before, mid, after);
  jp.slab_lo = -half_width;
  jp.slab_hi = std::fabs(mid.d_local.x()) + half_width;
  const Eigen::Matrix3d Rl = mid.to_local.transpose();
  const Vec3 end = mid.origin + Rl * mid.d_local;
  const Vec3 start_before =
      before ? Vec3(mid.origin - std::min(1.0, half_width / std::fabs(before->d_local.x())) * (Rl * before->d_local)) : mid.origin;
  const Vec3 end_after =
      after ? Vec3(end + std::min(1.0, half_width / std::fabs(after->d_local.x())) * (Rl * after->d_local)) : end;
  jp.bounds = sections_box(jp, {mid.origin, end, start_before, end_after}, reach);
  if (jp.bounds.empty()) return std::nullopt;
  return jp;
}

std::optional<JointPrim> crest_prim(const ProfilePrim& mid, const ProfilePrim& after, double half_width,
                                    const Aabb& reach) {
  if (!(half_width > 0)) return std::nullopt;
  JointPrim jp = joint_base(nullptr, mid, &after);
  jp.crest = true;
  const double lm = std::fabs(mid.d_local.x()), la = std::fabs(after.d_local.x());
  const double back = std::min(2 * half_width, lm), on = std::min(2 * half_width, la);
  jp.slab_lo = lm - back;
  jp.slab_hi = lm + on;
  // The sections at the slab's faces on both lines drawn on, and at the joint.
  const Eigen::Matrix3d Rl = mid.to_local.transpose();
  const Vec3 joint = mid.origin + Rl * mid.d_local;
  const Vec3 dm = Rl * mid.d_local / lm, da = Rl * after.d_local / la;  // per unit along the cut
  jp.bounds = sections_box(jp, {joint - back * dm, joint + on * dm, joint - back * da, joint + on * da}, reach);
  if (jp.bounds.empty()) return std::nullopt;
  return jp;
}

namespace {
// `p` drawn back along its own line by `length` (along the cut, its local
// x), its box grown to match.
ProfilePrim extended_back(const ProfilePrim& p, double length) {
  const Eigen::Matrix3d Rl = p.to_local.transpose();
  const Vec3 tip1 = p.origin + Rl * p.d_local;
  const double f = length / std::fabs(p.d_local.x());
  return make_profile(p.origin - f * (Rl * p.d_local), tip1, p.edge, Rl);  // (p.edge's turn is in Rl)
}

// A prism's slope along the cut: its rise per unit of local x.
double slope(const ProfilePrim& p) { return p.d_local.z() / std::fabs(p.d_local.x()); }

// `b` after `a` turns over a crest: both V tools planing (a V's section
// lifted along its axis lies inside itself), the slope not rising.
bool crest(const ProfilePrim& a, const ProfilePrim& b) { return planing(a) && planing(b) && slope(b) <= slope(a); }
}  // namespace

std::optional<ProfilePrim> Joiner::drawn_back(const ProfilePrim& next) const {
  const double length = 2 * half_width_;
  // A crest, run for the whole length behind the joint, whose slope falls
  // by no more than 0.01 within half_width of it (from last_'s slope, or
  // the run's first where last_ is shorter): there the drawn-back line runs
  // at most 1 % of half_width above the path, and the voxels that take
  // their depth from it read no more than that shallow.
  if (!last_ || reach_.empty() || !(half_width_ > 0) || !crest(*last_, next) || run_ < length) return std::nullopt;
  const double behind = std::fabs(last_->d_local.x()) >= half_width_ ? slope(*last_) : run_slope_;
  if (behind - slope(next) > 0.01) return std::nullopt;
  ProfilePrim drawn = extended_back(next, length);
  // Behind the joint the line runs at most `lift` above the path: the
  // drawn-back V stands out of the cut only by its top's strip that high,
  // which must lie outside the material's reach.
  const double lift = length * (run_slope_ - slope(next));
  if (lift <= 1e-12) return drawn;
  Aabb strip = tool::shape_bounds(tool::Shape(next.edge));
  strip.min.z() = strip.max.z() - lift;
  const Eigen::Matrix3d Rl = next.to_local.transpose();
  Aabb box = world_box(strip, Rl, drawn.origin);
  box.extend(world_box(strip, Rl, next.origin));
  if (box.overlaps(reach_.expanded(lift))) return std::nullopt;
  return drawn;
}

void Joiner::emit(Sweep& s, const ProfilePrim* after) {
  if (!last_) return;
  if (auto j = joint_prim(before_ ? &*before_ : nullptr, *last_, after, half_width_, reach_)) {
    s.bounds.extend(j->bounds);
    s.prims.emplace_back(*j);
    ++joints_;
  }
}

void Joiner::operator()(Sweep& s) {
  ProfilePrim* first = s.prims.empty() ? nullptr : std::get_if<ProfilePrim>(&s.prims.front());
  const ProfilePrim* last = s.prims.empty() ? nullptr : std::get_if<ProfilePrim>(&s.prims.back());
  const bool joins = last_ && first && joinable(*last_, *first);
  const bool single = s.prims.size() == 1;
  std::optional<ProfilePrim> drawn = joins && single ? drawn_back(*first) : std::nullopt;
  const bool extend = drawn.has_value();
  // The crest run ending at this sweep's last prism (as it was given).
  if (extend || (joins && single && crest(*last_, *first))) {
    run_ += std::fabs(first->d_local.x());
  } else if (last && single) {
    run_ = std::fabs(last->d_local.x());
    run_slope_ = slope(*last);
  } else {
    run_ = 0;
  }
  // (s's own prisms are copied first: emit appends to s.prims.)
  std::optional<ProfilePrim> next_before, next_last;
  if (last) next_last = *last;
  // A crest not drawn back over: its own piece, and neither prism's
  // JointPrim reaches across it.
  std::optional<JointPrim> over_crest;
  const bool crest_piece = joins && !extend && crest(*last_, *first);
  if (crest_piece) over_crest = crest_prim(*last_, *first, half_width_, reach_);
  if (joins && !extend && !crest_piece && single) next_before = *last_;
  if (extend) {
    *first = std::move(*drawn);
    s.bounds.extend(first->bounds);
    next_last = *first;
    ++extended_;
  }
  // last_'s JointPrim: at its start unless it was drawn back there (then
  // before_ is empty), at its end unless `first` is drawn back over it or
  // the joint is a crest. (Last: appending to s.prims may move `first`.)
  emit(s, joins && !extend && !crest_piece ? first : nullptr);
  if (over_crest) {
    s.bounds.extend(over_crest->bounds);
    s.prims.emplace_back(*over_crest);
    ++crests_;
  }
  before_ = std::move(next_before);
  last_ = std::move(next_last);
}

Sweep Joiner::finish() {
  Sweep s;
  emit(s, nullptr);
  before_.reset();
  last_.reset();
  run_ = 0;
  return s;
}

Aabb world_box(const Aabb& local, const Eigen::Matrix3d& R, const Vec3& tip) {
  Aabb b;
  for (int i = 0; i < 8; ++i) {
    const Vec3 c((i & 1) ? local.max.x() : local.min.x(), (i & 2) ? local.max.y() : local.min.y(),
                 (i & 4) ? local.max.z() : local.min.z());
    b.extend(tip + R * c);
  }
  return b;
}

double Sweep::distance(const Vec3& x) const {
  double d = std::numeric_limits<double>::infinity();
  for (const Primitive& p : prims) {
    // A piece's box is no farther than the piece: skip pieces whose box is
    // already beyond the nearest distance found.
    const Aabb& b = sweep::bounds(p);
    const double out = (b.min - x).cwiseMax(x - b.max).cwiseMax(0.0).norm();
    if (out > 0 && out >= d) continue;
    d = std::min(d, sweep::distance(p, x));
  }
  return d;
}

Sweep sweep_move(const motion::Move& m, const tool::Tool& tool, const SweepOptions& opt) {
  const tool::RevolvedEnvelope env = tool::cutting_envelope(tool);
  const Vec3 lift(0, 0, env.core_offset);
  Sweep s;
  if (!m.is_arc()) {
    s.prims.emplace_back(make_linear(m.start.xyz + lift, m.end.xyz + lift, env));
  } else {
    const double r0 = m.arc_start_radius(), r1 = m.arc_end_radius();
    const bool planar = std::fabs(m.end.xyz.z() - m.start.xyz.z()) <= 1e-12;
    const bool about_z = std::fabs(std::fabs(m.normal.z()) - 1.0) <= 1e-12;
    if (about_z && planar && std::fabs(r1 - r0) <= 1e-9 * std::max(1.0, r0)) {
      ArcPrim ap;
      ap.centre = Vec3(m.centre.x(), m.centre.y(), m.start.xyz.z() + env.core_offset);
      ap.radius = r0;
      ap.start_angle = std::atan2(m.start.xyz.y() - m.centre.y(), m.start.xyz.x() - m.centre.x());
      ap.sweep_angle = m.normal.z() > 0 ? m.arc_sweep_angle() : -m.arc_sweep_angle();
      ap.env = env;
      // Bounds: the path's box grown by the envelope.
      Aabb pb = m.path_bounds();
      ap.bounds = envelope_box_z(pb.min + lift, env);
      ap.bounds.extend(envelope_box_z(pb.max + lift, env));
      s.prims.emplace_back(ap);
    } else {
      // Chords: sagitta r (1 - cos(a/2)) <= tolerance.
      const double r = std::max(r0, r1);
      const double tol = std::min(opt.chord_tolerance_mm, r);
      const double max_step = 2 * std::acos(1 - tol / r);
      const int n = std::max(1, static_cast<int>(std::ceil(std::fabs(m.arc_sweep_angle()) / max_step)));
      Vec3 prev = m.start.xyz;
      for (int i = 1; i <= n; ++i) {
        const Vec3 next = (i == n) ? m.end.xyz : m.point_at(static_cast<double>(i) / n);
        s.prims.emplace_back(make_linear(prev + lift, next + lift, env));
        prev = next;
      }
    }
  }
  for (const Primitive& p : s.prims) s.bounds.extend(bounds(p));
  return s;
}

Sweep sweep_line(const Vec3& tip0, const Vec3& tip1, const Eigen::Matrix3d& R, const tool::Shape& shape) {
  Sweep s;
  append_line(s, tip0, tip1, R, shape);
  for (const Primitive& p : s.prims) s.bounds.extend(bounds(p));
  return s;
}

namespace {
// The highest point of `reach` along the tool axis w, above `tip`.
double top_within(const Vec3& w, const Vec3& tip, const Aabb& reach) {
  double top = 0;
  for (int k = 0; k < 3; ++k) top += std::max(w[k] * (reach.min[k] - tip[k]), w[k] * (reach.max[k] - tip[k]));
  return top;
}
}  // namespace

Aabb world_box_within(const tool::Shape& shape, const Eigen::Matrix3d& R, const Vec3& tip, const Aabb& reach) {
  return world_box(tool::shape_bounds_below(shape, top_within(R.col(2), tip, reach)), R, tip);
}

void clip_bounds(Sweep& s, const Aabb& reach) {
  if (reach.empty()) return;
  Aabb all;
  for (Primitive& p : s.prims) {
    Aabb& b = std::visit([](auto& q) -> Aabb& { return q.bounds; }, p);
    if (auto* pp = std::get_if<ProfilePrim>(&p)) {
      // One box for both ends, of the part below the higher of their tops:
      // the cross-sections between them are that box moved along the move.
      const Eigen::Matrix3d Rl = pp->to_local.transpose();
      const Vec3 tip1 = pp->origin + Rl * pp->d_local;
      const double top = std::max(top_within(Rl.col(2), pp->origin, reach), top_within(Rl.col(2), tip1, reach));
      const Aabb local = tool::shape_bounds_below(tool::Shape(pp->edge), top);
      b = world_box(local, Rl, pp->origin);
      b.extend(world_box(local, Rl, tip1));
    } else if (auto* tp = std::get_if<TorusPrim>(&p)) {
      // A fly-cutter's revolution: only the tip's few micrometres reach in.
      const Eigen::Matrix3d Rl = tp->to_local.transpose();
      b = world_box(tool::shape_bounds_below(tool::Shape(tp->torus), top_within(Rl.col(2), tp->origin, reach)), Rl,
                    tp->origin);
    }
    b = b.intersected(reach);
    if (!b.empty()) all.extend(b.min), all.extend(b.max);
  }
  s.bounds = all.empty() ? s.bounds.intersected(reach) : all;
}

Sweep sweep_line(const Vec3& tip0, const Vec3& tip1, const Eigen::Matrix3d& R, const tool::Tool& tool) {
  return sweep_line(tip0, tip1, R, tool::cutting_shape(tool));
}

Sweep sweep_poses(const std::function<Pose(double)>& pose_at, const tool::Shape& shape, double tolerance_mm,
                  int min_pieces, const Aabb* region) {
  // Tip to the top of an envelope; to the farthest corner of other shapes.
  double reach = 0, radial = -1;
  if (const auto* env = std::get_if<tool::RevolvedEnvelope>(&shape)) {
    reach = env->core_offset + env->core_length + env->corner_radius;
    radial = env->disk_radius + env->corner_radius;
  } else {
    const Aabb lb = tool::shape_bounds(shape);
    for (int i = 0; i < 8; ++i)
      reach = std::max(reach, Vec3((i & 1) ? lb.max.x() : lb.min.x(), (i & 2) ? lb.max.y() : lb.min.y(),
                                   (i & 4) ? lb.max.z() : lb.min.z()).norm());
  }
  // An envelope's points beyond a face of `region` cannot cut: only the
  // length of the tool inside it counts for the error of a held
  // orientation (a long flute mostly above the stock turns freely).
  // Its cross-section at axial distance r spans r (a . n) +- radial
  // sqrt(1 - (a . n)^2) along a face's normal n.
  const bool capped = region && !region->empty() && radial >= 0;
  auto axial_inside = [&](const Pose& q) {
    const Vec3 tip = q.translation(), a = q.linear().col(2);
    double r = reach;
    for (int i = 0; i < 3; ++i)
      for (const double sign : {1.0, -1.0}) {
        const double an = sign * a[i];
        if (an <= 1e-9) continue;
        const double face = sign > 0 ? region->max[i] : -region->min[i];
        r = std::min(r, (face - sign * tip[i] + radial * std::sqrt(std::max(0.0, 1 - an * an))) / an);
      }
    return std::max(r, 0.0);
  };
  // The reach that counts over a piece: the farthest tool point inside the
  // region at its ends and middle, plus the tip's travel between them.
  auto piece_reach = [&](const Pose& p0, const Pose& p1, const Pose& pm) {
    if (!capped) return reach;
    const double r = std::max({axial_inside(p0), axial_inside(p1), axial_inside(pm)}) +
                     (p1.translation() - p0.translation()).norm();
    return std::min(reach, std::hypot(r, radial));
  };
  // A ball end (no flat disk) turns as hull pieces: then only the paths'
  // departure from the chords and the hull's thickness (the turn out of
  // the motion's plane) count, not the turn itself.
  const auto* ball = std::get_if<tool::RevolvedEnvelope>(&shape);
  if (ball && !(ball->disk_radius == 0 && ball->corner_radius > 0)) ball = nullptr;
  Sweep s;
  struct Node { double t0, t1; Pose p0, p1; int depth; };
  std::vector<Node> stack;
  const int n0 = std::max(1, min_pieces);
  std::vector<Pose> poses(static_cast<std::size_t>(n0) + 1);
  for (int i = 0; i <= n0; ++i) poses[static_cast<std::size_t>(i)] = pose_at(static_cast<double>(i) / n0);
  for (int i = n0 - 1; i >= 0; --i)
    stack.push_back({static_cast<double>(i) / n0, static_cast<double>(i + 1) / n0, poses[static_cast<std::size_t>(i)],
                     poses[static_cast<std::size_t>(i) + 1], 0});
  while (!stack.empty()) {
    Node nd = stack.back();
    stack.pop_back();
    const double tm = 0.5 * (nd.t0 + nd.t1);
    const Pose pm = pose_at(tm);
    const Vec3 a0 = nd.p0.linear().col(2), a1 = nd.p1.linear().col(2), am = pm.linear().col(2);
    const double top = piece_reach(nd.p0, nd.p1, pm);  // the reach that counts over this piece
    const Vec3 tip_mid = 0.5 * (nd.p0.translation() + nd.p1.translation());
    const Vec3 top_mid = 0.5 * (nd.p0.translation() + top * a0 + nd.p1.translation() + top * a1);
    const double dev = std::max((pm.translation() - tip_mid).norm(), (pm.translation() + top * am - top_mid).norm());
    bool split = dev > tolerance_mm;
    if (!split && ball) {
      // The hull holds the core's bilinear sweep between the two ends and
      // departs from it by at most its thickness (over the length that counts).
      const double len = std::clamp(top - ball->core_offset, 0.0, ball->core_length);
      const Vec3 c0 = nd.p0.translation() + ball->core_offset * a0, c1 = nd.p1.translation() + ball->core_offset * a1;
      split = hull_thickness({c0, c0 + len * a0, c1, c1 + len * a1}) > tolerance_mm;
    } else if (!split) {
      // Holding the middle orientation over the piece moves the top by at
      // most top * (half the turn).
      split = top * 0.5 * std::acos(std::clamp(a0.dot(a1), -1.0, 1.0)) > tolerance_mm;
    }
    if (split && nd.depth < 30) {
      stack.push_back({tm, nd.t1, pm, nd.p1, nd.depth + 1});
      stack.push_back({nd.t0, tm, nd.p0, pm, nd.depth + 1});
      continue;
    }
    if (ball)
      s.prims.emplace_back(make_hull(nd.p0, nd.p1, *ball));
    else
      append_line(s, nd.p0.translation(), nd.p1.translation(), pm.linear(), shape);
  }
  for (const Primitive& p : s.prims) s.bounds.extend(bounds(p));
  return s;
}

Sweep sweep_tori(const std::vector<Pose>& poses, const tool::SwingTorus& torus) {
  Sweep s;
  for (const Pose& p : poses) s.prims.emplace_back(make_torus(p, torus));
  for (const Primitive& p : s.prims) s.bounds.extend(bounds(p));
  return s;
}

Sweep tool_at(const Vec3& tip, const tool::Tool& tool) {
  const tool::RevolvedEnvelope env = tool::cutting_envelope(tool);
  const Vec3 base = tip + Vec3(0, 0, env.core_offset);
  Sweep s;
  s.prims.emplace_back(make_linear(base, base, env));
  s.bounds = bounds(s.prims.front());
  return s;
}

}  // namespace cutsim::sweep
