#pragma once
// The design (target) as a closed triangle mesh with exact signed
// distances: Embree finds the closest triangle, the sign comes from the
// angle-weighted pseudonormal of the closest feature (Baerentzen-Aanaes),
// which is exact for closed, consistently oriented meshes.
#include <memory>
#include <optional>
#include <vector>

#include "cutsim/core/mesh.h"

namespace cutsim::compare {

class Target {
public:
  /// @pre `mesh` is closed and consistently oriented (io::require_closed).
  explicit Target(TriMesh mesh);
  ~Target();
  Target(Target&&) noexcept;

  /// Signed distance to the surface, mm: negative inside (material).
  double signed_distance(const Vec3& p) const;
  /// Like signed_distance; exact within `radius`, and beyond it the
  /// unbounded query (faster when most points are near the surface).
  double signed_distance_within(const Vec3& p, double radius) const;
  /// The signed distance when the surface lies within `radius` of `p`;
  /// otherwise nothing (cheap: no unbounded search).
  std::optional<double> signed_distance_if_within(const Vec3& p, double radius) const;
  /// The triangles within `radius` of `c` (every one that does; one a
  /// rounding error farther may come too), for many queries near one place.
  void triangles_near(const Vec3& c, double radius, std::vector<unsigned>& out) const;
  /// The same, taken from `from` (which holds every triangle near enough).
  void triangles_near(const Vec3& c, double radius, const std::vector<unsigned>& from,
                      std::vector<unsigned>& out) const;
  /// signed_distance_if_within over `near` only: the same answer when `near`
  /// holds every triangle within `radius` of `p` (triangles_near of a ball
  /// that holds the query's), without a search of the whole mesh.
  std::optional<double> signed_distance_if_within(const Vec3& p, double radius,
                                                  const std::vector<unsigned>& near) const;
  /// The same for the n points (px, py, pz)[i], n <= 4: out[i] the signed
  /// distance, or NaN where there is none within `radius`. The same bits
  /// as one query each (with AVX2, the four at once).
  void signed_distances_if_within(int n, const double* px, const double* py, const double* pz, double radius,
                                  const std::vector<unsigned>& near, double* out) const;
  /// Without AVX2 (one query each) and with it, for the tests.
  void signed_distances_if_within_scalar(int n, const double* px, const double* py, const double* pz, double radius,
                                         const std::vector<unsigned>& near, double* out) const;
  void signed_distances_if_within_avx2(int n, const double* px, const double* py, const double* pz, double radius,
                                       const std::vector<unsigned>& near, double* out) const;
  /// A plane: the points x with n . x = c, n unit and pointing out of the material.
  struct Plane {
    Vec3 n;
    double c = 0;
    double signed_distance(const Vec3& p) const { return n.dot(p) - c; }
  };
  /// The plane `near` lies in, when every one of its triangles lies in one
  /// plane (within 1e-9 mm) facing one way; nothing when `near` is empty.
  /// If `near` holds every triangle within R of a point c, the surface
  /// within R of c is that plane's disc (the mesh is closed: an edge of the
  /// flat patch inside the ball would be shared with a triangle out of the
  /// plane, itself within R), and the two half balls lie wholly outside and
  /// inside. So at a point p within R of c, the signed distance clamped to
  /// +-(R - |p - c|) is the plane's signed distance clamped alike.
  std::optional<Plane> common_plane(const std::vector<unsigned>& near) const;
  /// Inside by ray parity (a cross-check for tests; not robust on edges).
  bool inside(const Vec3& p) const;
  /// For diagnosis: the closest triangle, its feature and point.
  void debug_closest(const Vec3& p, unsigned* prim, int* feature, Vec3* closest) const;
  const TriMesh& mesh() const;
  const Aabb& bounds() const;
  double volume_mm3() const;

private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace cutsim::compare
