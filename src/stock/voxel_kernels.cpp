#include "voxel_kernels.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cstddef>
#include <limits>

#if defined(__x86_64__)
#include <immintrin.h>
#endif

namespace cutsim::stock::detail {

// The voxels b < n (bits) of a quarter whose nearest distance so far d[b]
// is above `floor` and where the plane lies below min(d[b], need[b]): those
// the piece may lower. The planes are summed as Eigen's dot does, so both
// versions give the same bits. Scalar, it was a third of raster40k's voxel
// step (a loop over 41 voxels for each of 7 pieces a quarter): AVX2 takes
// four at a time where the CPU has it.
std::uint64_t planes_below_scalar(const double* d, const double* need, const double* yx, const double* yy,
                                  const double* yz, int from, int n, const CentrePlane& pl, double floor) {
  std::uint64_t bits = 0;
  for (int b = from; b < n; ++b) {
    const double lim = std::min(d[b], need[b]);
    const bool below = d[b] > floor && pl.c + (pl.gx * yx[b] + pl.gy * yy[b] + pl.gz * yz[b]) < lim;
    bits |= std::uint64_t(below) << b;
  }
  return bits;
}

#if defined(__x86_64__)
// (No FMA: the target adds none, so the products round as above.)
[[gnu::target("avx2")]] std::uint64_t planes_below_avx2(const double* d, const double* need, const double* yx,
                                                         const double* yy, const double* yz, int n, const CentrePlane& pl,
                                                         double floor) {
  const __m256d c = _mm256_set1_pd(pl.c), gx = _mm256_set1_pd(pl.gx), gy = _mm256_set1_pd(pl.gy),
                gz = _mm256_set1_pd(pl.gz), fl = _mm256_set1_pd(floor);
  std::uint64_t bits = 0;
  int b = 0;
  for (; b + 4 <= n; b += 4) {
    const __m256d db = _mm256_loadu_pd(d + b);
    // min(need, d): need where it is less, else d (std::min(d, need)).
    const __m256d lim = _mm256_min_pd(_mm256_loadu_pd(need + b), db);
    __m256d t = _mm256_add_pd(_mm256_mul_pd(gx, _mm256_loadu_pd(yx + b)), _mm256_mul_pd(gy, _mm256_loadu_pd(yy + b)));
    t = _mm256_add_pd(c, _mm256_add_pd(t, _mm256_mul_pd(gz, _mm256_loadu_pd(yz + b))));
    const __m256d below = _mm256_and_pd(_mm256_cmp_pd(db, fl, _CMP_GT_OQ), _mm256_cmp_pd(t, lim, _CMP_LT_OQ));
    bits |= static_cast<std::uint64_t>(_mm256_movemask_pd(below)) << b;
  }
  return bits | planes_below_scalar(d, need, yx, yy, yz, b, n, pl, floor);
}
#else
std::uint64_t planes_below_avx2(const double* d, const double* need, const double* yx, const double* yy,
                                const double* yz, int n, const CentrePlane& pl, double floor) {
  return planes_below_scalar(d, need, yx, yy, yz, 0, n, pl, floor);
}
#endif

std::uint64_t planes_below(const double* d, const double* need, const double* yx, const double* yy, const double* yz,
                           int n, const CentrePlane& pl, double floor) {
  if (use_avx2()) return planes_below_avx2(d, need, yx, yy, yz, n, pl, floor);
  return planes_below_scalar(d, need, yx, yy, yz, 0, n, pl, floor);
}

// The voxels a piece's box leaves to its distance, among those not yet
// at or below `floor`: the box test the stock update's loop over a
// quarter's voxels made per voxel, after the cone test (a piece's value
// at the voxel last evaluated, less the way from there). The box's
// verdict does not depend on the other voxels, so it can come first, for
// all of them: four at a time with AVX2. (In the snowflake's quarters of
// several pieces, the test and its loop were a fifth of the voxel step.)
std::uint64_t boxes_reach_scalar(const double* d, const double* need, const double* px, const double* py,
                                 const double* pz, int from, int n, const Aabb& box, bool inner, double floor) {
  std::uint64_t bits = 0;
  for (int b = from; b < n; ++b) {
    if (d[b] <= floor) continue;
    const double thr = std::min(d[b], need[b]);
    const double lim = inner ? std::min(thr, 0.0) : thr;
    const double b2 = sweep::detail::box_distance2(box, Vec3(px[b], py[b], pz[b]));
    if (b2 > 0 && (lim <= 0 || b2 >= lim * lim)) continue;
    bits |= std::uint64_t(1) << b;
  }
  return bits;
}

#if defined(__x86_64__)
namespace {
// Row i of m applied to r (sweep::detail::to_frame), on four points.
[[gnu::target("avx2")]] inline __m256d frame_row_avx2(const Eigen::Matrix3d& m, int i, __m256d rx, __m256d ry, __m256d rz) {
  return _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(_mm256_set1_pd(m(i, 0)), rx), _mm256_mul_pd(_mm256_set1_pd(m(i, 1)), ry)),
                       _mm256_mul_pd(_mm256_set1_pd(m(i, 2)), rz));
}

// std::fabs
[[gnu::target("avx2")]] inline __m256d abs_avx2(__m256d x) { return _mm256_andnot_pd(_mm256_set1_pd(-0.0), x); }
// std::max(a, b), std::min(a, b): (a < b ? b : a), (b < a ? b : a); the
// vector max(x, y) and min(x, y) are (x > y ? x : y), (x < y ? x : y).
[[gnu::target("avx2")]] inline __m256d std_max_avx2(__m256d a, __m256d b) { return _mm256_max_pd(b, a); }
[[gnu::target("avx2")]] inline __m256d std_min_avx2(__m256d a, __m256d b) { return _mm256_min_pd(b, a); }
// std::max(std::max(lo - p, p - hi), 0.0) on four points: the box's gap
// along one axis (sweep::detail::box_distance2).
[[gnu::target("avx2")]] inline __m256d box_gap_avx2(__m256d p, double lo, double hi) {
  const __m256d inner = std_max_avx2(_mm256_sub_pd(_mm256_set1_pd(lo), p), _mm256_sub_pd(p, _mm256_set1_pd(hi)));
  return std_max_avx2(inner, _mm256_setzero_pd());
}
// sweep::detail::box_distance2 on four points: gx^2 + gy^2 + gz^2.
[[gnu::target("avx2")]] inline __m256d box_distance2_avx2(__m256d x, __m256d y, __m256d z, const Aabb& box) {
  const __m256d gx = box_gap_avx2(x, box.min.x(), box.max.x());
  const __m256d gy = box_gap_avx2(y, box.min.y(), box.max.y());
  const __m256d gz = box_gap_avx2(z, box.min.z(), box.max.z());
  return _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(gx, gx), _mm256_mul_pd(gy, gy)), _mm256_mul_pd(gz, gz));
}
}  // namespace

