// Surface extraction: the grid's zero level set clipped to the ROI, plus the
// analytic box faces outside the ROI.
#include <openvdb/tools/Interpolation.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "cutsim/stock/level_set_mesher.h"
#include "stock_impl.h"

namespace cutsim::stock {

namespace {

// Keeps the part of a convex polygon on the side `sign * (p[k] - c) <= 0`.
void clip_polygon(std::vector<Vec3>& poly, int k, double c, double sign) {
  std::vector<Vec3> out;
  out.reserve(poly.size() + 2);
  const std::size_t n = poly.size();
  for (std::size_t i = 0; i < n; ++i) {
    const Vec3& a = poly[i];
    const Vec3& b = poly[(i + 1) % n];
    const double da = sign * (a[k] - c), db = sign * (b[k] - c);
    if (da <= 0) out.push_back(a);
    if ((da < 0 && db > 0) || (da > 0 && db < 0)) {
      const double t = da / (da - db);
      Vec3 p = a + t * (b - a);
      p[k] = c;  // exactly on the plane, so it meets the analytic faces
      out.push_back(p);
    }
  }
  poly.swap(out);
}

void add_rect(TriMesh& mesh, int k, double c, bool positive, double u0, double u1, double v0, double v1) {
  if (u1 - u0 <= 0 || v1 - v0 <= 0) return;
  const int u = (k + 1) % 3, v = (k + 2) % 3;
  const auto base = static_cast<std::uint32_t>(mesh.positions.size());
  const double us[4] = {u0, u1, u1, u0}, vs[4] = {v0, v0, v1, v1};
  Eigen::Vector3f n = Eigen::Vector3f::Zero();
  n[k] = positive ? 1.f : -1.f;
  for (int i = 0; i < 4; ++i) {
    Vec3 p;
    p[k] = c;
    p[u] = us[i];
    p[v] = vs[i];
    mesh.positions.push_back(p);
    mesh.normals.push_back(n);
  }
  // (u, v, k) is right-handed, so counter-clockwise in (u, v) faces +k.
  if (positive) {
    mesh.triangles.push_back({base, base + 1, base + 2});
    mesh.triangles.push_back({base, base + 2, base + 3});
  } else {
    mesh.triangles.push_back({base, base + 2, base + 1});
    mesh.triangles.push_back({base, base + 3, base + 2});
  }
}

}  // namespace

TriMesh Stock::surface_mesh(double adaptivity) const {
  const Impl& m = *impl_;
  const LevelSetMesh raw = mesh_level_set(m.grid->tree(), adaptivity);

  TriMesh mesh;
  mesh.positions.resize(raw.points.size());
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, raw.points.size(), 1 << 16), [&](const auto& range) {
    for (std::size_t i = range.begin(); i != range.end(); ++i) mesh.positions[i] = m.origin + m.h * raw.points[i];
  });

  // Clip to the ROI cell box where it lies inside the stock box; elsewhere
  // the grid's surface is the box face itself and needs no clipping.
  const Aabb& r = m.roi;
  struct Plane { int k; double c; double sign; };
  std::vector<Plane> planes;
  for (int k = 0; k < 3; ++k) {
    if (r.min[k] > m.box.min[k]) planes.push_back({k, r.min[k], -1});
    if (r.max[k] < m.box.max[k]) planes.push_back({k, r.max[k], +1});
  }
  // Which planes each vertex lies beyond (a bit each), on both threads: a
  // triangle is kept whole when none of its vertices is beyond any, and
  // dropped when all three are beyond one.
  std::vector<std::uint8_t> beyond(mesh.positions.size());
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, beyond.size(), 1 << 16), [&](const auto& range) {
    for (std::size_t i = range.begin(); i != range.end(); ++i) {
      std::uint8_t bits = 0;
      for (std::size_t j = 0; j < planes.size(); ++j)
        if (planes[j].sign * (mesh.positions[i][planes[j].k] - planes[j].c) > 0) bits |= static_cast<std::uint8_t>(1u << j);
      beyond[i] = bits;
    }
  });
  mesh.triangles.reserve(raw.triangles.size());
  std::vector<Vec3> poly;
  auto clip = [&](const std::array<std::uint32_t, 3>& t) {
    const std::uint8_t any = beyond[t[0]] | beyond[t[1]] | beyond[t[2]];
    if (any == 0) { mesh.triangles.push_back(t); return; }
    if ((beyond[t[0]] & beyond[t[1]] & beyond[t[2]]) != 0) return;
    poly = {mesh.positions[t[0]], mesh.positions[t[1]], mesh.positions[t[2]]};
    for (const Plane& pl : planes) {
      clip_polygon(poly, pl.k, pl.c, pl.sign);
      if (poly.size() < 3) break;
    }
    if (poly.size() < 3) return;
    const auto base = static_cast<std::uint32_t>(mesh.positions.size());
    for (const Vec3& p : poly) mesh.positions.push_back(p);
    for (std::uint32_t i = 1; i + 1 < poly.size(); ++i) mesh.triangles.push_back({base, base + i, base + i + 1});
  };
  for (const auto& t : raw.triangles) clip(t);
  // Drop vertices no triangle uses (the clipped-away ones), keeping order.
  std::vector<std::uint32_t> source;  // each kept vertex's index before
  {
    std::vector<std::uint32_t> remap(mesh.positions.size(), UINT32_MAX);
    std::vector<Vec3> kept;
    for (auto& t : mesh.triangles)
      for (auto& i : t) {
        if (remap[i] == UINT32_MAX) {
          remap[i] = static_cast<std::uint32_t>(kept.size());
          kept.push_back(mesh.positions[i]);
          source.push_back(i);
        }
        i = remap[i];
      }
    mesh.positions.swap(kept);
  }
  // Normals: the mesher's at its points. At the points the ROI's clipping
  // made, the level set's gradient (central differences of trilinear
  // samples half a voxel either side along each axis). The six samples
  // read only the 3^3 voxels from floor(q - 1/2): those are read once (27
  // reads, not 48) and each sample interpolates OpenVDB's way.
  mesh.normals.resize(mesh.positions.size());
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, mesh.positions.size(), 4096), [&](const auto& range) {
    auto acc = m.grid->getConstAccessor();
    for (std::size_t i = range.begin(); i != range.end(); ++i) {
      if (source[i] < raw.normals.size()) {
        mesh.normals[i] = raw.normals[source[i]];
        continue;
      }
      const Vec3 q = (mesh.positions[i] - m.origin) / m.h;
      const openvdb::Coord base(static_cast<int>(std::floor(q.x() - 0.5)), static_cast<int>(std::floor(q.y() - 0.5)),
                                static_cast<int>(std::floor(q.z() - 0.5)));
      float v[3][3][3];
      for (int x = 0; x < 3; ++x)
        for (int y = 0; y < 3; ++y)
          for (int z = 0; z < 3; ++z) v[x][y][z] = acc.getValue(base.offsetBy(x, y, z));
      auto sample = [&](const openvdb::Vec3d& a) {
        const openvdb::Vec3d fl(std::floor(a[0]), std::floor(a[1]), std::floor(a[2]));
        const int o[3] = {static_cast<int>(fl[0]) - base.x(), static_cast<int>(fl[1]) - base.y(),
                          static_cast<int>(fl[2]) - base.z()};
        if (o[0] < 0 || o[0] > 1 || o[1] < 0 || o[1] > 1 || o[2] < 0 || o[2] > 1)
          return openvdb::tools::BoxSampler::sample(acc, a);  // (rounding put the sample past the 3^3 voxels)
        float d[2][2][2];
        for (int x = 0; x < 2; ++x)
          for (int y = 0; y < 2; ++y)
            for (int z = 0; z < 2; ++z) d[x][y][z] = v[o[0] + x][o[1] + y][o[2] + z];
        return openvdb::tools::BoxSampler::trilinearInterpolation(d, a - fl);
      };
      Vec3 gr;
      for (int k = 0; k < 3; ++k) {
        openvdb::Vec3d a(q.x(), q.y(), q.z()), b = a;
        a[k] += 0.5;
        b[k] -= 0.5;
        gr[k] = sample(a) - sample(b);
      }
      const double n = gr.norm();
      mesh.normals[i] = n > 0 ? Eigen::Vector3f((gr / n).cast<float>()) : Eigen::Vector3f(0, 0, 1);
    }
  });

  // Analytic faces of the box outside the ROI.
  const Aabb& b = m.box;
  for (int k = 0; k < 3; ++k) {
    const int u = (k + 1) % 3, v = (k + 2) % 3;
    for (int side = 0; side < 2; ++side) {
      const double c = side ? b.max[k] : b.min[k];
      const bool positive = side == 1;
      const bool covered = c >= r.min[k] && c <= r.max[k];
      if (!covered) {
        add_rect(mesh, k, c, positive, b.min[u], b.max[u], b.min[v], b.max[v]);
        continue;
      }
      // Face minus the ROI's window (clamped to the face): up to four strips.
      const double wu0 = std::clamp(r.min[u], b.min[u], b.max[u]), wu1 = std::clamp(r.max[u], b.min[u], b.max[u]);
      const double wv0 = std::clamp(r.min[v], b.min[v], b.max[v]), wv1 = std::clamp(r.max[v], b.min[v], b.max[v]);
      add_rect(mesh, k, c, positive, b.min[u], b.max[u], b.min[v], wv0);
      add_rect(mesh, k, c, positive, b.min[u], b.max[u], wv1, b.max[v]);
      add_rect(mesh, k, c, positive, b.min[u], wu0, wv0, wv1);
      add_rect(mesh, k, c, positive, wu1, b.max[u], wv0, wv1);
    }
  }
  return mesh;
}

}  // namespace cutsim::stock
