#include "cutsim/compare/target.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

#include <embree3/rtcore.h>
#if defined(__x86_64__)
#include <immintrin.h>
#endif

#include "cutsim/core/cpu.h"
#include "cutsim/core/error.h"

namespace cutsim::compare {

namespace {

// Closest point on triangle (a, b, c) to p (Ericson, Real-Time Collision
// Detection 5.1.5); `feature` is 0 face, 1-3 vertex a/b/c, 4-6 edge ab/bc/ca.
Vec3 closest_on_triangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c, int& feature) {
  const Vec3 ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) { feature = 1; return a; }
  const Vec3 bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) { feature = 2; return b; }
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) { feature = 4; return a + (d1 / (d1 - d3)) * ab; }
  const Vec3 cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) { feature = 3; return c; }
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) { feature = 6; return a + (d2 / (d2 - d6)) * ac; }
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) { feature = 5; return b + ((d4 - d3) / ((d4 - d3) + (d5 - d6))) * (c - b); }
  const double denom = 1 / (va + vb + vc);
  feature = 0;
  return a + ab * (vb * denom) + ac * (vc * denom);
}

}  // namespace

struct Target::Impl {
  TriMesh mesh;
  Aabb box;
  Vec3 origin;  // Embree works in floats: coordinates relative to this
  std::vector<Vec3> face_n;      // unit face normals
  std::vector<Vec3> vertex_n;    // angle-weighted pseudonormals
  // Each triangle's edges' pseudonormals (the sum of the two faces'
  // normals), edges ab, bc, ca: kept per triangle, not looked up by edge.
  std::vector<std::array<Vec3, 3>> face_edge_n;
  RTCDevice device = nullptr;
  RTCScene scene = nullptr;
  double volume = 0;

  static std::uint64_t edge_key(std::uint32_t a, std::uint32_t b) {
    return (static_cast<std::uint64_t>(std::min(a, b)) << 32) | std::max(a, b);
  }

  struct Query {
    const Impl* self;
    Vec3 p;
    double best2 = std::numeric_limits<double>::infinity();
    Vec3 closest;
    unsigned prim = 0;
    int feature = 0;
  };

  std::vector<Aabb> face_box;  // each triangle's box, kept together for the culls

  // The squared distance from `p` to triangle `f`'s box.
  double box_distance2(unsigned f, const Vec3& p) const {
    const Aabb& b = face_box[f];
    return (b.min - p).cwiseMax(p - b.max).cwiseMax(0.0).squaredNorm();
  }

  // Whether triangle `f` comes within sqrt(r2) of `p`: its box first, then
  // the triangle itself. The target's long slivers (the blade's are 2.3 mm)
  // have boxes that reach far wider than they do: near the blade's surface
  // the box keeps some 19 triangles for a voxel quarter, the triangles 2.
  bool within2(unsigned f, const Vec3& p, double r2) const {
    if (box_distance2(f, p) > r2) return false;
    const auto& t = mesh.triangles[f];
    int feature;
    const Vec3 c = closest_on_triangle(p, mesh.positions[t[0]], mesh.positions[t[1]], mesh.positions[t[2]], feature);
    return (c - p).squaredNorm() <= r2;
  }

  // Triangle `f` as a candidate: true when it is the nearest so far.
  bool consider(Query& q, unsigned f) const {
    // Embree offers every triangle of a tree leaf whose box meets the
    // sphere: the triangle's own box rejects most of the others cheaply.
    if (box_distance2(f, q.p) >= q.best2) return false;
    const auto& t = mesh.triangles[f];
    int feature;
    const Vec3 c = closest_on_triangle(q.p, mesh.positions[t[0]], mesh.positions[t[1]], mesh.positions[t[2]], feature);
    const double d2 = (c - q.p).squaredNorm();
    if (d2 >= q.best2) return false;
    q.best2 = d2;
    q.closest = c;
    q.prim = f;
    q.feature = feature;
    return true;
  }

  static bool callback(RTCPointQueryFunctionArguments* args) {
    Query& q = *static_cast<Query*>(args->userPtr);
    if (!q.self->consider(q, args->primID)) return false;
    args->query->radius = static_cast<float>(std::sqrt(q.best2) * (1 + 1e-6) + 1e-9);
    return true;
  }

  struct Gather {
    const Impl* self;
    Vec3 p;
    double r2;
    std::vector<unsigned>* out;
  };
  static bool gather(RTCPointQueryFunctionArguments* args) {
    const Gather& g = *static_cast<const Gather*>(args->userPtr);
    if (g.self->within2(args->primID, g.p, g.r2)) g.out->push_back(args->primID);
    return false;
  }