[[gnu::target("avx2")]] std::uint64_t boxes_reach_avx2(const double* d, const double* need, const double* px,
                                                        const double* py, const double* pz, int n, const Aabb& box,
                                                        bool inner, double floor) {
  const __m256d fl = _mm256_set1_pd(floor), zero = _mm256_setzero_pd();
  std::uint64_t bits = 0;
  int b = 0;
  for (; b + 4 <= n; b += 4) {
    const __m256d db = _mm256_loadu_pd(d + b);
    // (min(d, need) as planes_below takes it; inner: min(thr, 0.0) is
    // (0 < thr ? 0 : thr), _mm256_min_pd(zero, thr).)
    __m256d lim = _mm256_min_pd(_mm256_loadu_pd(need + b), db);
    if (inner) lim = _mm256_min_pd(zero, lim);
    const __m256d b2 = box_distance2_avx2(_mm256_loadu_pd(px + b), _mm256_loadu_pd(py + b), _mm256_loadu_pd(pz + b), box);
    // passed over: b2 > 0 && (lim <= 0 || b2 >= lim * lim); or d <= floor
    const __m256d far = _mm256_or_pd(_mm256_cmp_pd(lim, zero, _CMP_LE_OQ),
                                     _mm256_cmp_pd(b2, _mm256_mul_pd(lim, lim), _CMP_GE_OQ));
    const __m256d over = _mm256_or_pd(_mm256_cmp_pd(db, fl, _CMP_LE_OQ),
                                      _mm256_and_pd(_mm256_cmp_pd(b2, zero, _CMP_GT_OQ), far));
    bits |= static_cast<std::uint64_t>(~_mm256_movemask_pd(over) & 0xf) << b;
  }
  return bits | boxes_reach_scalar(d, need, px, py, pz, b, n, box, inner, floor);
}
#else
std::uint64_t boxes_reach_avx2(const double* d, const double* need, const double* px, const double* py,
                               const double* pz, int n, const Aabb& box, bool inner, double floor) {
  return boxes_reach_scalar(d, need, px, py, pz, 0, n, box, inner, floor);
}
#endif

std::uint64_t boxes_reach(const double* d, const double* need, const double* px, const double* py, const double* pz,
                          int n, const Aabb& box, bool inner, double floor) {
  if (use_avx2()) return boxes_reach_avx2(d, need, px, py, pz, n, box, inner, floor);
  return boxes_reach_scalar(d, need, px, py, pz, 0, n, box, inner, floor);
}

// The pieces a quarter of a leaf takes, of the leaf's convex ones: the
// test the stock update made piece by piece per quarter (its branches
// were some 6 % of raster40k's simulation, a leaf's 8 quarters each
// testing some 19 ball lines). The tests of a piece do not depend on the
// others, so AVX2 takes four at a time, to the same values.
int quarter_pieces_scalar(const LeafPieces& f, int from, int n, const QuarterAt& q, double* seed,
                          std::pair<double, std::uint32_t>* out, int* least) {
  const Vec3 c(q.cx, q.cy, q.cz);
  const double reach = q.need_max + q.hd;
  int m = 0;
  *least = 0;
  for (int k = from; k < n; ++k) {
    if (f.key[k] - q.oc - q.hd >= q.need_max) break;  // and every piece after it
    const Aabb box{Vec3(f.lox[k], f.loy[k], f.loz[k]), Vec3(f.hix[k], f.hiy[k], f.hiz[k])};
    const double b2 = sweep::detail::box_distance2(box, c);
    if (b2 > 0 && (reach <= 0 || b2 >= reach * reach)) continue;
    const double dk = f.key[k] + (f.gx[k] * q.rx + f.gy[k] * q.ry + f.gz[k] * q.rz);
    if (dk - q.hq * f.g1[k] >= q.need_max) continue;
    seed[k] = dk;
    const double key = dk > 0 || f.clip[k] != 0 ? dk : -std::numeric_limits<double>::infinity();
    if (key - q.hd >= q.need_max) continue;
    if (m > 0 && key < out[*least].first) *least = m;  // (k rises: the first of equal keys is least)
    out[m++] = {key, static_cast<std::uint32_t>(k)};
  }
  return m;
}

#if defined(__x86_64__)
namespace {
// std::max(std::max(lo - p, p - hi), 0.0) for four boxes and one point:
// the gap along one axis (sweep::detail::box_distance2).
[[gnu::target("avx2")]] inline __m256d boxes_gap_avx2(__m256d lo, __m256d hi, __m256d p) {
  return std_max_avx2(std_max_avx2(_mm256_sub_pd(lo, p), _mm256_sub_pd(p, hi)), _mm256_setzero_pd());
}
}  // namespace

