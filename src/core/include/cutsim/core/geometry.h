#pragma once
// Shared geometric vocabulary: positions in mm as doubles, angles in radians.
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <limits>

namespace cutsim {

using Vec3 = Eigen::Vector3d;
using Pose = Eigen::Isometry3d;

constexpr double kPi = 3.14159265358979323846;
/// The finest voxel the stock grid takes, mm: OpenVDB's transform refuses a
/// voxel whose volume (in the grid's unit, mm) is below 3e-15 (h < 0.0144 um).
constexpr double kFinestVoxelMm = 1.5e-5;
inline double deg_to_rad(double deg) { return deg * kPi / 180.0; }
inline double rad_to_deg(double rad) { return rad * 180.0 / kPi; }
/// sqrt(a^2 + b^2) for mm-sized values: std::hypot guards against overflow
/// and costs half the stock update in profiles; nothing here comes near it.
inline double hypot2(double a, double b) { return std::sqrt(a * a + b * b); }

/// Axis-aligned box in mm. Empty when min > max in any axis.
struct Aabb {
  Vec3 min = Vec3::Constant(std::numeric_limits<double>::infinity());
  Vec3 max = Vec3::Constant(-std::numeric_limits<double>::infinity());

  static Aabb from_min_max(const Vec3& lo, const Vec3& hi) { return Aabb{lo, hi}; }
  bool empty() const { return (min.array() > max.array()).any(); }
  void extend(const Vec3& p) {
    min = min.cwiseMin(p);
    max = max.cwiseMax(p);
  }
  void extend(const Aabb& b) {
    if (b.empty()) return;
    min = min.cwiseMin(b.min);
    max = max.cwiseMax(b.max);
  }
  Aabb expanded(double margin) const {
    if (empty()) return *this;
    return Aabb{min.array() - margin, max.array() + margin};
  }
  Aabb intersected(const Aabb& b) const {
    return Aabb{min.cwiseMax(b.min), max.cwiseMin(b.max)};
  }
  bool overlaps(const Aabb& b) const {
    return !empty() && !b.empty() && (min.array() <= b.max.array()).all() &&
           (b.min.array() <= max.array()).all();
  }
  bool contains(const Vec3& p) const {
    return (p.array() >= min.array()).all() && (p.array() <= max.array()).all();
  }
  Vec3 size() const { return empty() ? Vec3::Zero() : Vec3(max - min); }
  Vec3 center() const { return 0.5 * (min + max); }
  double volume() const { Vec3 s = size(); return s.x() * s.y() * s.z(); }
};

/// A point's signed distance to a box from its per-axis offsets q (|p - centre|
/// less the half size, each axis on its own: a lattice computes them per row).
inline double box_signed_distance_q(const Vec3& q) {
  const double outside = q.cwiseMax(0.0).norm();
  const double inside = std::min(q.maxCoeff(), 0.0);
  return outside + inside;
}

/// Signed distance to an axis-aligned box (negative inside), exact.
inline double box_signed_distance(const Aabb& b, const Vec3& p) {
  const Vec3 c = b.center();
  const Vec3 h = 0.5 * (b.max - b.min);
  return box_signed_distance_q((p - c).cwiseAbs() - h);
}

}  // namespace cutsim