  // Embree's query for a ball (in floats, relative to `origin`: grown a
  // little so that rounding drops no triangle within it).
  RTCPointQuery ball(const Vec3& p, double radius) const {
    RTCPointQuery pq;
    const Vec3 l = p - origin;
    pq.x = static_cast<float>(l.x());
    pq.y = static_cast<float>(l.y());
    pq.z = static_cast<float>(l.z());
    pq.time = 0;
    pq.radius = std::isfinite(radius) ? static_cast<float>(radius * (1 + 1e-5) + 1e-6) : std::numeric_limits<float>::infinity();
    return pq;
  }

  // Closest point within `radius`; false when there is none.
  // Only triangles within `radius` count: a farther one Embree happens to
  // offer (its box touches the sphere) is not the closest beyond the radius,
  // and its distance and sign would be wrong.
  bool closest(const Vec3& p, double radius, Query& q) const {
    q.self = this;
    q.p = p;
    q.best2 = std::isfinite(radius) ? radius * radius : std::numeric_limits<double>::infinity();
    RTCPointQuery pq = ball(p, radius);
    RTCPointQueryContext ctx;
    rtcInitPointQueryContext(&ctx);
    const double limit = q.best2;
    rtcPointQuery(scene, &pq, &ctx, &Impl::callback, &q);
    return q.best2 < limit || (!std::isfinite(limit) && std::isfinite(q.best2));
  }

  double sign_at(const Query& q) const {
    const auto& t = mesh.triangles[q.prim];
    Vec3 n;
    switch (q.feature) {
      case 0: n = face_n[q.prim]; break;
      case 1: n = vertex_n[t[0]]; break;
      case 2: n = vertex_n[t[1]]; break;
      case 3: n = vertex_n[t[2]]; break;
      case 4: n = face_edge_n[q.prim][0]; break;
      case 5: n = face_edge_n[q.prim][1]; break;
      default: n = face_edge_n[q.prim][2]; break;
    }
    return (q.p - q.closest).dot(n) >= 0 ? 1.0 : -1.0;
  }

  // Inside by ray parity along a direction no axis-aligned model lines up with.
  bool inside_by_ray(const Vec3& p) const {
    const Vec3 dir = Vec3(0.5773, 0.5774, 0.5775).normalized();
    int hits = 0;
    float tnear = 0;
    const Vec3 l = p - origin;
    for (int guard = 0; guard < 100000; ++guard) {
      RTCRayHit rh{};
      rh.ray.org_x = static_cast<float>(l.x());
      rh.ray.org_y = static_cast<float>(l.y());
      rh.ray.org_z = static_cast<float>(l.z());
      rh.ray.dir_x = static_cast<float>(dir.x());
      rh.ray.dir_y = static_cast<float>(dir.y());
      rh.ray.dir_z = static_cast<float>(dir.z());
      rh.ray.tnear = tnear;
      rh.ray.tfar = std::numeric_limits<float>::infinity();
      rh.ray.mask = 0xFFFFFFFF;
      rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
      RTCIntersectContext ic;
      rtcInitIntersectContext(&ic);
      rtcIntersect1(scene, &ic, &rh);
      if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) break;
      ++hits;
      tnear = std::nextafter(rh.ray.tfar, std::numeric_limits<float>::infinity());
    }
    return hits % 2 == 1;
  }
};