[[gnu::target("avx2")]] int quarter_pieces_avx2(const LeafPieces& f, int n, const QuarterAt& q, double* seed,
                                                std::pair<double, std::uint32_t>* out, int* least) {
  const __m256d zero = _mm256_setzero_pd(), ninf = _mm256_set1_pd(-std::numeric_limits<double>::infinity());
  const __m256d oc = _mm256_set1_pd(q.oc), hd = _mm256_set1_pd(q.hd), need = _mm256_set1_pd(q.need_max),
                hq = _mm256_set1_pd(q.hq);
  const __m256d cx = _mm256_set1_pd(q.cx), cy = _mm256_set1_pd(q.cy), cz = _mm256_set1_pd(q.cz);
  const __m256d rx = _mm256_set1_pd(q.rx), ry = _mm256_set1_pd(q.ry), rz = _mm256_set1_pd(q.rz);
  const double reach = q.need_max + q.hd;
  const __m256d reach_none = reach <= 0 ? _mm256_castsi256_pd(_mm256_set1_epi64x(-1)) : zero;
  const __m256d reach2 = _mm256_set1_pd(reach * reach);
  int m = 0, k = 0;
  double low = std::numeric_limits<double>::infinity();  // out[best].first, once m > 0
  int best = 0;
  bool stopped = false;
  for (; k + 4 <= n; k += 4) {
    const __m256d key = _mm256_loadu_pd(f.key + k);
    const int stop = _mm256_movemask_pd(_mm256_cmp_pd(_mm256_sub_pd(_mm256_sub_pd(key, oc), hd), need, _CMP_GE_OQ));
    const __m256d gx = boxes_gap_avx2(_mm256_loadu_pd(f.lox + k), _mm256_loadu_pd(f.hix + k), cx);
    const __m256d gy = boxes_gap_avx2(_mm256_loadu_pd(f.loy + k), _mm256_loadu_pd(f.hiy + k), cy);
    const __m256d gz = boxes_gap_avx2(_mm256_loadu_pd(f.loz + k), _mm256_loadu_pd(f.hiz + k), cz);
    const __m256d b2 = _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(gx, gx), _mm256_mul_pd(gy, gy)), _mm256_mul_pd(gz, gz));
    // b2 > 0 && (reach <= 0 || b2 >= reach^2)
    __m256d over = _mm256_and_pd(_mm256_cmp_pd(b2, zero, _CMP_GT_OQ),
                                 _mm256_or_pd(reach_none, _mm256_cmp_pd(b2, reach2, _CMP_GE_OQ)));
    const __m256d dot = _mm256_add_pd(
        _mm256_add_pd(_mm256_mul_pd(_mm256_loadu_pd(f.gx + k), rx), _mm256_mul_pd(_mm256_loadu_pd(f.gy + k), ry)),
        _mm256_mul_pd(_mm256_loadu_pd(f.gz + k), rz));
    const __m256d dk = _mm256_add_pd(key, dot);
    over = _mm256_or_pd(
        over, _mm256_cmp_pd(_mm256_sub_pd(dk, _mm256_mul_pd(hq, _mm256_loadu_pd(f.g1 + k))), need, _CMP_GE_OQ));
    _mm256_storeu_pd(seed + k, dk);
    const __m256d keep = _mm256_or_pd(_mm256_cmp_pd(dk, zero, _CMP_GT_OQ),
                                      _mm256_cmp_pd(_mm256_loadu_pd(f.clip + k), zero, _CMP_NEQ_OQ));
    const __m256d bk = _mm256_blendv_pd(ninf, dk, keep);
    over = _mm256_or_pd(over, _mm256_cmp_pd(_mm256_sub_pd(bk, hd), need, _CMP_GE_OQ));
    int take = ~_mm256_movemask_pd(over) & 0xf;
    if (stop != 0) take &= (1 << std::countr_zero(static_cast<unsigned>(stop))) - 1;
    if (take != 0) {
      alignas(32) double kv[4];
      _mm256_store_pd(kv, bk);
      for (; take != 0; take &= take - 1) {
        const int i = std::countr_zero(static_cast<unsigned>(take));
        if (m == 0 || kv[i] < low) {
          low = kv[i];
          best = m;
        }
        out[m++] = {kv[i], static_cast<std::uint32_t>(k + i)};
      }
    }
    if (stop != 0) {
      stopped = true;
      break;
    }
  }
  int tail_least = 0;
  const int tail = stopped ? 0 : quarter_pieces_scalar(f, k, n, q, seed, out + m, &tail_least);
  if (tail > 0 && (m == 0 || out[m + tail_least].first < low)) best = m + tail_least;
  *least = best;
  return m + tail;
}
#else
int quarter_pieces_avx2(const LeafPieces& f, int n, const QuarterAt& q, double* seed, std::pair<double, std::uint32_t>* out,
                        int* least) {
  return quarter_pieces_scalar(f, 0, n, q, seed, out, least);
}
#endif

int quarter_pieces(const LeafPieces& f, int n, const QuarterAt& q, double* seed, std::pair<double, std::uint32_t>* out,
                   int* least) {
  if (use_avx2()) return quarter_pieces_avx2(f, n, q, seed, out, least);
  return quarter_pieces_scalar(f, 0, n, q, seed, out, least);
}

// The voxels of a quarter a piece may lower, by the bounds that need no
// distance: the piece's key at the quarter's centre less the voxel's
// offset, and a profile prism's section plane. Neither depends on the
// other voxels, so they are taken for the whole quarter before the loop
// over the voxels that pass: four at a time with AVX2. (Voxel by voxel,
// the loop and these tests were a third of the snowflake's one-piece
// quarters.)
std::uint64_t quarter_reach_scalar(const float* data, int first, float gamma, double key, const double* off,
                                   bool inner, const sweep::SectionPlane* sec, const double* yx, const double* yy,
                                   const double* yz) {
  std::uint64_t bits = 0;
  for (int q = 0; q < 64; ++q) {
    const float v = data[first + ((q >> 4) << 6) + (((q >> 2) & 3) << 3) + (q & 3)];
    if (v >= gamma) continue;
    const double need = inner ? std::min(-static_cast<double>(v), 0.0) : -static_cast<double>(v);
    const auto i = static_cast<std::size_t>(q);
    if (key - off[i] >= need) continue;
    if (sec && sweep::section_bound(*sec, Vec3(yx[i], yy[i], yz[i])) >= need) continue;
    bits |= std::uint64_t(1) << q;
  }
  return bits;
}

#if defined(__x86_64__)
namespace {
// (a x + b y) + c z, as Eigen's dot of (a, b, c) with (x, y, z) sums.
[[gnu::target("avx2")]] inline __m256d dot_avx2(const Vec3& g, __m256d x, __m256d y, __m256d z) {
  return _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(_mm256_set1_pd(g.x()), x), _mm256_mul_pd(_mm256_set1_pd(g.y()), y)),
                       _mm256_mul_pd(_mm256_set1_pd(g.z()), z));
}
}  // namespace

[[gnu::target("avx2")]] std::uint64_t quarter_reach_avx2(const float* data, int first, float gamma, double key,
                                                          const double* off, bool inner, const sweep::SectionPlane* sec,
                                                          const double* yx, const double* yy, const double* yz) {
  const __m256d zero = _mm256_setzero_pd(), kv = _mm256_set1_pd(key);
  const __m128 gm = _mm_set1_ps(gamma);
  std::uint64_t bits = 0;
  for (int row = 0; row < 16; ++row) {
    const int q = 4 * row;
    const __m128 vf = _mm_loadu_ps(data + first + ((row >> 2) << 6) + ((row & 3) << 3));
    // material: not v >= gamma (in floats, as the scalar test)
    const int material = ~_mm_movemask_ps(_mm_cmp_ps(vf, gm, _CMP_GE_OQ)) & 0xf;
    if (material == 0) continue;
    __m256d need = _mm256_xor_pd(_mm256_cvtps_pd(vf), _mm256_set1_pd(-0.0));
    if (inner) need = _mm256_min_pd(zero, need);  // std::min(-v, 0.0)
    __m256d over = _mm256_cmp_pd(_mm256_sub_pd(kv, _mm256_loadu_pd(off + q)), need, _CMP_GE_OQ);
    if (sec) {
      const __m256d x = _mm256_loadu_pd(yx + q), y = _mm256_loadu_pd(yy + q), z = _mm256_loadu_pd(yz + q);
      // sweep::section_bound
      const __m256d px = _mm256_add_pd(_mm256_set1_pd(sec->px), dot_avx2(sec->axis, x, y, z));
      const __m256d a = _mm256_add_pd(_mm256_set1_pd(sec->c), dot_avx2(sec->g, x, y, z));
      const __m256d b = std_max_avx2(_mm256_sub_pd(_mm256_set1_pd(sec->lo), px), _mm256_sub_pd(px, _mm256_set1_pd(sec->hi)));
      const __m256d fmin = _mm256_set1_pd(sec->f_min);
      const __m256d past = std_max_avx2(b, _mm256_mul_pd(fmin, _mm256_sub_pd(a, _mm256_mul_pd(b, _mm256_set1_pd(sec->shear)))));
      const __m256d within = _mm256_blendv_pd(std_max_avx2(a, b), _mm256_mul_pd(fmin, a), _mm256_cmp_pd(a, zero, _CMP_GE_OQ));
      const __m256d bound = _mm256_blendv_pd(within, past, _mm256_cmp_pd(b, zero, _CMP_GT_OQ));
      over = _mm256_or_pd(over, _mm256_cmp_pd(bound, need, _CMP_GE_OQ));
    }
    bits |= static_cast<std::uint64_t>(material & ~_mm256_movemask_pd(over) & 0xf) << q;
  }
  return bits;
}
#else
std::uint64_t quarter_reach_avx2(const float* data, int first, float gamma, double key, const double* off, bool inner,
                                 const sweep::SectionPlane* sec, const double* yx, const double* yy, const double* yz) {
  return quarter_reach_scalar(data, first, gamma, key, off, inner, sec, yx, yy, yz);
}
#endif

