#include "cutsim/compare/compare.h"

#include <cmath>
#include <mutex>

#include <openvdb/openvdb.h>
#include <openvdb/tools/VolumeToMesh.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

namespace cutsim::compare {

namespace {
double fraction(double d, double h) { return std::clamp(0.5 - d / h, 0.0, 1.0); }

// A region's level set over the blocks where it exists, meshed.
struct RegionBlock {
  openvdb::Coord origin;
  int n[3];
  float v[512];
};

TriMesh mesh_region(const std::vector<RegionBlock>& blocks, const Vec3& origin, double h) {
  TriMesh out;
  if (blocks.empty()) return out;
  openvdb::initialize();
  auto grid = openvdb::FloatGrid::create(static_cast<float>(h));
  grid->setTransform(openvdb::math::Transform::createLinearTransform(h));
  auto acc = grid->getAccessor();
  for (const auto& b : blocks)
    for (int x = 0; x < b.n[0]; ++x)
      for (int y = 0; y < b.n[1]; ++y)
        for (int z = 0; z < b.n[2]; ++z) acc.setValue(b.origin.offsetBy(x, y, z), b.v[(x * 8 + y) * 8 + z]);
  std::vector<openvdb::Vec3s> pts;
  std::vector<openvdb::Vec3I> tris;
  std::vector<openvdb::Vec4I> quads;
  // Meshed at +h/4 so that a region thinner than a voxel still shows.
  openvdb::tools::volumeToMesh(*grid, pts, tris, quads, 0.25 * h, 0.0);
  for (const auto& p : pts) out.positions.push_back(origin + Vec3(p.x(), p.y(), p.z()));
  for (const auto& t : tris) out.triangles.push_back({t[0], t[2], t[1]});
  for (const auto& q : quads) {
    out.triangles.push_back({q[0], q[2], q[1]});
    out.triangles.push_back({q[0], q[3], q[2]});
  }
  return out;
}

}  // namespace

CompareResult compare(const stock::Stock& stock, const Target& target, const TriMesh& machined,
                      const CompareOptions& opt) {
  CompareResult r;
  r.tolerance_mm = opt.tolerance_mm;
  const double h = stock.voxel_mm();
  const double hd = std::sqrt(3.0) * 3.5 * h;  // block centre to its farthest voxel centre

  // Volumes: blocks summed into per-block slots, then added in a fixed
  // order so the answer does not depend on threading.
  struct Sum { Vec3 key; double over = 0, under = 0; };
  std::vector<Sum> sums;
  std::vector<RegionBlock> over_blocks, under_blocks;
  std::mutex mu;
  const Vec3 grid_origin = (stock.roi().min / h).array().round().matrix() * h;
  stock.for_each_roi_block([&](const stock::VoxelBlock& b) {
    const Vec3 centre = b.first_center + 0.5 * h * Vec3(b.n[0] - 1, b.n[1] - 1, b.n[2] - 1);
    const double dc = target.signed_distance_within(centre, hd + h);
    const bool target_uniform = std::fabs(dc) >= hd + 0.5 * h;
    double over = 0, under = 0;
    RegionBlock ro, ru;
    for (int x = 0; x < b.n[0]; ++x)
      for (int y = 0; y < b.n[1]; ++y)
        for (int z = 0; z < b.n[2]; ++z) {
          const int i = (x * 8 + y) * 8 + z;
          const double ds = b.uniform ? b.value : b.values[i];
          const double fs = fraction(ds, h);
          double dt;
          if (target_uniform) {
            dt = dc < 0 ? -h : h;
          } else {
            // Distance is 1-Lipschitz: a voxel nearer the centre than
            // |dc| - h/2 is saturated like the centre; only the rest need a query.
            const Vec3 p = b.first_center + h * Vec3(x, y, z);
            if ((p - centre).norm() <= std::fabs(dc) - 0.5 * h) dt = dc < 0 ? -h : h;
            else dt = std::clamp(target.signed_distance_within(p, h), -h, h);
          }
          const double ft = fraction(dt, h);
          over += std::max(0.0, ft - fs);
          under += std::max(0.0, fs - ft);
          const double cs = std::clamp(ds, -h, h);
          ro.v[i] = static_cast<float>(std::max(dt, -cs));
          ru.v[i] = static_cast<float>(std::max(cs, -dt));
        }
    if (over == 0 && under == 0) return;
    const Vec3 idx = (b.first_center - grid_origin) / h;
    ro.origin = ru.origin = openvdb::Coord(static_cast<int>(std::lround(idx.x())), static_cast<int>(std::lround(idx.y())),
                                           static_cast<int>(std::lround(idx.z())));
    for (int k = 0; k < 3; ++k) ro.n[k] = ru.n[k] = b.n[k];
    std::lock_guard<std::mutex> lock(mu);
    sums.push_back({b.first_center, over, under});
    if (over > 0) over_blocks.push_back(ro);
    if (under > 0) under_blocks.push_back(ru);
  });
  std::sort(sums.begin(), sums.end(), [](const Sum& a, const Sum& b) {
    return std::lexicographical_compare(a.key.data(), a.key.data() + 3, b.key.data(), b.key.data() + 3);
  });
  auto by_origin = [](const RegionBlock& a, const RegionBlock& b) { return a.origin < b.origin; };
  std::sort(over_blocks.begin(), over_blocks.end(), by_origin);
  std::sort(under_blocks.begin(), under_blocks.end(), by_origin);
  r.overcut_mesh = mesh_region(over_blocks, grid_origin, h);
  r.undercut_mesh = mesh_region(under_blocks, grid_origin, h);
  const double hv = h * h * h;
  for (const Sum& s : sums) {
    r.overcut_volume_mm3 += s.over * hv;
    r.undercut_volume_mm3 += s.under * hv;
  }

  // Deviation at every vertex of the machined surface.
  const std::size_t nv = machined.positions.size();
  r.vertex_deviation_mm.resize(nv);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nv), [&](const auto& range) {
    for (std::size_t i = range.begin(); i != range.end(); ++i)
      r.vertex_deviation_mm[i] = static_cast<float>(target.signed_distance(machined.positions[i]));
  });
  double area_in = 0, area_all = 0;
  for (const auto& t : machined.triangles) {
    const Vec3 &a = machined.positions[t[0]], &b = machined.positions[t[1]], &c = machined.positions[t[2]];
    const double area = 0.5 * (b - a).cross(c - a).norm();
    for (int k = 0; k < 3; ++k) {
      const double d = r.vertex_deviation_mm[t[static_cast<std::size_t>(k)]];
      area_all += area / 3;
      if (std::fabs(d) <= opt.tolerance_mm) area_in += area / 3;
    }
  }
  for (float d : r.vertex_deviation_mm) {
    r.max_overcut_mm = std::max(r.max_overcut_mm, -static_cast<double>(d));
    r.max_undercut_mm = std::max(r.max_undercut_mm, static_cast<double>(d));
  }
  r.fraction_in_tolerance = area_all > 0 ? area_in / area_all : 1.0;
  return r;
}

}  // namespace cutsim::compare