Target::Target(TriMesh mesh) : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  m.mesh = std::move(mesh);
  m.box = m.mesh.bounds();
  m.origin = m.box.center();
  m.volume = m.mesh.signed_volume();
  const std::size_t nf = m.mesh.triangles.size(), nv = m.mesh.positions.size();
  // Every (edge, face * 3 + k), sorted: an edge's faces are one run, in
  // face order.
  std::vector<std::pair<std::uint64_t, std::size_t>> edge_uses;
  edge_uses.reserve(3 * nf);
  m.face_n.resize(nf);
  m.face_box.reserve(nf);
  m.vertex_n.assign(nv, Vec3::Zero());
  for (std::size_t f = 0; f < nf; ++f) {
    const auto& t = m.mesh.triangles[f];
    const Vec3 &a = m.mesh.positions[t[0]], &b = m.mesh.positions[t[1]], &c = m.mesh.positions[t[2]];
    Vec3 n = (b - a).cross(c - a);
    const double len = n.norm();
    m.face_n[f] = len > 0 ? Vec3(n / len) : Vec3::Zero();
    m.face_box.push_back(Aabb{a.cwiseMin(b).cwiseMin(c), a.cwiseMax(b).cwiseMax(c)});
    const Vec3* v[3] = {&a, &b, &c};
    for (int k = 0; k < 3; ++k) {
      const Vec3 e1 = (*v[(k + 1) % 3] - *v[k]).normalized(), e2 = (*v[(k + 2) % 3] - *v[k]).normalized();
      const double ang = std::acos(std::clamp(e1.dot(e2), -1.0, 1.0));
      m.vertex_n[t[static_cast<std::size_t>(k)]] += ang * m.face_n[f];
      edge_uses.emplace_back(Impl::edge_key(t[static_cast<std::size_t>(k)], t[static_cast<std::size_t>((k + 1) % 3)]),
                             3 * f + static_cast<std::size_t>(k));
    }
  }
  // An edge's pseudonormal: the sum of its faces' normals, added in face order.
  std::sort(edge_uses.begin(), edge_uses.end());
  m.face_edge_n.resize(nf);
  for (std::size_t i = 0; i < edge_uses.size();) {
    std::size_t j = i;
    Vec3 sum = Vec3::Zero();
    for (; j < edge_uses.size() && edge_uses[j].first == edge_uses[i].first; ++j) sum += m.face_n[edge_uses[j].second / 3];
    for (; i < j; ++i) m.face_edge_n[edge_uses[i].second / 3][edge_uses[i].second % 3] = sum;
  }
  m.device = rtcNewDevice(nullptr);
  if (!m.device) throw GeometryError({}, "Embree: cannot create a device");
  m.scene = rtcNewScene(m.device);
  RTCGeometry g = rtcNewGeometry(m.device, RTC_GEOMETRY_TYPE_TRIANGLE);
  auto* vb = static_cast<float*>(rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), nv));
  for (std::size_t i = 0; i < nv; ++i) {
    const Vec3 l = m.mesh.positions[i] - m.origin;
    vb[3 * i] = static_cast<float>(l.x());
    vb[3 * i + 1] = static_cast<float>(l.y());
    vb[3 * i + 2] = static_cast<float>(l.z());
  }
  auto* ib = static_cast<unsigned*>(rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(unsigned), nf));
  for (std::size_t f = 0; f < nf; ++f)
    for (int k = 0; k < 3; ++k) ib[3 * f + static_cast<std::size_t>(k)] = m.mesh.triangles[f][static_cast<std::size_t>(k)];
  rtcCommitGeometry(g);
  rtcAttachGeometry(m.scene, g);
  rtcReleaseGeometry(g);
  rtcSetSceneFlags(m.scene, RTC_SCENE_FLAG_ROBUST);
  rtcCommitScene(m.scene);
  if (rtcGetDeviceError(m.device) != RTC_ERROR_NONE) throw GeometryError({}, "Embree: cannot build the target scene");
}

Target::~Target() {
  if (!impl_) return;
  if (impl_->scene) rtcReleaseScene(impl_->scene);
  if (impl_->device) rtcReleaseDevice(impl_->device);
}
Target::Target(Target&&) noexcept = default;

double Target::signed_distance(const Vec3& p) const {
  Impl::Query q;
  impl_->closest(p, std::numeric_limits<double>::infinity(), q);
  return impl_->sign_at(q) * std::sqrt(q.best2);
}

double Target::signed_distance_within(const Vec3& p, double radius) const {
  Impl::Query q;
  if (impl_->closest(p, radius, q)) return impl_->sign_at(q) * std::sqrt(q.best2);
  // Beyond the radius: the unbounded query, not ray parity (a ray through a
  // shared edge can count it twice, depending on the BVH).
  return signed_distance(p);
}

std::optional<double> Target::signed_distance_if_within(const Vec3& p, double radius) const {
  Impl::Query q;
  if (impl_->closest(p, radius, q)) return impl_->sign_at(q) * std::sqrt(q.best2);
  return std::nullopt;
}

void Target::triangles_near(const Vec3& c, double radius, std::vector<unsigned>& out) const {
  out.clear();
  Impl::Gather g{impl_.get(), c, radius * radius * (1 + 1e-9), &out};
  RTCPointQuery pq = impl_->ball(c, radius);
  RTCPointQueryContext ctx;
  rtcInitPointQueryContext(&ctx);
  rtcPointQuery(impl_->scene, &pq, &ctx, &Impl::gather, &g);
}