std::uint64_t quarter_reach(const float* data, int first, float gamma, double key, const double* off, bool inner,
                            const sweep::SectionPlane* sec, const double* yx, const double* yy, const double* yz) {
  if (use_avx2()) return quarter_reach_avx2(data, first, gamma, key, off, inner, sec, yx, yy, yz);
  return quarter_reach_scalar(data, first, gamma, key, off, inner, sec, yx, yy, yz);
}

// The contact check's voxels of a quarter that may be deeper than the
// deepest overlap so far: material, then the region's plane. Per voxel in
// its loop, these two tests were a third of the contact scan's own time on
// the snowflake; the loop now runs over the bits this leaves.
std::uint64_t overlap_candidates_scalar(const float* data, int first, double floor, const CentrePlane* pl, double h) {
  std::uint64_t bits = 0;
  for (int q = 0; q < 64; ++q) {
    const int x = q >> 4, y = (q >> 2) & 3, z = q & 3;
    bool keep = -static_cast<double>(data[first + (x << 6) + (y << 3) + z]) > floor;
    if (keep && pl) {
      const double yx = quarter_offset(x, h), yy = quarter_offset(y, h), yz = quarter_offset(z, h);
      keep = -(pl->c + (pl->gx * yx + pl->gy * yy + pl->gz * yz)) > floor;
    }
    bits |= std::uint64_t(keep) << q;
  }
  return bits;
}

#if defined(__x86_64__)
[[gnu::target("avx2")]] std::uint64_t overlap_candidates_avx2(const float* data, int first, double floor,
                                                               const CentrePlane* pl, double h) {
  const __m256d fl = _mm256_set1_pd(floor), neg = _mm256_set1_pd(-0.0);
  const __m256d yz = _mm256_setr_pd(quarter_offset(0, h), quarter_offset(1, h), quarter_offset(2, h), quarter_offset(3, h));
  std::uint64_t bits = 0;
  for (int row = 0; row < 16; ++row) {
    const int x = row >> 2, y = row & 3;
    const __m256d v = _mm256_cvtps_pd(_mm_loadu_ps(data + first + (x << 6) + (y << 3)));
    __m256d keep = _mm256_cmp_pd(_mm256_xor_pd(v, neg), fl, _CMP_GT_OQ);
    int m = _mm256_movemask_pd(keep);
    if (m && pl) {
      const __m256d t = _mm256_add_pd(_mm256_set1_pd(pl->gx * quarter_offset(x, h) + pl->gy * quarter_offset(y, h)),
                                      _mm256_mul_pd(_mm256_set1_pd(pl->gz), yz));
      const __m256d below = _mm256_xor_pd(_mm256_add_pd(_mm256_set1_pd(pl->c), t), neg);
      m &= _mm256_movemask_pd(_mm256_cmp_pd(below, fl, _CMP_GT_OQ));
    }
    bits |= static_cast<std::uint64_t>(m) << (4 * row);
  }
  return bits;
}
#else
std::uint64_t overlap_candidates_avx2(const float* data, int first, double floor, const CentrePlane* pl, double h) {
  return overlap_candidates_scalar(data, first, floor, pl, h);
}
#endif

std::uint64_t overlap_candidates(const float* data, int first, double floor, const CentrePlane* pl, double h) {
  if (use_avx2()) return overlap_candidates_avx2(data, first, floor, pl, h);
  return overlap_candidates_scalar(data, first, floor, pl, h);
}

// A profile prism's distances (sweep::detail::prism_distance) at a
// quarter's voxels. With AVX2, four at a time: both of the profile's cases
// (nearest the nose's centre, or a side face) and both of the length's
// (within it or past an end) worked out and the right one picked, in the
// portable version's operations, so each distance is the same to the bit.
// (A V tool's prisms are most of the snowflake's one-piece quarters, and
// their distances a third of that loop.)
void prism_distances_scalar(const sweep::ProfilePrim& pp, int from, int n, const double* px, const double* py,
                            const double* pz, double* out) {
  for (int i = from; i < n; ++i) out[i] = sweep::detail::prism_distance(pp, Vec3(px[i], py[i], pz[i]));
}

