#pragma once
// Triangle mesh in mm (double positions: micrometre parts far from the origin).
#include <array>
#include <cstdint>
#include <vector>

#include "cutsim/core/geometry.h"

namespace cutsim {

struct TriMesh {
  std::vector<Vec3> positions;
  std::vector<Eigen::Vector3f> normals;  ///< unit, one per position (may be empty)
  std::vector<std::array<std::uint32_t, 3>> triangles;

  Aabb bounds() const {
    Aabb b;
    for (const Vec3& p : positions) b.extend(p);
    return b;
  }
  /// Enclosed volume by the divergence theorem (meaningful when closed).
  double signed_volume() const {
    double v = 0;
    for (const auto& t : triangles)
      v += positions[t[0]].dot(positions[t[1]].cross(positions[t[2]]));
    return v / 6.0;
  }
};

}  // namespace cutsim
