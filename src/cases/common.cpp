#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>

#include "cutsim/cases/cases.h"
#include "cutsim/core/error.h"

namespace cutsim::cases {

std::string num(double v, int decimals) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*f", decimals, v);
  std::string s = buf;
  if (s.find('.') != std::string::npos) {
    while (s.back() == '0') s.pop_back();
    if (s.back() == '.') s.pop_back();
  }
  if (s == "-0") s = "0";
  return s;
}

TriMesh height_field_solid(const std::vector<double>& xs, const std::vector<double>& ys,
                           const std::function<double(double, double)>& f, double z_bottom) {
  TriMesh m;
  const auto nx = static_cast<std::uint32_t>(xs.size()), ny = static_cast<std::uint32_t>(ys.size());
  m.positions.reserve(static_cast<std::size_t>(nx) * ny + 2 * (nx + ny));
  for (std::uint32_t j = 0; j < ny; ++j)
    for (std::uint32_t i = 0; i < nx; ++i) m.positions.emplace_back(xs[i], ys[j], f(xs[i], ys[j]));
  auto top = [&](std::uint32_t i, std::uint32_t j) { return j * nx + i; };
  for (std::uint32_t j = 0; j + 1 < ny; ++j)
    for (std::uint32_t i = 0; i + 1 < nx; ++i) {
      m.triangles.push_back({top(i, j), top(i + 1, j), top(i + 1, j + 1)});
      m.triangles.push_back({top(i, j), top(i + 1, j + 1), top(i, j + 1)});
    }
  // The boundary ring, counter-clockwise seen from above, and under it the bottom.
  std::vector<std::uint32_t> ring;
  for (std::uint32_t i = 0; i + 1 < nx; ++i) ring.push_back(top(i, 0));
  for (std::uint32_t j = 0; j + 1 < ny; ++j) ring.push_back(top(nx - 1, j));
  for (std::uint32_t i = nx - 1; i > 0; --i) ring.push_back(top(i, ny - 1));
  for (std::uint32_t j = ny - 1; j > 0; --j) ring.push_back(top(0, j));
  const auto base = static_cast<std::uint32_t>(m.positions.size());
  for (std::uint32_t k : ring) m.positions.emplace_back(m.positions[k].x(), m.positions[k].y(), z_bottom);
  const auto centre = static_cast<std::uint32_t>(m.positions.size());
  m.positions.emplace_back(0.5 * (xs.front() + xs.back()), 0.5 * (ys.front() + ys.back()), z_bottom);
  const auto n = static_cast<std::uint32_t>(ring.size());
  for (std::uint32_t k = 0; k < n; ++k) {
    const std::uint32_t a = ring[k], b = ring[(k + 1) % n], a0 = base + k, b0 = base + (k + 1) % n;
    m.triangles.push_back({a, a0, b0});  // side, facing out
    m.triangles.push_back({a, b0, b});
    m.triangles.push_back({centre, b0, a0});  // bottom, facing down
  }
  return m;
}

std::string bench_table(const std::string& keys) {
  return "\n[bench]                # issue 7's goal, on a 2-core machine (cutsim bench prints the distance)\n" + keys;
}

std::string ply_binary(const TriMesh& m) {
  std::string out = "ply\nformat binary_little_endian 1.0\ncomment cutsim-cases\nelement vertex " +
                    std::to_string(m.positions.size()) +
                    "\nproperty double x\nproperty double y\nproperty double z\nelement face " +
                    std::to_string(m.triangles.size()) + "\nproperty list uchar uint vertex_indices\nend_header\n";
  out.reserve(out.size() + m.positions.size() * 24 + m.triangles.size() * 13);
  auto put = [&](const void* p, std::size_t n) { out.append(static_cast<const char*>(p), n); };
  for (const Vec3& p : m.positions) {
    const double v[3] = {p.x(), p.y(), p.z()};
    put(v, sizeof v);
  }
  for (const auto& t : m.triangles) {
    const unsigned char three = 3;
    put(&three, 1);
    put(t.data(), 12);
  }
  return out;
}

std::vector<double> graded_axis(double lo, double hi, double fine_lo, double fine_hi, double fine, double coarse) {
  std::vector<double> below, mid, above;
  const int n = static_cast<int>(std::ceil((fine_hi - fine_lo) / fine - 1e-9));
  for (int i = 0; i <= n; ++i) mid.push_back(i == n ? fine_hi : fine_lo + i * fine);
  for (double s = fine * 1.5, x = fine_lo - s; x > lo; s = std::min(coarse, s * 1.5), x -= s) below.push_back(x);
  below.push_back(lo);
  for (double s = fine * 1.5, x = fine_hi + s; x < hi; s = std::min(coarse, s * 1.5), x += s) above.push_back(x);
  above.push_back(hi);
  std::vector<double> xs(below.rbegin(), below.rend());
  xs.insert(xs.end(), mid.begin(), mid.end());
  xs.insert(xs.end(), above.begin(), above.end());
  return xs;
}

}  // namespace cutsim::cases