#if defined(__x86_64__)
namespace {

// sweep::detail::prism_section on four points (y, z) in a prism's plane:
// the profile's two cases (nearest the nose's centre, or a side face) each
// worked out where one of the four needs it and the right one picked,
// with the lean's factors of the move `d` (f_side, f_top: the piece's).
[[gnu::target("avx2")]] inline __m256d prism_section_avx2(const tool::EdgeProfile& e, double sin_half, double cos_half,
                                                          const Vec3& d, const double (&f_side)[2], double f_top,
                                                          __m256d y, __m256d z) {
  const __m256d zero = _mm256_setzero_pd();
  const __m256d sb = _mm256_set1_pd(sin_half), cb = _mm256_set1_pd(cos_half), nose = _mm256_set1_pd(e.nose_radius);
  const __m256d a = abs_avx2(y), b = _mm256_sub_pd(z, nose);
  const __m256d round = _mm256_cmp_pd(_mm256_add_pd(_mm256_mul_pd(a, sb), _mm256_mul_pd(b, cb)), zero, _CMP_LE_OQ);
  __m256d af;
  {
    // A side face: (r - nose) f_side[y < 0]
    const __m256d r = _mm256_sub_pd(_mm256_mul_pd(a, cb), _mm256_mul_pd(b, sb));
    const __m256d f = _mm256_blendv_pd(_mm256_set1_pd(f_side[0]), _mm256_set1_pd(f_side[1]), _mm256_cmp_pd(y, zero, _CMP_LT_OQ));
    af = _mm256_mul_pd(_mm256_sub_pd(r, nose), f);
  }
  if (_mm256_movemask_pd(round)) {
    // Nearest the nose's centre: r = hypot2(a, b), factor ax r / hypot2(ax r, y d.y + b d.z)
    // (where r = 0: prism_factor(ax, -d.z), the piece's)
    const __m256d ax = _mm256_set1_pd(std::fabs(d.x()));
    const __m256d r = _mm256_sqrt_pd(_mm256_add_pd(_mm256_mul_pd(a, a), _mm256_mul_pd(b, b)));
    const __m256d t1 = _mm256_mul_pd(ax, r);
    const __m256d t2 = _mm256_add_pd(_mm256_mul_pd(y, _mm256_set1_pd(d.y())), _mm256_mul_pd(b, _mm256_set1_pd(d.z())));
    const __m256d h = _mm256_sqrt_pd(_mm256_add_pd(_mm256_mul_pd(t1, t1), _mm256_mul_pd(t2, t2)));
    const __m256d f_axis = _mm256_set1_pd(sweep::detail::prism_factor(std::fabs(d.x()), -d.z()));
    const __m256d f = _mm256_blendv_pd(f_axis, _mm256_div_pd(t1, h), _mm256_cmp_pd(r, zero, _CMP_GT_OQ));
    af = _mm256_blendv_pd(af, _mm256_mul_pd(_mm256_sub_pd(r, nose), f), round);
  }
  return std_max_avx2(af, _mm256_mul_pd(_mm256_sub_pd(z, _mm256_set1_pd(e.height)), _mm256_set1_pd(f_top)));
}

// sweep::detail::prism_sd(a, b): the hypot of the positive parts plus min(max(a, b), 0).
[[gnu::target("avx2")]] inline __m256d prism_sd_avx2(__m256d a, __m256d b) {
  const __m256d zero = _mm256_setzero_pd();
  const __m256d ao = std_max_avx2(a, zero), bo = std_max_avx2(b, zero);
  return _mm256_add_pd(_mm256_sqrt_pd(_mm256_add_pd(_mm256_mul_pd(ao, ao), _mm256_mul_pd(bo, bo))),
                       std_min_avx2(std_max_avx2(a, b), zero));
}

// sweep::detail::prism_distance at four world points.
[[gnu::target("avx2")]] inline __m256d prism_distance_avx2(const sweep::ProfilePrim& pp, __m256d wx, __m256d wy, __m256d wz) {
  const Eigen::Matrix3d& m = pp.to_local;
  const Vec3& d = pp.d_local;
  const __m256d zero = _mm256_setzero_pd(), one = _mm256_set1_pd(1.0);
  // sweep::detail::to_frame
  const __m256d rx = _mm256_sub_pd(wx, _mm256_set1_pd(pp.origin.x())), ry = _mm256_sub_pd(wy, _mm256_set1_pd(pp.origin.y())),
                rz = _mm256_sub_pd(wz, _mm256_set1_pd(pp.origin.z()));
  const __m256d qx = frame_row_avx2(m, 0, rx, ry, rz), qy = frame_row_avx2(m, 1, rx, ry, rz),
                qz = frame_row_avx2(m, 2, rx, ry, rz);
  // s = clamp01(px inv_dx): 0 below 0, 1 above 1, else t
  __m256d s = _mm256_mul_pd(qx, _mm256_set1_pd(pp.inv_dx));
  s = _mm256_blendv_pd(s, one, _mm256_cmp_pd(s, one, _CMP_GT_OQ));
  s = _mm256_blendv_pd(s, zero, _mm256_cmp_pd(s, zero, _CMP_LT_OQ));
  const __m256d y = _mm256_sub_pd(qy, _mm256_mul_pd(s, _mm256_set1_pd(d.y()))),
                z = _mm256_sub_pd(qz, _mm256_mul_pd(s, _mm256_set1_pd(d.z())));
  const __m256d sec = prism_section_avx2(pp.edge, pp.sin_half, pp.cos_half, d, pp.f_side, pp.f_top, y, z);
  // The way past the nearer end along the move.
  const __m256d dxv = _mm256_set1_pd(d.x());
  const __m256d along = d.x() > 0 ? std_max_avx2(_mm256_xor_pd(qx, _mm256_set1_pd(-0.0)), _mm256_sub_pd(qx, dxv))
                                  : std_max_avx2(qx, _mm256_sub_pd(dxv, qx));
  const __m256d inside_min = std_min_avx2(std_max_avx2(sec, along), zero);
  // Within the length (and not a tiny positive a): max(a, 0) + min(max(a, b), 0)
  const __m256d pos = _mm256_cmp_pd(sec, zero, _CMP_GT_OQ);
  const __m256d short_way = _mm256_andnot_pd(_mm256_and_pd(pos, _mm256_cmp_pd(sec, _mm256_set1_pd(1e-150), _CMP_LT_OQ)),
                                             _mm256_cmp_pd(along, zero, _CMP_LE_OQ));
  const __m256d within = _mm256_add_pd(_mm256_blendv_pd(zero, sec, pos), inside_min);
  // Else prism_sd(a, b).
  __m256d r = _mm256_blendv_pd(prism_sd_avx2(sec, along), within, short_way);
  // Outside, no less than the way to the piece's box.
  const __m256d outside = _mm256_cmp_pd(r, zero, _CMP_GT_OQ);
  if (_mm256_movemask_pd(outside)) {
    const __m256d b2 = box_distance2_avx2(wx, wy, wz, pp.bounds);
    const __m256d farther = _mm256_and_pd(outside, _mm256_cmp_pd(b2, _mm256_mul_pd(r, r), _CMP_GT_OQ));
    r = _mm256_blendv_pd(r, _mm256_sqrt_pd(b2), farther);
  }
  return r;
}

// Up to four of the voxels in `bits` (taken from it), their places in
// `at` (the last repeated to fill four) and their centres.
struct Gathered {
  std::array<std::size_t, 4> at;
  std::size_t n = 0;
  __m256d x, y, z;
};
[[gnu::target("avx2")]] inline Gathered gather4(std::uint64_t& bits, const double* px, const double* py, const double* pz) {
  Gathered g;
  for (; bits != 0 && g.n < 4; bits &= bits - 1) g.at[g.n++] = static_cast<std::size_t>(std::countr_zero(bits));
  for (std::size_t j = g.n; j < 4; ++j) g.at[j] = g.at[g.n - 1];  // (repeats: the same value again)
  g.x = _mm256_set_pd(px[g.at[3]], px[g.at[2]], px[g.at[1]], px[g.at[0]]);
  g.y = _mm256_set_pd(py[g.at[3]], py[g.at[2]], py[g.at[1]], py[g.at[0]]);
  g.z = _mm256_set_pd(pz[g.at[3]], pz[g.at[2]], pz[g.at[1]], pz[g.at[0]]);
  return g;
}

}  // namespace

