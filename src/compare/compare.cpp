#include "cutsim/compare/compare.h"

#include <cmath>
#include <mutex>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

namespace cutsim::compare {

namespace {
double fraction(double d, double h) { return std::clamp(0.5 - d / h, 0.0, 1.0); }
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
  std::mutex mu;
  stock.for_each_roi_block([&](const stock::VoxelBlock& b) {
    const Vec3 centre = b.first_center + 0.5 * h * Vec3(b.n[0] - 1, b.n[1] - 1, b.n[2] - 1);
    const double dc = target.signed_distance_within(centre, hd + h);
    const bool target_uniform = std::fabs(dc) >= hd + 0.5 * h;
    double over = 0, under = 0;
    for (int x = 0; x < b.n[0]; ++x)
      for (int y = 0; y < b.n[1]; ++y)
        for (int z = 0; z < b.n[2]; ++z) {
          const double fs = fraction(b.uniform ? b.value : b.values[(x * 8 + y) * 8 + z], h);
          double ft;
          if (target_uniform) {
            ft = dc < 0 ? 1.0 : 0.0;
          } else {
            // Distance is 1-Lipschitz: a voxel nearer the centre than
            // |dc| - h/2 is saturated like the centre; only the rest need a query.
            const Vec3 p = b.first_center + h * Vec3(x, y, z);
            if ((p - centre).norm() <= std::fabs(dc) - 0.5 * h) ft = dc < 0 ? 1.0 : 0.0;
            else ft = fraction(target.signed_distance_within(p, h), h);
          }
          over += std::max(0.0, ft - fs);
          under += std::max(0.0, fs - ft);
        }
    if (over == 0 && under == 0) return;
    std::lock_guard<std::mutex> lock(mu);
    sums.push_back({b.first_center, over, under});
  });
  std::sort(sums.begin(), sums.end(), [](const Sum& a, const Sum& b) {
    return std::lexicographical_compare(a.key.data(), a.key.data() + 3, b.key.data(), b.key.data() + 3);
  });
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