void Target::triangles_near(const Vec3& c, double radius, const std::vector<unsigned>& from,
                            std::vector<unsigned>& out) const {
  out.clear();
  const double r2 = radius * radius * (1 + 1e-9);
  for (const unsigned f : from)
    if (impl_->within2(f, c, r2)) out.push_back(f);
}

std::optional<double> Target::signed_distance_if_within(const Vec3& p, double radius,
                                                        const std::vector<unsigned>& near) const {
  Impl::Query q;
  q.self = impl_.get();
  q.p = p;
  q.best2 = radius * radius;
  const double limit = q.best2;
  for (const unsigned f : near) impl_->consider(q, f);
  if (q.best2 < limit) return impl_->sign_at(q) * std::sqrt(q.best2);
  return std::nullopt;
}

void Target::signed_distances_if_within_scalar(int n, const double* px, const double* py, const double* pz,
                                               double radius, const std::vector<unsigned>& near, double* out) const {
  for (int i = 0; i < n; ++i) {
    const auto d = signed_distance_if_within(Vec3(px[i], py[i], pz[i]), radius, near);
    out[i] = d ? *d : std::numeric_limits<double>::quiet_NaN();
  }
}

#if defined(__x86_64__)
namespace {
struct V3 {
  __m256d x, y, z;
};
[[gnu::target("avx2")]] inline V3 sub3(const V3& a, const V3& b) {
  return {_mm256_sub_pd(a.x, b.x), _mm256_sub_pd(a.y, b.y), _mm256_sub_pd(a.z, b.z)};
}
// a . b as Eigen sums a 3-vector's: (x + y) + z.
[[gnu::target("avx2")]] inline __m256d dot3(const V3& a, const V3& b) {
  return _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(a.x, b.x), _mm256_mul_pd(a.y, b.y)), _mm256_mul_pd(a.z, b.z));
}
[[gnu::target("avx2")]] inline V3 splat3(const Vec3& v) {
  return {_mm256_set1_pd(v.x()), _mm256_set1_pd(v.y()), _mm256_set1_pd(v.z())};
}
// o + t e, per component.
[[gnu::target("avx2")]] inline V3 along3(const V3& o, __m256d t, const V3& e) {
  return {_mm256_add_pd(o.x, _mm256_mul_pd(t, e.x)), _mm256_add_pd(o.y, _mm256_mul_pd(t, e.y)),
          _mm256_add_pd(o.z, _mm256_mul_pd(t, e.z))};
}
// Where `m` is set and nothing is taken yet (`taken`): v, and feature f.
[[gnu::target("avx2")]] inline void take3(V3& out, __m256d& feature, __m256d& taken, __m256d m, const V3& v, double f) {
  const __m256d now = _mm256_andnot_pd(taken, m);
  out.x = _mm256_blendv_pd(out.x, v.x, now);
  out.y = _mm256_blendv_pd(out.y, v.y, now);
  out.z = _mm256_blendv_pd(out.z, v.z, now);
  feature = _mm256_blendv_pd(feature, _mm256_set1_pd(f), now);
  taken = _mm256_or_pd(taken, now);
}
[[gnu::target("avx2")]] inline __m256d le(__m256d a, __m256d b) { return _mm256_cmp_pd(a, b, _CMP_LE_OQ); }
[[gnu::target("avx2")]] inline __m256d ge(__m256d a, __m256d b) { return _mm256_cmp_pd(a, b, _CMP_GE_OQ); }