[[gnu::target("avx2")]] void prism_distances_avx2(const sweep::ProfilePrim& pp, int n, const double* px,
                                                  const double* py, const double* pz, double* out) {
  int i = 0;
  for (; i + 4 <= n; i += 4)
    _mm256_storeu_pd(out + i, prism_distance_avx2(pp, _mm256_loadu_pd(px + i), _mm256_loadu_pd(py + i), _mm256_loadu_pd(pz + i)));
  prism_distances_scalar(pp, i, n, px, py, pz, out);
}
#else
void prism_distances_avx2(const sweep::ProfilePrim& pp, int n, const double* px, const double* py, const double* pz,
                          double* out) {
  prism_distances_scalar(pp, 0, n, px, py, pz, out);
}
#endif

void prism_distances(const sweep::ProfilePrim& pp, int n, const double* px, const double* py, const double* pz,
                     double* out) {
  if (use_avx2()) prism_distances_avx2(pp, n, px, py, pz, out);
  else prism_distances_scalar(pp, 0, n, px, py, pz, out);
}

// A profile prism, or a joint, lowering the nearest distance so far at
// the bars in `bits` (the stock update's pieces that are 1-Lipschitz, where
// no plane bounds them). With AVX2 four at a time, each distance in the
// portable version's operations, so each value is the same to the bit. A
// joint's four stop once a part has reached every one's limit, where the
// portable version stops at each voxel's own: a voxel past its limit then
// keeps a bound (from fewer parts, or the whole distance), which it does
// not take either way.
void lower_by_prism_scalar(const sweep::ProfilePrim& pp, std::uint64_t bits, const double* px, const double* py,
                           const double* pz, double* d) {
  for (; bits != 0; bits &= bits - 1) {
    const auto b = static_cast<std::size_t>(std::countr_zero(bits));
    d[b] = std::min(d[b], sweep::detail::prism_distance(pp, Vec3(px[b], py[b], pz[b])));
  }
}

void lower_by_joint_scalar(const sweep::JointPrim& jp, std::uint64_t bits, const double* px, const double* py,
                           const double* pz, const double* need, double* d) {
  for (; bits != 0; bits &= bits - 1) {
    const auto b = static_cast<std::size_t>(std::countr_zero(bits));
    const double lim = std::min(std::min(d[b], need[b]), 0.0);
    const double dj = sweep::detail::joint_distance_below(jp, Vec3(px[b], py[b], pz[b]), lim);
    if (dj < lim) d[b] = dj;  // (else only a bound)
  }
}

#if defined(__x86_64__)
namespace {

// sweep::detail::joint_part on four points.
[[gnu::target("avx2")]] inline __m256d joint_part_avx2(const sweep::JointPrim& jp, const sweep::JointPrim::Side& sd,
                                                       __m256d wx, __m256d wy, __m256d wz, bool start_cap, bool end_cap) {
  const Eigen::Matrix3d& m = jp.to_local;
  const __m256d rx = _mm256_sub_pd(wx, _mm256_set1_pd(sd.origin.x())), ry = _mm256_sub_pd(wy, _mm256_set1_pd(sd.origin.y())),
                rz = _mm256_sub_pd(wz, _mm256_set1_pd(sd.origin.z()));
  const __m256d x = frame_row_avx2(m, 0, rx, ry, rz), y = frame_row_avx2(m, 1, rx, ry, rz), z = frame_row_avx2(m, 2, rx, ry, rz);
  __m256d s = _mm256_mul_pd(x, _mm256_set1_pd(sd.inv_dx));
  if (start_cap) s = std_max_avx2(s, _mm256_setzero_pd());
  if (end_cap) s = std_min_avx2(s, _mm256_set1_pd(1.0));
  const __m256d a = prism_section_avx2(jp.edge, jp.sin_half, jp.cos_half, sd.d, sd.f_side, sd.f_top,
                                       _mm256_sub_pd(y, _mm256_mul_pd(s, _mm256_set1_pd(sd.d.y()))),
                                       _mm256_sub_pd(z, _mm256_mul_pd(s, _mm256_set1_pd(sd.d.z()))));
  if (!start_cap && !end_cap) return a;
  const __m256d start = _mm256_mul_pd(_mm256_set1_pd(-jp.sign), x);
  const __m256d end = _mm256_mul_pd(_mm256_set1_pd(jp.sign), _mm256_sub_pd(x, _mm256_set1_pd(sd.d.x())));
  const __m256d b = start_cap && end_cap ? std_max_avx2(start, end) : start_cap ? start : end;
  return prism_sd_avx2(a, b);
}

// Whether every one of four values is at or above its limit (none below).
[[gnu::target("avx2")]] inline bool none_below_avx2(__m256d v, __m256d lim) {
  return _mm256_movemask_pd(_mm256_cmp_pd(v, lim, _CMP_LT_OQ)) == 0;
}

// sweep::detail::joint_distance_below on four points, each with its
// limit: where every one has reached its limit, what the parts so far
// give (the portable version's bound; it stops at once where it has
// reached it, so a point that reaches it earlier may have a lower bound
// here, but no less than its limit), else the whole distance.
[[gnu::target("avx2")]] inline __m256d joint_distance_avx2(const sweep::JointPrim& jp, __m256d wx, __m256d wy, __m256d wz,
                                                           __m256d lim) {
  const Aabb& bx = jp.bounds;
  const __m256d om = std_max_avx2(
      std_max_avx2(std_max_avx2(_mm256_sub_pd(_mm256_set1_pd(bx.min.x()), wx), _mm256_sub_pd(wx, _mm256_set1_pd(bx.max.x()))),
                   std_max_avx2(_mm256_sub_pd(_mm256_set1_pd(bx.min.y()), wy), _mm256_sub_pd(wy, _mm256_set1_pd(bx.max.y())))),
      std_max_avx2(_mm256_sub_pd(_mm256_set1_pd(bx.min.z()), wz), _mm256_sub_pd(wz, _mm256_set1_pd(bx.max.z()))));
  __m256d g = om;
  const __m256d out = _mm256_cmp_pd(om, _mm256_setzero_pd(), _CMP_GT_OQ);  // (not om <= 0)
  if (_mm256_movemask_pd(out)) g = _mm256_blendv_pd(om, _mm256_sqrt_pd(box_distance2_avx2(wx, wy, wz, bx)), out);
  const __m256d rx = _mm256_sub_pd(wx, _mm256_set1_pd(jp.mid.origin.x())),
                ry = _mm256_sub_pd(wy, _mm256_set1_pd(jp.mid.origin.y())),
                rz = _mm256_sub_pd(wz, _mm256_set1_pd(jp.mid.origin.z()));
  const __m256d along = _mm256_mul_pd(_mm256_set1_pd(jp.sign), frame_row_avx2(jp.to_local, 0, rx, ry, rz));
  g = std_max_avx2(g, std_max_avx2(_mm256_sub_pd(_mm256_set1_pd(jp.slab_lo), along),
                                   _mm256_sub_pd(along, _mm256_set1_pd(jp.slab_hi))));  // the slab
  if (none_below_avx2(g, lim)) return g;
  if (jp.crest) {
    // max(g, min(a, after)) is g where a <= g (the portable version's early return).
    const __m256d a = joint_part_avx2(jp, jp.mid, wx, wy, wz, true, false);
    if (none_below_avx2(g, a)) return g;  // (a <= g everywhere)
    return std_max_avx2(g, std_min_avx2(a, joint_part_avx2(jp, jp.after, wx, wy, wz, false, true)));
  }
  g = std_max_avx2(g, joint_part_avx2(jp, jp.mid, wx, wy, wz, !jp.has_before, !jp.has_after));
  if (none_below_avx2(g, lim)) return g;
  if (jp.has_before) g = std_max_avx2(g, joint_part_avx2(jp, jp.before, wx, wy, wz, true, false));
  if (jp.has_after) g = std_max_avx2(g, joint_part_avx2(jp, jp.after, wx, wy, wz, false, true));
  return g;
}

}  // namespace

