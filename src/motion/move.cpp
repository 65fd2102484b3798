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
// In-plane axes (u, v) for the plane normal to axis `n`, right-handed:
// G17 (n=2): X,Y; G18 (n=1): Z,X; G19 (n=0): Y,Z.
void plane_axes(int n, int& u, int& v) {
  u = (n + 1) % 3;
  v = (n + 2) % 3;
}
}  // namespace

double Move::arc_start_radius() const {
  int u, v;
  plane_axes(plane_axis, u, v);
  return std::hypot(start.xyz[u] - centre[u], start.xyz[v] - centre[v]);
}

double Move::arc_end_radius() const {
  int u, v;
  plane_axes(plane_axis, u, v);
  return std::hypot(end.xyz[u] - centre[u], end.xyz[v] - centre[v]);
}

double Move::arc_sweep_angle() const {
  int u, v;
  plane_axes(plane_axis, u, v);
  const double a0 = std::atan2(start.xyz[v] - centre[v], start.xyz[u] - centre[u]);
  const double a1 = std::atan2(end.xyz[v] - centre[v], end.xyz[u] - centre[u]);
  double d = a1 - a0;
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
  int u, v;
  plane_axes(plane_axis, u, v);
  const double a0 = std::atan2(start.xyz[v] - centre[v], start.xyz[u] - centre[u]);
  const double a = a0 + t * arc_sweep_angle();
  const double r = arc_start_radius() + t * (arc_end_radius() - arc_start_radius());
  Vec3 p;
  p[u] = centre[u] + r * std::cos(a);
  p[v] = centre[v] + r * std::sin(a);
  p[plane_axis] = start.xyz[plane_axis] + t * (end.xyz[plane_axis] - start.xyz[plane_axis]);
  if (t >= 1.0) return end.xyz;  // exact end point
  return p;
}

Aabb Move::path_bounds() const {
  Aabb b;
  b.extend(start.xyz);
  b.extend(end.xyz);
  if (!is_arc()) return b;
  int u, v;
  plane_axes(plane_axis, u, v);
  const double r = std::max(arc_start_radius(), arc_end_radius());
  // Conservative: the full circle's box in the plane, clipped by nothing.
  // Tight enough for region-of-interest use, cheap, and never too small.
  const double a0 = std::atan2(start.xyz[v] - centre[v], start.xyz[u] - centre[u]);
  const double sweep = arc_sweep_angle();
  // Add the axis-extreme points that the arc passes.
  for (int q = -8; q <= 8; ++q) {
    const double a = q * kPi / 2;
    const double t = (a - a0) / sweep;
    if (t > 0 && t < 1) {
      Vec3 p = point_at(t);
      b.extend(p);
    }
  }
  (void)r;
  return b;
}

}  // namespace cutsim::motion
