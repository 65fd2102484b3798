#include "cutsim/motion/move.h"

#include <cmath>

namespace cutsim::motion {

const char* motion_name(MotionKind k) {
  switch (k) {
    case MotionKind::rapid: return "G0";
    case MotionKind::linear: return "G1";
    case MotionKind::arc_cw: return "G2";
    case MotionKind::arc_ccw: return "G3";
  }
  return "?";
}

namespace {
// In-plane basis (u, v) with u towards the start point and v = n x u.
struct PlaneFrame {
  Vec3 u, v, n;
};
PlaneFrame frame_of(const Move& m) {
  PlaneFrame f;
  f.n = m.normal;
  Vec3 r = m.start.xyz - m.centre;
  r -= r.dot(f.n) * f.n;
  const double len = r.norm();
  if (len > 0) f.u = r / len;
  else f.u = f.n.unitOrthogonal();
  f.v = f.n.cross(f.u);
  return f;
}
double in_plane_radius(const Move& m, const Vec3& p) {
  Vec3 r = p - m.centre;
  r -= r.dot(m.normal) * m.normal;
  return r.norm();
}
}  // namespace

double Move::arc_start_radius() const { return in_plane_radius(*this, start.xyz); }
double Move::arc_end_radius() const { return in_plane_radius(*this, end.xyz); }

double Move::arc_sweep_angle() const {
  const PlaneFrame f = frame_of(*this);
  const Vec3 r1 = end.xyz - centre;
  double d = std::atan2(r1.dot(f.v), r1.dot(f.u));  // end angle, start at 0
  const double two_pi = 2 * kPi;
  if (kind == MotionKind::arc_ccw) {
    while (d <= 1e-12) d += two_pi;
    while (d > two_pi + 1e-12) d -= two_pi;
  } else {
    while (d >= -1e-12) d -= two_pi;
    while (d < -two_pi - 1e-12) d += two_pi;
  }
  const double extra = (turns > 1 ? turns - 1 : 0) * two_pi;
  return kind == MotionKind::arc_ccw ? d + extra : d - extra;
}

Vec3 Move::point_at(double t) const {
  if (!is_arc()) return start.xyz + t * (end.xyz - start.xyz);
  if (t >= 1.0) return end.xyz;  // exact end point
  const PlaneFrame f = frame_of(*this);
  const double a = t * arc_sweep_angle();
  const double r = arc_start_radius() + t * (arc_end_radius() - arc_start_radius());
  const double axial0 = (start.xyz - centre).dot(f.n), axial1 = (end.xyz - centre).dot(f.n);
  return centre + r * (std::cos(a) * f.u + std::sin(a) * f.v) + (axial0 + t * (axial1 - axial0)) * f.n;
}

Aabb Move::path_bounds() const {
  Aabb b;
  b.extend(start.xyz);
  b.extend(end.xyz);
  if (!is_arc()) return b;
  // Extremes of a circle in each coordinate: where the tangent is normal to
  // that axis. Sample densely enough and pad by the sampling sagitta.
  const double sweep = std::fabs(arc_sweep_angle());
  const int n = std::max(8, static_cast<int>(std::ceil(sweep / (kPi / 64))));
  for (int i = 1; i < n; ++i) b.extend(point_at(static_cast<double>(i) / n));
  const double r = std::max(arc_start_radius(), arc_end_radius());
  return b.expanded(r * (1 - std::cos(sweep / n / 2)));
}

double Move::length() const {
  if (!is_arc()) return (end.xyz - start.xyz).norm();
  const double r = 0.5 * (arc_start_radius() + arc_end_radius());
  const double axial = (end.xyz - start.xyz).dot(normal);
  return std::hypot(r * arc_sweep_angle(), axial);
}

}  // namespace cutsim::motion