// closest_on_triangle on four points: every region's point, the first
// region (in the portable version's order) each point is in taken.
[[gnu::target("avx2")]] inline V3 closest_on_triangle4(const V3& p, const Vec3& av, const Vec3& bv, const Vec3& cv,
                                                        __m256d& feature) {
  const __m256d zero = _mm256_setzero_pd();
  const V3 a = splat3(av), b = splat3(bv), c = splat3(cv);
  const V3 ab = splat3(bv - av), ac = splat3(cv - av);
  const V3 ap = sub3(p, a);
  const __m256d d1 = dot3(ab, ap), d2 = dot3(ac, ap);
  V3 out{zero, zero, zero};
  __m256d taken = zero;
  feature = zero;
  take3(out, feature, taken, _mm256_and_pd(le(d1, zero), le(d2, zero)), a, 1);
  const V3 bp = sub3(p, b);
  const __m256d d3 = dot3(ab, bp), d4 = dot3(ac, bp);
  take3(out, feature, taken, _mm256_and_pd(ge(d3, zero), le(d4, d3)), b, 2);
  const __m256d vc = _mm256_sub_pd(_mm256_mul_pd(d1, d4), _mm256_mul_pd(d3, d2));
  take3(out, feature, taken, _mm256_and_pd(_mm256_and_pd(le(vc, zero), ge(d1, zero)), le(d3, zero)),
        along3(a, _mm256_div_pd(d1, _mm256_sub_pd(d1, d3)), ab), 4);
  const V3 cp = sub3(p, c);
  const __m256d d5 = dot3(ab, cp), d6 = dot3(ac, cp);
  take3(out, feature, taken, _mm256_and_pd(ge(d6, zero), le(d5, d6)), c, 3);
  const __m256d vb = _mm256_sub_pd(_mm256_mul_pd(d5, d2), _mm256_mul_pd(d1, d6));
  take3(out, feature, taken, _mm256_and_pd(_mm256_and_pd(le(vb, zero), ge(d2, zero)), le(d6, zero)),
        along3(a, _mm256_div_pd(d2, _mm256_sub_pd(d2, d6)), ac), 6);
  const __m256d va = _mm256_sub_pd(_mm256_mul_pd(d3, d6), _mm256_mul_pd(d5, d4));
  const __m256d e43 = _mm256_sub_pd(d4, d3), e56 = _mm256_sub_pd(d5, d6);
  take3(out, feature, taken, _mm256_and_pd(_mm256_and_pd(le(va, zero), ge(e43, zero)), ge(e56, zero)),
        along3(b, _mm256_div_pd(e43, _mm256_add_pd(e43, e56)), splat3(cv - bv)), 5);
  const __m256d denom = _mm256_div_pd(_mm256_set1_pd(1.0), _mm256_add_pd(_mm256_add_pd(va, vb), vc));
  take3(out, feature, taken, _mm256_castsi256_pd(_mm256_set1_epi64x(-1)),
        along3(along3(a, _mm256_mul_pd(vb, denom), ab), _mm256_mul_pd(vc, denom), ac), 0);
  return out;
}
}  // namespace