[[gnu::target("avx2")]] void lower_by_prism_avx2(const sweep::ProfilePrim& pp, std::uint64_t bits, const double* px,
                                                 const double* py, const double* pz, double* d) {
  while (bits != 0) {
    const Gathered w = gather4(bits, px, py, pz);
    std::array<double, 4> dist;
    _mm256_storeu_pd(dist.data(), prism_distance_avx2(pp, w.x, w.y, w.z));
    for (std::size_t j = 0; j < w.n; ++j) d[w.at[j]] = std::min(d[w.at[j]], dist[j]);
  }
}

[[gnu::target("avx2")]] void lower_by_joint_avx2(const sweep::JointPrim& jp, std::uint64_t bits, const double* px,
                                                 const double* py, const double* pz, const double* need, double* d) {
  while (bits != 0) {
    const Gathered w = gather4(bits, px, py, pz);
    std::array<double, 4> lim, dist;
    for (std::size_t j = 0; j < 4; ++j) lim[j] = std::min(std::min(d[w.at[j]], need[w.at[j]]), 0.0);
    _mm256_storeu_pd(dist.data(), joint_distance_avx2(jp, w.x, w.y, w.z, _mm256_loadu_pd(lim.data())));
    for (std::size_t j = 0; j < w.n; ++j)
      if (dist[j] < lim[j]) d[w.at[j]] = dist[j];
  }
}
#else
void lower_by_prism_avx2(const sweep::ProfilePrim& pp, std::uint64_t bits, const double* px, const double* py,
                         const double* pz, double* d) {
  lower_by_prism_scalar(pp, bits, px, py, pz, d);
}
void lower_by_joint_avx2(const sweep::JointPrim& jp, std::uint64_t bits, const double* px, const double* py,
                         const double* pz, const double* need, double* d) {
  lower_by_joint_scalar(jp, bits, px, py, pz, need, d);
}
#endif

void lower_by_prism(const sweep::ProfilePrim& pp, std::uint64_t bits, const double* px, const double* py,
                    const double* pz, double* d) {
  if (use_avx2()) lower_by_prism_avx2(pp, bits, px, py, pz, d);
  else lower_by_prism_scalar(pp, bits, px, py, pz, d);
}

void lower_by_joint(const sweep::JointPrim& jp, std::uint64_t bits, const double* px, const double* py,
                    const double* pz, const double* need, double* d) {
  if (use_avx2()) lower_by_joint_avx2(jp, bits, px, py, pz, need, d);
  else lower_by_joint_scalar(jp, bits, px, py, pz, need, d);
}

// A ball end's line (sweep::detail::ball_line_distance) lowering the
// nearest distance so far, d[b] = min(d[b], distance at (px, py, pz)[b]),
// at the bars in `bits`. With AVX2, four at a time: each case of the
// parallelogram that one of the four needs worked out and the right one
// picked, in the portable version's operations, so each distance is the
// same to the bit. (The distances were a third of raster40k's voxel step.)
void lower_by_ball_line_scalar(const sweep::LinearPrim& lp, std::uint64_t bits, const double* px, const double* py,
                               const double* pz, double* d) {
  for (; bits != 0; bits &= bits - 1) {
    const auto b = static_cast<std::size_t>(std::countr_zero(bits));
    d[b] = std::min(d[b], sweep::detail::ball_line_distance(lp, Vec3(px[b], py[b], pz[b])));
  }
}

#if defined(__x86_64__)
namespace {

struct Off4 {
  __m256d x, y, z;
};

// sweep::detail::seg_offset_inv's squared length, on four points.
[[gnu::target("avx2")]] inline __m256d seg_offset_inv2_avx2(const Off4& p, double ax, double ay, double az, double abx,
                                                            double aby, double abz, double inv_l2) {
  const __m256d pax = _mm256_sub_pd(p.x, _mm256_set1_pd(ax)), pay = _mm256_sub_pd(p.y, _mm256_set1_pd(ay)),
                paz = _mm256_sub_pd(p.z, _mm256_set1_pd(az));
  const __m256d vx = _mm256_set1_pd(abx), vy = _mm256_set1_pd(aby), vz = _mm256_set1_pd(abz);
  __m256d t = _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(pax, vx), _mm256_mul_pd(pay, vy)), _mm256_mul_pd(paz, vz));
  t = _mm256_mul_pd(t, _mm256_set1_pd(inv_l2));
  // clamp01: 0 below 0, 1 above 1, else t (NaN too)
  t = _mm256_blendv_pd(t, _mm256_set1_pd(1.0), _mm256_cmp_pd(t, _mm256_set1_pd(1.0), _CMP_GT_OQ));
  t = _mm256_blendv_pd(t, _mm256_setzero_pd(), _mm256_cmp_pd(t, _mm256_setzero_pd(), _CMP_LT_OQ));
  const __m256d ox = _mm256_sub_pd(pax, _mm256_mul_pd(t, vx)), oy = _mm256_sub_pd(pay, _mm256_mul_pd(t, vy)),
                oz = _mm256_sub_pd(paz, _mm256_mul_pd(t, vz));
  return _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(ox, ox), _mm256_mul_pd(oy, oy)), _mm256_mul_pd(oz, oz));
}