[[gnu::target("avx2")]] void Target::signed_distances_if_within_avx2(int n, const double* px, const double* py,
                                                                     const double* pz, double radius,
                                                                     const std::vector<unsigned>& near,
                                                                     double* out) const {
  const Impl& m = *impl_;
  double x[4], y[4], z[4];
  for (int i = 0; i < 4; ++i) {
    const int j = i < n ? i : n - 1;  // (repeats: the same query again)
    x[i] = px[j];
    y[i] = py[j];
    z[i] = pz[j];
  }
  const V3 p{_mm256_loadu_pd(x), _mm256_loadu_pd(y), _mm256_loadu_pd(z)};
  const double limit = radius * radius;
  __m256d best2 = _mm256_set1_pd(limit), feature = _mm256_setzero_pd();
  __m256i prim = _mm256_setzero_si256();
  V3 closest{_mm256_setzero_pd(), _mm256_setzero_pd(), _mm256_setzero_pd()};
  const __m256d zero = _mm256_setzero_pd();
  for (const unsigned f : near) {
    // Impl::consider: the triangle's box first (below the best so far), then the triangle.
    const Aabb& b = m.face_box[f];
    // (min - p).cwiseMax(p - max).cwiseMax(0).squaredNorm()
    const __m256d gx = _mm256_max_pd(_mm256_max_pd(_mm256_sub_pd(_mm256_set1_pd(b.min.x()), p.x), _mm256_sub_pd(p.x, _mm256_set1_pd(b.max.x()))), zero);
    const __m256d gy = _mm256_max_pd(_mm256_max_pd(_mm256_sub_pd(_mm256_set1_pd(b.min.y()), p.y), _mm256_sub_pd(p.y, _mm256_set1_pd(b.max.y()))), zero);
    const __m256d gz = _mm256_max_pd(_mm256_max_pd(_mm256_sub_pd(_mm256_set1_pd(b.min.z()), p.z), _mm256_sub_pd(p.z, _mm256_set1_pd(b.max.z()))), zero);
    const __m256d box2 = dot3({gx, gy, gz}, {gx, gy, gz});
    const __m256d near_box = _mm256_cmp_pd(box2, best2, _CMP_LT_OQ);
    if (_mm256_movemask_pd(near_box) == 0) continue;
    const auto& t = m.mesh.triangles[f];
    __m256d feat;
    const V3 c = closest_on_triangle4(p, m.mesh.positions[t[0]], m.mesh.positions[t[1]], m.mesh.positions[t[2]], feat);
    const V3 off = sub3(c, p);
    const __m256d d2 = dot3(off, off);
    const __m256d better = _mm256_and_pd(near_box, _mm256_cmp_pd(d2, best2, _CMP_LT_OQ));
    if (_mm256_movemask_pd(better) == 0) continue;
    best2 = _mm256_blendv_pd(best2, d2, better);
    closest.x = _mm256_blendv_pd(closest.x, c.x, better);
    closest.y = _mm256_blendv_pd(closest.y, c.y, better);
    closest.z = _mm256_blendv_pd(closest.z, c.z, better);
    feature = _mm256_blendv_pd(feature, feat, better);
    prim = _mm256_castpd_si256(_mm256_blendv_pd(_mm256_castsi256_pd(prim),
                                                 _mm256_castsi256_pd(_mm256_set1_epi64x(static_cast<long long>(f))), better));
  }
  double b2[4], cx[4], cy[4], cz[4], ft[4];
  long long pr[4];
  _mm256_storeu_pd(b2, best2);
  _mm256_storeu_pd(cx, closest.x);
  _mm256_storeu_pd(cy, closest.y);
  _mm256_storeu_pd(cz, closest.z);
  _mm256_storeu_pd(ft, feature);
  _mm256_storeu_si256(reinterpret_cast<__m256i*>(pr), prim);
  for (int i = 0; i < n; ++i) {
    if (!(b2[i] < limit)) {
      out[i] = std::numeric_limits<double>::quiet_NaN();
      continue;
    }
    Impl::Query q;
    q.self = &m;
    q.p = Vec3(x[i], y[i], z[i]);
    q.best2 = b2[i];
    q.closest = Vec3(cx[i], cy[i], cz[i]);
    q.prim = static_cast<unsigned>(pr[i]);
    q.feature = static_cast<int>(ft[i]);
    out[i] = m.sign_at(q) * std::sqrt(q.best2);
  }
}
#else
void Target::signed_distances_if_within_avx2(int n, const double* px, const double* py, const double* pz,
                                             double radius, const std::vector<unsigned>& near, double* out) const {
  signed_distances_if_within_scalar(n, px, py, pz, radius, near, out);
}
#endif

void Target::signed_distances_if_within(int n, const double* px, const double* py, const double* pz, double radius,
                                        const std::vector<unsigned>& near, double* out) const {
#if defined(__x86_64__)
  if (use_avx2()) return signed_distances_if_within_avx2(n, px, py, pz, radius, near, out);
#endif
  signed_distances_if_within_scalar(n, px, py, pz, radius, near, out);
}

std::optional<Target::Plane> Target::common_plane(const std::vector<unsigned>& near) const {
  const Impl& m = *impl_;
  constexpr double kFlat = 1e-9;           // mm off the plane
  constexpr double kParallel = 1 - 1e-12;  // cosine between face normals
  Vec3 n = Vec3::Zero();
  for (const unsigned f : near)
    if (m.face_n[f] != Vec3::Zero()) {
      n = m.face_n[f];
      break;
    }
  if (n == Vec3::Zero()) return std::nullopt;  // (and when `near` is empty)
  const double c = n.dot(m.mesh.positions[m.mesh.triangles[near.front()][0]]);
  for (const unsigned f : near) {
    if (m.face_n[f] != Vec3::Zero() && m.face_n[f].dot(n) < kParallel) return std::nullopt;
    for (const auto v : m.mesh.triangles[f])
      if (std::fabs(n.dot(m.mesh.positions[v]) - c) > kFlat) return std::nullopt;
  }
  return Plane{n, c};
}

bool Target::inside(const Vec3& p) const { return impl_->inside_by_ray(p); }

void Target::debug_closest(const Vec3& p, unsigned* prim, int* feature, Vec3* closest) const {
  Impl::Query q;
  impl_->closest(p, std::numeric_limits<double>::infinity(), q);
  *prim = q.prim;
  *feature = q.feature;
  *closest = q.closest;
}
const TriMesh& Target::mesh() const { return impl_->mesh; }
const Aabb& Target::bounds() const { return impl_->box; }
double Target::volume_mm3() const { return impl_->volume; }

}  // namespace cutsim::compare