// v2 where it is valid and less than best (not NaN): the scalar version's
// running least.
[[gnu::target("avx2")]] inline __m256d take_less_avx2(__m256d best, __m256d valid, __m256d v2) {
  return _mm256_min_pd(_mm256_blendv_pd(_mm256_set1_pd(std::numeric_limits<double>::infinity()), v2, valid), best);
}

}  // namespace

[[gnu::target("avx2")]] void lower_by_ball_line_avx2(const sweep::LinearPrim& lp, std::uint64_t bits, const double* px,
                                                     const double* py, const double* pz, double* d) {
  using sweep::LinearPrim;
  const double dx = lp.d_local.x(), dy = lp.d_local.y(), dz = lp.d_local.z(), L = lp.env.core_length;
  const bool vertical = lp.kind == LinearPrim::Case::vertical;
  // (A parallelogram that is a segment: the portable version's division.)
  if (!vertical && lp.inv_lr2 == 0) return lower_by_ball_line_scalar(lp, bits, px, py, pz, d);
  const __m256d zero = _mm256_setzero_pd(), one = _mm256_set1_pd(1.0);
  while (bits != 0) {
    const Gathered w = gather4(bits, px, py, pz);
    // sweep::detail::to_piece
    const __m256d rx = _mm256_sub_pd(w.x, _mm256_set1_pd(lp.origin.x())),
                  ry = _mm256_sub_pd(w.y, _mm256_set1_pd(lp.origin.y())),
                  rz = _mm256_sub_pd(w.z, _mm256_set1_pd(lp.origin.z()));
    Off4 p{rx, ry, rz};
    if (!lp.axis_z) {
      const Eigen::Matrix3d& m = lp.to_local;
      p = {frame_row_avx2(m, 0, rx, ry, rz), frame_row_avx2(m, 1, rx, ry, rz), frame_row_avx2(m, 2, rx, ry, rz)};
    }
    __m256d n2;
    if (vertical) {
      const double z0 = std::min(0.0, dz);
      n2 = seg_offset_inv2_avx2(p, 0, 0, z0, 0, 0, std::max(0.0, dz) + L - z0, lp.inv_span);
    } else {
      // sweep::detail::parallelogram_offset
      const __m256d vdx = _mm256_set1_pd(dx), vdy = _mm256_set1_pd(dy);
      const __m256d ph = _mm256_add_pd(_mm256_mul_pd(p.x, vdx), _mm256_mul_pd(p.y, vdy));
      const __m256d s = _mm256_mul_pd(ph, _mm256_set1_pd(lp.inv_r2));
      const __m256d t = _mm256_mul_pd(_mm256_sub_pd(_mm256_mul_pd(p.z, _mm256_set1_pd(dx * dx + dy * dy)),
                                                    _mm256_mul_pd(ph, _mm256_set1_pd(dz))),
                                      _mm256_set1_pd(lp.inv_lr2));
      const __m256d s_lo = _mm256_cmp_pd(s, zero, _CMP_LT_OQ), s_hi = _mm256_cmp_pd(s, one, _CMP_GT_OQ);
      const __m256d t_lo = _mm256_cmp_pd(t, zero, _CMP_LT_OQ), t_hi = _mm256_cmp_pd(t, one, _CMP_GT_OQ);
      const __m256d inside =
          _mm256_and_pd(_mm256_and_pd(_mm256_cmp_pd(s, zero, _CMP_GE_OQ), _mm256_cmp_pd(s, one, _CMP_LE_OQ)),
                        _mm256_and_pd(_mm256_cmp_pd(t, zero, _CMP_GE_OQ), _mm256_cmp_pd(t, one, _CMP_LE_OQ)));
      // Outside: the least over the edges that count (the others: infinity),
      // each edge worked out only where some point needs it (below a ball
      // end's centre, where it cuts, only the bottom edge).
      const __m256d c3 = _mm256_andnot_pd(_mm256_and_pd(t_lo, _mm256_cmp_pd(p.z, zero, _CMP_LE_OQ)), s_lo);
      const __m256d c4 = _mm256_andnot_pd(_mm256_and_pd(t_lo, _mm256_cmp_pd(p.z, _mm256_set1_pd(dz), _CMP_LE_OQ)), s_hi);
      __m256d best = _mm256_set1_pd(std::numeric_limits<double>::infinity());
      if (_mm256_movemask_pd(t_lo)) best = take_less_avx2(best, t_lo, seg_offset_inv2_avx2(p, 0, 0, 0, dx, dy, dz, lp.inv_dd));
      if (_mm256_movemask_pd(t_hi)) best = take_less_avx2(best, t_hi, seg_offset_inv2_avx2(p, 0, 0, L, dx, dy, dz, lp.inv_dd));
      if (_mm256_movemask_pd(c3)) best = take_less_avx2(best, c3, seg_offset_inv2_avx2(p, 0, 0, 0, 0, 0, L, lp.inv_ll));
      if (_mm256_movemask_pd(c4)) best = take_less_avx2(best, c4, seg_offset_inv2_avx2(p, dx, dy, dz, 0, 0, L, lp.inv_ll));
      n2 = best;
      if (_mm256_movemask_pd(inside)) {
        const __m256d k = _mm256_mul_pd(_mm256_sub_pd(_mm256_mul_pd(p.x, vdy), _mm256_mul_pd(p.y, vdx)), _mm256_set1_pd(lp.inv_r2));
        const __m256d kx = _mm256_mul_pd(k, vdy), ky = _mm256_mul_pd(k, vdx);  // the offset (k dy, -k dx, 0)
        n2 = _mm256_blendv_pd(n2, _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(kx, kx), _mm256_mul_pd(ky, ky)), zero), inside);
      }
    }
    std::array<double, 4> dist;
    _mm256_storeu_pd(dist.data(), _mm256_sub_pd(_mm256_sqrt_pd(n2), _mm256_set1_pd(lp.env.corner_radius)));
    for (std::size_t j = 0; j < w.n; ++j) d[w.at[j]] = std::min(d[w.at[j]], dist[j]);
  }
}
#else
void lower_by_ball_line_avx2(const sweep::LinearPrim& lp, std::uint64_t bits, const double* px, const double* py,
                             const double* pz, double* d) {
  lower_by_ball_line_scalar(lp, bits, px, py, pz, d);
}
#endif

void lower_by_ball_line(const sweep::LinearPrim& lp, std::uint64_t bits, const double* px, const double* py,
                        const double* pz, double* d) {
  if (use_avx2()) lower_by_ball_line_avx2(lp, bits, px, py, pz, d);
  else lower_by_ball_line_scalar(lp, bits, px, py, pz, d);
}

}  // namespace cutsim::stock::detail
