// The stock's private bounds, tested directly (stock_impl.h).
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <variant>
#include <vector>

#include "cutsim/sweep/sweep.h"
#include "cutsim/tool/tool.h"
#include "stock_impl.h"
#include "voxel_kernels.h"
#include "helpers.h"

namespace cutsim::test {
namespace {

using LeafPlanes = stock::Stock::Impl::LeafPlanes;
constexpr double kH = 0.01;     // voxel, mm
constexpr float kGamma = 0.03f; // half band, mm

// min over the leaf's voxels short of the band's air edge of
// v(p) + g . (p - c), c the leaf's centre.
double exact_least(const float* v, const Vec3& g) {
  double best = std::numeric_limits<double>::infinity();
  for (int x = 0; x < 8; ++x)
    for (int y = 0; y < 8; ++y)
      for (int z = 0; z < 8; ++z) {
        const float val = v[(x << 6) | (y << 3) | z];
        if (val >= kGamma) continue;
        best = std::min(best, val + g.dot(kH * Vec3(x - 3.5, y - 3.5, z - 3.5)));
      }
  return best;
}

TEST(Stock, LeafPlanesBoundALeafsMaterialUnderEveryPlane) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1, 1);
  float v[512];
  int exact_hits = 0;
  for (int trial = 0; trial < 400; ++trial) {
    // A clamped distance to a random plane or ball, or noise, with some
    // voxels at the band's edges.
    const Vec3 n = Vec3(u(rng), u(rng), u(rng)).normalized(), c = 0.05 * Vec3(u(rng), u(rng), u(rng));
    const int kind = trial % 3;
    for (int i = 0; i < 512; ++i) {
      const Vec3 p = kH * Vec3((i >> 6) - 3.5, ((i >> 3) & 7) - 3.5, (i & 7) - 3.5);
      const double d = kind == 0 ? n.dot(p - c) : kind == 1 ? (p - c).norm() - 0.03 : 0.04 * u(rng);
      v[i] = static_cast<float>(std::clamp(d, -double(kGamma), double(kGamma)));
    }
    const LeafPlanes lp = LeafPlanes::of_leaf(v, kH, kGamma);
    for (int j = 0; j < 50; ++j) {
      Vec3 g = Vec3(u(rng), u(rng), u(rng)).normalized();
      if (j < 6) g = Vec3::Unit(j / 2) * (j % 2 ? -1.0 : 1.0) * (1 + 1e-15);  // past 1 in rounding
      const double bound = lp.least(g, kH), exact = exact_least(v, g);
      ASSERT_LE(bound, exact + 1e-12) << "trial " << trial << " plane " << j;
      exact_hits += bound > exact - 1e-7;
    }
  }
  // Along an axis the bound is the exact least; it is not vacuous.
  EXPECT_GE(exact_hits, 400 * 6 / 2);
}

TEST(Stock, LeafPlanesSeeAFlatFloorUnderAToolAbove) {
  // A machined floor 12 um under the leaf's centre; the tool's plane
  // (distance falling upwards) d(p) = t - (z - c_z): a tool bottom at
  // height t - ... above the floor leaves every voxel, one below does not.
  // The voxels of air at the band's edge must not count, or the bound is
  // 3.5 voxels less than the band's lower.
  float v[512];
  const double floor_z = -0.012;
  for (int i = 0; i < 512; ++i) {
    const double z = kH * ((i & 7) - 3.5);
    v[i] = static_cast<float>(std::clamp(z - floor_z, -double(kGamma), double(kGamma)));
  }
  const LeafPlanes lp = LeafPlanes::of_leaf(v, kH, kGamma);
  const Vec3 down(0, 0, -1);
  EXPECT_NEAR(lp.least(down, kH), 0 - floor_z, 1e-8);  // v - (z - c_z) = c_z - floor
  // All air at the band's edge: nothing there can change.
  std::fill(std::begin(v), std::end(v), kGamma);
  EXPECT_EQ(LeafPlanes::of_leaf(v, kH, kGamma).least(down, kH), std::numeric_limits<double>::infinity());
  EXPECT_EQ(LeafPlanes::of_tile(kGamma, kH, kGamma).least(down, kH), std::numeric_limits<double>::infinity());
  // A material tile: its least is at the top voxels, 3.5 voxels up.
  EXPECT_NEAR(LeafPlanes::of_tile(-kGamma, kH, kGamma).least(down, kH), -kGamma - 3.5 * kH, 1e-8);
}

}  // namespace

// The voxel step's loops (voxel_kernels.h) against the definitions they
// implement, written out here one voxel at a time: the portable versions,
// the dispatching functions a run calls, and the four-wide AVX2 versions
// where the CPU has AVX2, all to the same bits (the stock update's
// results depend on them to the last digit).
TEST(VoxelKernels, PlaneTestGivesThePortableBits) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  int tested = 0, set = 0;
  for (int trial = 0; trial < 2000; ++trial) {
    const int n = static_cast<int>(rng() % 65);
    std::array<double, 64> d{}, need{}, yx{}, yy{}, yz{};
    for (int b = 0; b < n; ++b) {
      // Some voxels not yet reached (infinity), some at or below the floor,
      // some whose distance so far is their need exactly.
      need[b] = 0.03 * u(rng);
      switch (rng() % 5) {
        case 0: d[b] = std::numeric_limits<double>::infinity(); break;
        case 1: d[b] = -0.03; break;
        case 2: d[b] = need[b]; break;
        default: d[b] = 0.05 * u(rng);
      }
      yx[b] = 0.015 * ((b >> 4) - 1.5);
      yy[b] = 0.015 * (((b >> 2) & 3) - 1.5);
      yz[b] = 0.015 * ((b & 3) - 1.5);
    }
    const stock::detail::CentrePlane pl{0.02 * u(rng), u(rng), u(rng), u(rng)};
    // Some voxels whose bar is the plane there, to the ulp (or one ulp
    // either side): a sum taken in another order would tip them.
    for (int b = 0; b < n; ++b) {
      if (rng() % 3 != 0) continue;
      const double plane = pl.c + (pl.gx * yx[b] + pl.gy * yy[b] + pl.gz * yz[b]);
      const int side = static_cast<int>(rng() % 3) - 1;
      need[b] = side == 0 ? plane : std::nextafter(plane, side * std::numeric_limits<double>::infinity());
      d[b] = std::numeric_limits<double>::infinity();
    }
    // The definition: above the floor, and the plane (summed as Eigen's
    // dot) below the bar.
    std::uint64_t want = 0;
    for (int b = 0; b < n; ++b) {
      const Vec3 y(yx[b], yy[b], yz[b]);
      if (d[b] > -0.03 && pl.c + Vec3(pl.gx, pl.gy, pl.gz).dot(y) < std::min(d[b], need[b])) want |= std::uint64_t(1) << b;
    }
    const std::uint64_t portable =
        stock::detail::planes_below_scalar(d.data(), need.data(), yx.data(), yy.data(), yz.data(), 0, n, pl, -0.03);
    ASSERT_EQ(want, portable) << "trial " << trial << ", n " << n;
    ASSERT_EQ(want, stock::detail::planes_below(d.data(), need.data(), yx.data(), yy.data(), yz.data(), n, pl, -0.03))
        << "trial " << trial;
    if (cpu_has_avx2()) {
      ASSERT_EQ(want, stock::detail::planes_below_avx2(d.data(), need.data(), yx.data(), yy.data(), yz.data(), n, pl, -0.03))
          << "trial " << trial << ", n " << n;
    }
    ++tested;
    set += std::popcount(want);
  }
  EXPECT_EQ(tested, 2000);
  EXPECT_GT(set, 5000);  // the tests pass some voxels and not others
}

// Which of a leaf's convex pieces a quarter takes (quarter_pieces), against
// the loop the stock update made per piece, in Eigen's expressions: the
// keys in order up to the first too far, the box, the plane at the
// quarter's centre, the bounded key; the seeds; the place of the least.
TEST(VoxelKernels, QuarterPiecesGiveTheLoopsPieces) {
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  constexpr double kInf = std::numeric_limits<double>::infinity();
  int tested = 0, taken = 0, stopped = 0, by_box = 0, by_plane = 0, by_key = 0, unbounded = 0;
  for (int trial = 0; trial < 3000; ++trial) {
    const int n = static_cast<int>(rng() % 41);
    const double hq = 1.5 * kH, hd = std::sqrt(3.0) * hq;
    const Vec3 lc(u(rng), u(rng), u(rng));
    // A quarter's centre, 2 voxels from the leaf's along each axis (its
    // offset as the update takes it, cb - lc).
    const Vec3 cb = lc + 2 * kH * Vec3(2.0 * (rng() % 2) - 1, 2.0 * (rng() % 2) - 1, 2.0 * (rng() % 2) - 1);
    const Vec3 r = cb - lc;
    const double oc = r.norm();
    // Mostly a cut's quarter (material to 0.03 deep); now and then one
    // whose reach is not positive.
    const double need_max = rng() % 8 == 0 ? -0.04 : 0.03 * u(rng);
    std::vector<double> key(static_cast<std::size_t>(n));
    for (auto& k : key) k = rng() % 10 == 0 ? -kInf : 0.12 * u(rng) - 0.04;
    std::sort(key.begin(), key.end());
    std::vector<Aabb> box;
    std::vector<Vec3> grad;
    std::vector<char> clip;
    std::array<std::vector<double>, 12> fv;
    for (auto& f : fv) f.resize(static_cast<std::size_t>(n));
    for (int k = 0; k < n; ++k) {
      const Vec3 lo = cb + Vec3(0.1 * u(rng) - 0.08, 0.1 * u(rng) - 0.08, 0.1 * u(rng) - 0.08);
      box.push_back({lo, lo + Vec3(0.06 * u(rng), 0.06 * u(rng), 0.06 * u(rng))});
      // (Unit gradients, and some shorter and longer: the key's test passes
      // over a piece the plane's leaves only where |g|_1 > sqrt(3).)
      const double len[4] = {1.0, 1.0, 0.2, 1.8};
      const Vec3 g = Vec3(2 * u(rng) - 1, 2 * u(rng) - 1, 2 * u(rng) - 1).normalized() * len[rng() % 4];
      grad.push_back(g);
      clip.push_back(rng() % 3 != 0);
      const auto i = static_cast<std::size_t>(k);
      const double vals[12] = {key[i], lo.x(), lo.y(), lo.z(), box.back().max.x(), box.back().max.y(), box.back().max.z(),
                               g.x(), g.y(), g.z(), g.cwiseAbs().sum(), clip.back() ? 1.0 : 0.0};
      for (std::size_t f = 0; f < 12; ++f) fv[f][i] = vals[f];
    }
    const stock::detail::LeafPieces lp{fv[0].data(), fv[1].data(), fv[2].data(), fv[3].data(),
                                       fv[4].data(), fv[5].data(), fv[6].data(), fv[7].data(),
                                       fv[8].data(), fv[9].data(), fv[10].data(), fv[11].data()};
    // The loop, as the update wrote it.
    std::vector<std::pair<double, std::uint32_t>> want;
    std::vector<double> want_seed(static_cast<std::size_t>(n), std::nan(""));
    for (int k = 0; k < n; ++k) {
      const auto i = static_cast<std::size_t>(k);
      if (key[i] - oc - hd >= need_max) {
        ++stopped;
        break;
      }
      const double b2 = sweep::detail::box_distance2(box[i], cb);
      const double reach = need_max + hd;
      if (b2 > 0 && (reach <= 0 || b2 >= reach * reach)) {
        ++by_box;
        continue;
      }
      const double dk = key[i] + grad[i].dot(cb - lc);
      if (dk - hq * grad[i].cwiseAbs().sum() >= need_max) {
        ++by_plane;
        continue;
      }
      want_seed[i] = dk;
      const double bk = dk > 0 || clip[i] ? dk : -kInf;
      unbounded += bk == -kInf;
      if (bk - hd >= need_max) {
        ++by_key;
        continue;
      }
      want.emplace_back(bk, static_cast<std::uint32_t>(k));
    }
    const auto want_least = static_cast<int>(std::min_element(want.begin(), want.end()) - want.begin());
    const stock::detail::QuarterAt at{cb.x(), cb.y(), cb.z(), r.x(), r.y(), r.z(), oc, need_max, hd, hq};
    auto check = [&](const char* version, auto&& run) {
      std::vector<std::pair<double, std::uint32_t>> got(static_cast<std::size_t>(n));
      std::vector<double> seed(static_cast<std::size_t>(n), std::nan(""));
      int least = -1;
      got.resize(static_cast<std::size_t>(run(seed.data(), got.data(), &least)));
      ASSERT_EQ(want, got) << version << ", trial " << trial << ", n " << n;
      if (!want.empty()) {
        EXPECT_EQ(want_least, least) << version << ", trial " << trial;
      }
      for (const auto& [bk, k] : want) EXPECT_EQ(want_seed[k], seed[k]) << version << ", trial " << trial;
    };
    check("portable", [&](double* seed, auto* out, int* least) {
      return stock::detail::quarter_pieces_scalar(lp, 0, n, at, seed, out, least);
    });
    check("dispatched", [&](double* seed, auto* out, int* least) {
      return stock::detail::quarter_pieces(lp, n, at, seed, out, least);
    });
    if (cpu_has_avx2()) {
      check("avx2", [&](double* seed, auto* out, int* least) {
        return stock::detail::quarter_pieces_avx2(lp, n, at, seed, out, least);
      });
    }
    ++tested;
    taken += static_cast<int>(want.size());
  }
  EXPECT_EQ(tested, 3000);
  // Every way out of the loop is taken, and pieces are taken.
  EXPECT_GT(taken, 3000);
  EXPECT_GT(stopped, 300);
  EXPECT_GT(by_box, 300);
  EXPECT_GT(by_plane, 300);
  EXPECT_GT(unbounded, 100);
  EXPECT_GT(by_key, 0);
}

// The box test the cone's loop over a quarter's voxels takes first
// (boxes_reach), against its definition voxel by voxel: not at or below
// the floor, and inside the box or nearer it than a positive limit.
TEST(VoxelKernels, BoxTestGivesThePortableBits) {
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const double floor = -0.03;
  int tested = 0, passed = 0, inside = 0, near = 0, on_limit = 0;
  for (int trial = 0; trial < 4000; ++trial) {
    const int n = static_cast<int>(rng() % 65);
    const bool inner = trial % 2 == 1;
    const Vec3 lo(u(rng) - 0.5, u(rng) - 0.5, u(rng) - 0.5);
    const Aabb box{lo, lo + Vec3(0.25 * u(rng), 0.25 * u(rng), 0.25 * u(rng))};
    std::array<double, 64> d{}, need{}, px{}, py{}, pz{};
    for (int b = 0; b < n; ++b) {
      px[b] = box.min.x() - 0.1 + (box.max.x() - box.min.x() + 0.2) * u(rng);
      py[b] = box.min.y() - 0.1 + (box.max.y() - box.min.y() + 0.2) * u(rng);
      pz[b] = box.min.z() - 0.1 + (box.max.z() - box.min.z() + 0.2) * u(rng);
      need[b] = 0.2 * u(rng) - 0.05;
      switch (rng() % 6) {
        case 0: d[b] = std::numeric_limits<double>::infinity(); break;
        case 1: d[b] = floor; break;  // at the floor: passed over
        case 2: d[b] = std::nextafter(floor, 1.0); break;
        case 3: {
          // On a face (the squared distance 0), or a quarter off one face
          // with a limit whose square is the squared distance exactly, or
          // one ulp either side of it.
          px[b] = rng() % 2 ? box.min.x() : box.max.x();
          if (rng() % 2) {
            px[b] = box.max.x() + 0.25;
            py[b] = std::clamp(py[b], box.min.y(), box.max.y());
            pz[b] = std::clamp(pz[b], box.min.z(), box.max.z());
            const double b2 = sweep::detail::box_distance2(box, Vec3(px[b], py[b], pz[b]));
            const double r = std::sqrt(b2);
            const int side = static_cast<int>(rng() % 3) - 1;
            need[b] = side == 0 ? r : std::nextafter(r, side * std::numeric_limits<double>::infinity());
          }
          d[b] = std::numeric_limits<double>::infinity();
          break;
        }
        default: d[b] = 0.3 * u(rng) - 0.1;
      }
    }
    std::uint64_t want = 0;
    for (int b = 0; b < n; ++b) {
      if (d[b] <= floor) continue;
      const double lim = inner ? std::min(std::min(d[b], need[b]), 0.0) : std::min(d[b], need[b]);
      const double b2 = sweep::detail::box_distance2(box, Vec3(px[b], py[b], pz[b]));
      on_limit += b2 > 0 && lim > 0 && b2 == lim * lim;
      if (b2 > 0 && (lim <= 0 || b2 >= lim * lim)) continue;
      want |= std::uint64_t(1) << b;
      inside += b2 == 0;
      near += b2 > 0;
    }
    const std::uint64_t portable =
        stock::detail::boxes_reach_scalar(d.data(), need.data(), px.data(), py.data(), pz.data(), 0, n, box, inner, floor);
    ASSERT_EQ(want, portable) << "trial " << trial << ", n " << n;
    ASSERT_EQ(want, stock::detail::boxes_reach(d.data(), need.data(), px.data(), py.data(), pz.data(), n, box, inner, floor))
        << "trial " << trial;
    if (cpu_has_avx2()) {
      ASSERT_EQ(want,
                stock::detail::boxes_reach_avx2(d.data(), need.data(), px.data(), py.data(), pz.data(), n, box, inner, floor))
          << "trial " << trial << ", n " << n;
    }
    ++tested;
    passed += std::popcount(want);
  }
  EXPECT_EQ(tested, 4000);
  // Voxels inside the box and beside it pass, others not, and some lie
  // where the squared distance is the limit's square (passed over: the
  // test is strict there).
  EXPECT_GT(inside, 3000);
  EXPECT_GT(near, 1000);
  EXPECT_GT(on_limit, 50);
  EXPECT_LT(passed, 4000 * 32);
}

// The bounds taken for a whole quarter before its voxel loop
// (quarter_reach) against their definition voxel by voxel: material (below
// the band), and the need above the key less the offset and above the
// section plane's bound (sweep::section_bound), for a V tool's prism.
TEST(VoxelKernels, QuarterBoundsGiveThePortableBits) {
  const sweep::Sweep sw = sweep::sweep_line(Vec3(0, 0, 0), Vec3(0.02, 0.004, -0.002), Eigen::Matrix3d::Identity(),
                                            tool::parse_tool_spec("vtool:angle=90,h=0.05", "test"));
  const auto& prism = sw.prims.at(0);
  std::mt19937_64 rng(29);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const double h = 0.001;
  const float gamma = static_cast<float>(2 * h);
  std::array<double, 64> off{}, yx{}, yy{}, yz{};
  for (int q = 0; q < 64; ++q) {
    const Vec3 y = h * Vec3((q >> 4) - 1.5, ((q >> 2) & 3) - 1.5, (q & 3) - 1.5);
    off[static_cast<std::size_t>(q)] = y.norm();
    yx[static_cast<std::size_t>(q)] = y.x();
    yy[static_cast<std::size_t>(q)] = y.y();
    yz[static_cast<std::size_t>(q)] = y.z();
  }
  int set = 0, air = 0, by_key = 0, by_section = 0, on_key = 0;
  for (int trial = 0; trial < 3000; ++trial) {
    std::array<float, 512> data{};
    for (float& v : data) v = rng() % 4 == 0 ? gamma : static_cast<float>((2 * u(rng) - 1) * 2 * h);
    const int first = static_cast<int>(((rng() % 2) << 8) | ((rng() % 2) << 5) | ((rng() % 2) << 2));  // a quarter's first voxel
    const Vec3 centre(0.02 * u(rng), 0.006 * u(rng) - 0.003, 0.004 * u(rng) - 0.003);
    sweep::SectionPlane sec;
    ASSERT_TRUE(sweep::prism_section_plane(prism, centre, &sec));
    const bool sectioned = trial % 3 != 0, inner = trial % 4 == 1;
    double key = sweep::distance(prism, centre) - (trial % 5 == 0 ? 0.0 : 2 * h * u(rng));
    if (trial % 2 == 0) {
      // A voxel whose need is the key less its offset, exactly (the key
      // moved by an ulp or two till it is).
      const int q = static_cast<int>(rng() % 64);
      const double o = off[static_cast<std::size_t>(q)];
      const float v = data[static_cast<std::size_t>(first + ((q >> 4) << 6) + (((q >> 2) & 3) << 3) + (q & 3))];
      const double need = inner ? std::min(-static_cast<double>(v), 0.0) : -static_cast<double>(v);
      double k = o + need;
      for (int i = 0; i < 8 && k - o != need; ++i) k = std::nextafter(k, k - o < need ? 1.0 : -1.0);
      if (k - o == need && v < gamma) key = k;
    }
    std::uint64_t want = 0;
    for (int q = 0; q < 64; ++q) {
      const auto i = static_cast<std::size_t>(q);
      const float v = data[static_cast<std::size_t>(first + ((q >> 4) << 6) + (((q >> 2) & 3) << 3) + (q & 3))];
      if (v >= gamma) { ++air; continue; }
      const double need = inner ? std::min(-static_cast<double>(v), 0.0) : -static_cast<double>(v);
      on_key += key - off[i] == need;
      if (key - off[i] >= need) { ++by_key; continue; }
      if (sectioned && sweep::section_bound(sec, Vec3(yx[i], yy[i], yz[i])) >= need) { ++by_section; continue; }
      want |= std::uint64_t(1) << q;
    }
    const sweep::SectionPlane* sp = sectioned ? &sec : nullptr;
    const std::uint64_t portable = stock::detail::quarter_reach_scalar(data.data(), first, gamma, key, off.data(), inner, sp,
                                                                       yx.data(), yy.data(), yz.data());
    ASSERT_EQ(want, portable) << "trial " << trial;
    ASSERT_EQ(want, stock::detail::quarter_reach(data.data(), first, gamma, key, off.data(), inner, sp, yx.data(), yy.data(),
                                                 yz.data()))
        << "trial " << trial;
    if (cpu_has_avx2()) {
      ASSERT_EQ(want, stock::detail::quarter_reach_avx2(data.data(), first, gamma, key, off.data(), inner, sp, yx.data(),
                                                        yy.data(), yz.data()))
          << "trial " << trial;
    }
    set += std::popcount(want);
  }
  // Every test passes some voxels over and leaves others.
  EXPECT_GT(set, 10000);
  EXPECT_GT(air, 10000);
  EXPECT_GT(by_key, 5000);
  EXPECT_GT(by_section, 1000);
  EXPECT_GT(on_key, 100);
}

// The contact scan's voxels of a whole quarter (overlap_candidates)
// against their definition voxel by voxel: material deeper than the floor
// (-v > floor), and the region's plane above it there, -(c + g . y) >
// floor with y = h (x - 1.5, y - 1.5, z - 1.5), summed (gx yx + gy yy) + gz yz.
TEST(VoxelKernels, OverlapCandidatesGiveThePortableBits) {
  std::mt19937_64 rng(31);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const double h = 0.0005;
  auto offset = [&](int i) { return h * (i - 1.5); };
  int set = 0, by_material = 0, by_plane = 0, on_material = 0, on_plane = 0;
  for (int trial = 0; trial < 3000; ++trial) {
    std::array<float, 512> data{};
    for (float& v : data) v = static_cast<float>((2 * u(rng) - 1) * 2 * h);
    const int first = static_cast<int>(((rng() % 2) << 8) | ((rng() % 2) << 5) | ((rng() % 2) << 2));
    auto value = [&](int q) { return data[static_cast<std::size_t>(first + ((q >> 4) << 6) + (((q >> 2) & 3) << 3) + (q & 3))]; };
    auto dot = [&](const stock::detail::CentrePlane& p, int q) {
      return p.gx * offset(q >> 4) + p.gy * offset((q >> 2) & 3) + p.gz * offset(q & 3);
    };
    Vec3 g(2 * u(rng) - 1, 2 * u(rng) - 1, 2 * u(rng) - 1);
    g /= std::max(1.0, g.norm());
    stock::detail::CentrePlane pl{(2 * u(rng) - 1) * h, g.x(), g.y(), g.z()};
    double floor = (2 * u(rng) - 1) * h;
    if (trial % 3 == 0) floor = -static_cast<double>(value(static_cast<int>(rng() % 64)));  // a voxel's material at the floor
    if (trial % 3 == 1) {
      // A voxel whose plane lies at the floor, exactly (c moved by an ulp
      // or two till it does).
      const int q = static_cast<int>(rng() % 64);
      data[static_cast<std::size_t>(first + ((q >> 4) << 6) + (((q >> 2) & 3) << 3) + (q & 3))] = static_cast<float>(-(floor + h));
      pl.c = -floor - dot(pl, q);
      for (int i = 0; i < 8 && -(pl.c + dot(pl, q)) != floor; ++i)
        pl.c = std::nextafter(pl.c, -(pl.c + dot(pl, q)) > floor ? 1.0 : -1.0);
    }
    const bool with_plane = trial % 4 != 3;
    std::uint64_t want = 0;
    for (int q = 0; q < 64; ++q) {
      const double m = -static_cast<double>(value(q));
      on_material += m == floor;
      if (m <= floor) { ++by_material; continue; }
      if (with_plane) {
        const double r = -(pl.c + dot(pl, q));
        on_plane += r == floor;
        if (r <= floor) { ++by_plane; continue; }
      }
      want |= std::uint64_t(1) << q;
    }
    const auto* pp = with_plane ? &pl : nullptr;
    ASSERT_EQ(want, stock::detail::overlap_candidates_scalar(data.data(), first, floor, pp, h)) << "trial " << trial;
    ASSERT_EQ(want, stock::detail::overlap_candidates(data.data(), first, floor, pp, h)) << "trial " << trial;
    if (cpu_has_avx2()) {
      ASSERT_EQ(want, stock::detail::overlap_candidates_avx2(data.data(), first, floor, pp, h)) << "trial " << trial;
    }
    set += std::popcount(want);
  }
  // Both tests pass some voxels over and leave others, some at the floor exactly.
  EXPECT_GT(set, 20000);
  EXPECT_GT(by_material, 20000);
  EXPECT_GT(by_plane, 10000);
  EXPECT_GT(on_material, 500);
  EXPECT_GT(on_plane, 300);
}

namespace {
// The profile prisms (ProfilePrim::prism) of prism_moves and of the
// snowflake's tool, each with its move.
struct KernelPrism {
  PrismMove move;
  sweep::ProfilePrim prism;
};
std::vector<KernelPrism> kernel_prisms() {
  std::vector<PrismMove> cases = prism_moves();
  cases.push_back({"vtool:angle=90,clearance=7,h=0.1,body=0.3", Vec3(0.05, 0, 0), Eigen::Matrix3d::Identity()});
  std::vector<KernelPrism> out;
  for (const PrismMove& cs : cases) {
    const sweep::Sweep sw =
        sweep::sweep_line(prism_start, prism_start + cs.move, cs.frame, tool::parse_tool_spec(cs.spec, "test"));
    for (const sweep::Primitive& piece : sw.prims)
      if (const auto* pp = std::get_if<sweep::ProfilePrim>(&piece); pp && pp->prism) out.push_back({cs, *pp});
  }
  return out;
}
}  // namespace

// A profile prism's distances four at a time (prism_distances) against
// sweep::detail::prism_distance, to the bit: V and nose tools, moves along
// the cutting direction, sheared sideways and back along it, a tilted
// frame (prism_moves, and the snowflake's tool); points inside, beside,
// past the ends and beyond the box.
TEST(VoxelKernels, PrismDistancesGiveThePortableBits) {
  std::mt19937_64 rng(17);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  int prisms = 0, inside = 0, outside = 0, boxed = 0;
  for (const KernelPrism& kp : kernel_prisms()) {
    const auto* pp = &kp.prism;
    const PrismMove& cs = kp.move;
    ++prisms;
    const Aabb box = pp->bounds.expanded(0.05);
    for (int trial = 0; trial < 500; ++trial) {
      const int n = static_cast<int>(rng() % 65);
      std::array<double, 64> px{}, py{}, pz{}, portable{}, dispatched{}, wide{};
      for (int i = 0; i < n; ++i) {
        px[i] = box.min.x() + u(rng) * (box.max.x() - box.min.x());
        py[i] = box.min.y() + u(rng) * (box.max.y() - box.min.y());
        pz[i] = box.min.z() + u(rng) * (box.max.z() - box.min.z());
        if (rng() % 8 == 0) {  // on the move's line (the apex's path): the round case at r = 0
          const double t = u(rng) * 1.2 - 0.1;
          const Vec3 w = pp->origin + pp->to_local.transpose() * (t * pp->d_local);
          px[i] = w.x();
          py[i] = w.y();
          pz[i] = w.z();
        }
      }
      stock::detail::prism_distances_scalar(*pp, 0, n, px.data(), py.data(), pz.data(), portable.data());
      stock::detail::prism_distances(*pp, n, px.data(), py.data(), pz.data(), dispatched.data());
      ASSERT_EQ(0, std::memcmp(portable.data(), dispatched.data(), sizeof portable)) << cs.spec << ", trial " << trial;
      if (cpu_has_avx2()) {
        stock::detail::prism_distances_avx2(*pp, n, px.data(), py.data(), pz.data(), wide.data());
        for (int i = 0; i < n; ++i)
          ASSERT_EQ(0, std::memcmp(&portable[static_cast<std::size_t>(i)], &wide[static_cast<std::size_t>(i)], sizeof(double)))
              << cs.spec << ", trial " << trial << ", point " << i << ": " << portable[static_cast<std::size_t>(i)]
              << " against " << wide[static_cast<std::size_t>(i)];
      }
      for (int i = 0; i < n; ++i) {
        const Vec3 w(px[i], py[i], pz[i]);
        const double want = sweep::detail::prism_distance(*pp, w);
        ASSERT_EQ(0, std::memcmp(&want, &portable[static_cast<std::size_t>(i)], sizeof want));
        inside += want < 0;
        outside += want > 0;
        boxed += want > 0 && want * want == sweep::detail::box_distance2(pp->bounds, w);
      }
    }
  }
  EXPECT_EQ(prisms, 6);
  EXPECT_GT(inside, 5000);
  EXPECT_GT(outside, 20000);
  EXPECT_GT(boxed, 100);  // some where the way to the box is the distance
}

TEST(VoxelKernels, BallLineDistancesGiveThePortableBits) {
  const tool::Tool ball = tool::parse_tool_spec("ball:d=4");
  const Eigen::Matrix3d tilted = Eigen::AngleAxisd(0.3, Vec3(1, 0.2, 0).normalized()).toRotationMatrix();
  struct Move {
    Vec3 a, b;
    Eigen::Matrix3d r;
  };
  // Level (raster40k's), sloped, a plunge (the vertical case), a climb,
  // and the same on a tilted axis (no longer the identity frame).
  const std::vector<Move> moves = {
      {{0, 0, 0}, {0.5, 0, 0}, Eigen::Matrix3d::Identity()},   {{0, 0, 0}, {0.3, 0.2, -0.1}, Eigen::Matrix3d::Identity()},
      {{0, 0, 1}, {0, 0, 0}, Eigen::Matrix3d::Identity()},     {{0, 0, 0}, {-0.2, 0.1, 0.4}, Eigen::Matrix3d::Identity()},
      {{0, 0, 0}, {0.5, 0.1, -0.05}, tilted},                  {{0, 0, 1}, {0, 0, 0}, tilted}};
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  int vertical = 0, parallelogram = 0, framed = 0, lowered = 0;
  for (const Move& mv : moves) {
    const sweep::Sweep sw = sweep::sweep_line(mv.a, mv.b, mv.r, ball);
    for (const sweep::Primitive& piece : sw.prims) {
      const auto* lp = std::get_if<sweep::LinearPrim>(&piece);
      if (!lp || lp->env.disk_radius != 0) continue;
      (lp->kind == sweep::LinearPrim::Case::vertical ? vertical : parallelogram) += 1;
      framed += !lp->axis_z;
      const Aabb box = lp->bounds.expanded(0.5);
      for (int trial = 0; trial < 400; ++trial) {
        std::array<double, 64> px{}, py{}, pz{}, d{};
        for (int b = 0; b < 64; ++b) {
          px[b] = box.min.x() + u(rng) * (box.max.x() - box.min.x());
          py[b] = box.min.y() + u(rng) * (box.max.y() - box.min.y());
          pz[b] = box.min.z() + u(rng) * (box.max.z() - box.min.z());
          d[b] = rng() % 3 == 0 ? std::numeric_limits<double>::infinity() : 2 * u(rng) - 1;
        }
        const std::uint64_t bits = rng() & rng();  // about a quarter of the voxels
        std::array<double, 64> portable = d, dispatched = d, wide = d;
        stock::detail::lower_by_ball_line_scalar(*lp, bits, px.data(), py.data(), pz.data(), portable.data());
        stock::detail::lower_by_ball_line(*lp, bits, px.data(), py.data(), pz.data(), dispatched.data());
        ASSERT_EQ(0, std::memcmp(portable.data(), dispatched.data(), sizeof portable)) << "trial " << trial;
        if (cpu_has_avx2()) {
          stock::detail::lower_by_ball_line_avx2(*lp, bits, px.data(), py.data(), pz.data(), wide.data());
          ASSERT_EQ(0, std::memcmp(portable.data(), wide.data(), sizeof portable)) << "trial " << trial;
        }
        for (int b = 0; b < 64; ++b) {
          // Only the voxels in `bits`, each to the least of its distance so far and the piece's.
          const double want = (bits >> b) & 1 ? std::min(d[b], sweep::detail::ball_line_distance(*lp, Vec3(px[b], py[b], pz[b])))
                                              : d[b];
          ASSERT_EQ(want, portable[b]) << "voxel " << b;
          lowered += portable[b] != d[b];
        }
      }
    }
  }
  EXPECT_GT(vertical, 0);
  EXPECT_GT(parallelogram, 0);
  EXPECT_GT(framed, 0);
  EXPECT_GT(lowered, 10000);
}

namespace {
// 64 random points in `box`, and random bars (distances so far: none yet,
// deep, shallow or outside) and needs.
struct Bars64 {
  std::array<double, 64> px{}, py{}, pz{}, d{}, need{};
  std::uint64_t bits = 0;
};
Bars64 random_bars(const Aabb& box, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(0.0, 1.0);
  Bars64 b;
  const double span = (box.max - box.min).maxCoeff();
  for (std::size_t i = 0; i < 64; ++i) {
    b.px[i] = box.min.x() + u(rng) * (box.max.x() - box.min.x());
    b.py[i] = box.min.y() + u(rng) * (box.max.y() - box.min.y());
    b.pz[i] = box.min.z() + u(rng) * (box.max.z() - box.min.z());
    b.d[i] = rng() % 3 == 0 ? std::numeric_limits<double>::infinity() : span * (u(rng) - 0.7);
    b.need[i] = span * (u(rng) - 0.3);
  }
  b.bits = rng() | rng();  // about three in four
  return b;
}
}  // namespace

// A profile prism's and a joint's lowering of the bars four at a time
// (lower_by_prism, lower_by_joint) against their portable versions, to the
// bit, and those against the pieces' distances: a prism lowers a bar to
// its distance where that is less; a joint sets it to its distance where
// that is below the bar, the need and zero (the portable version stops
// once a part reaches that, and the wide one works out the whole).
TEST(VoxelKernels, PrismAndJointLoweringGiveThePortableBits) {
  std::mt19937_64 rng(23);
  int lowered = 0, untouched = 0, pieces = 0;
  auto check = [&](const auto& piece, const Aabb& box, auto portable_fn, auto dispatched_fn, auto wide_fn, auto want_fn) {
    ++pieces;
    for (int trial = 0; trial < 300; ++trial) {
      const Bars64 b = random_bars(box, rng);
      std::array<double, 64> portable = b.d, dispatched = b.d, wide = b.d;
      portable_fn(piece, b, portable.data());
      dispatched_fn(piece, b, dispatched.data());
      ASSERT_EQ(0, std::memcmp(portable.data(), dispatched.data(), sizeof portable)) << "trial " << trial;
      if (cpu_has_avx2()) {
        wide_fn(piece, b, wide.data());
        ASSERT_EQ(0, std::memcmp(portable.data(), wide.data(), sizeof portable)) << "trial " << trial;
      }
      for (std::size_t i = 0; i < 64; ++i) {
        const double want = (b.bits >> i) & 1 ? want_fn(piece, b, i) : b.d[i];
        ASSERT_EQ(0, std::memcmp(&want, &portable[i], sizeof want)) << "voxel " << i << ": " << want << " against " << portable[i];
        (portable[i] != b.d[i] ? lowered : untouched) += 1;
      }
    }
  };
  // Prisms: the profile prisms' moves and the snowflake's tool.
  for (const KernelPrism& kp : kernel_prisms()) {
    const sweep::ProfilePrim* pp = &kp.prism;
    check(
        *pp, pp->bounds.expanded(0.02),
        [](const auto& q, const Bars64& b, double* d) { stock::detail::lower_by_prism_scalar(q, b.bits, b.px.data(), b.py.data(), b.pz.data(), d); },
        [](const auto& q, const Bars64& b, double* d) { stock::detail::lower_by_prism(q, b.bits, b.px.data(), b.py.data(), b.pz.data(), d); },
        [](const auto& q, const Bars64& b, double* d) { stock::detail::lower_by_prism_avx2(q, b.bits, b.px.data(), b.py.data(), b.pz.data(), d); },
        [](const auto& q, const Bars64& b, std::size_t i) {
          return std::min(b.d[i], sweep::detail::prism_distance(q, Vec3(b.px[i], b.py[i], b.pz[i])));
        });
  }
  const int prism_pieces = pieces;
  // Joints: a V and a round nose along a valley (with and without the
  // prisms before and after), against the cutting direction, and crests.
  const Eigen::Matrix3d I = Eigen::Matrix3d::Identity();
  const std::vector<Vec3> valley = {Vec3(0, 0, 0.004), Vec3(0.004, 0, 0.001), Vec3(0.008, 0, 0), Vec3(0.012, 0, 0.002)};
  const std::vector<Vec3> back = {Vec3(0.012, 0, 0.002), Vec3(0.008, 0, 0), Vec3(0.004, 0, 0.001), Vec3(0, 0, 0.004)};
  const std::vector<Vec3> crest = {Vec3(0, 0, 0), Vec3(0.004, 0, 0.003), Vec3(0.008, 0, 0.0035), Vec3(0.012, 0, 0.001)};
  int crests = 0;
  for (const char* spec : {"vtool:angle=90,h=0.05", "nose:r=0.5,angle=100"}) {
    const tool::Tool t = tool::parse_tool_spec(spec, "test");
    for (const auto* path : {&valley, &back, &crest}) {
      std::vector<sweep::ProfilePrim> pp;
      for (std::size_t i = 0; i + 1 < path->size(); ++i)
        pp.push_back(std::get<sweep::ProfilePrim>(sweep::sweep_line((*path)[i], (*path)[i + 1], I, t).prims[0]));
      std::vector<sweep::JointPrim> joints;
      for (std::size_t mid = 0; mid < pp.size(); ++mid)
        if (auto j = sweep::joint_prim(mid > 0 ? &pp[mid - 1] : nullptr, pp[mid], mid + 1 < pp.size() ? &pp[mid + 1] : nullptr,
                                       0.001, Aabb{}))
          joints.push_back(*j);
      for (std::size_t k = 0; k + 1 < pp.size(); ++k)
        if (auto c = sweep::crest_prim(pp[k], pp[k + 1], 0.001, Aabb{})) joints.push_back(*c);
      for (const sweep::JointPrim& jp : joints) {
        crests += jp.crest;
        check(
            jp, jp.bounds.expanded(0.002),
            [](const auto& q, const Bars64& b, double* d) {
              stock::detail::lower_by_joint_scalar(q, b.bits, b.px.data(), b.py.data(), b.pz.data(), b.need.data(), d);
            },
            [](const auto& q, const Bars64& b, double* d) {
              stock::detail::lower_by_joint(q, b.bits, b.px.data(), b.py.data(), b.pz.data(), b.need.data(), d);
            },
            [](const auto& q, const Bars64& b, double* d) {
              stock::detail::lower_by_joint_avx2(q, b.bits, b.px.data(), b.py.data(), b.pz.data(), b.need.data(), d);
            },
            [](const auto& q, const Bars64& b, std::size_t i) {
              const double lim = std::min(std::min(b.d[i], b.need[i]), 0.0);
              const double dj = sweep::detail::joint_distance(q, Vec3(b.px[i], b.py[i], b.pz[i]));
              return dj < lim ? dj : b.d[i];
            });
      }
    }
  }
  EXPECT_EQ(prism_pieces, 6);
  EXPECT_GT(pieces - prism_pieces, 12);
  EXPECT_GT(crests, 1);
  EXPECT_GT(lowered, 20000);
  EXPECT_GT(untouched, 20000);
}

}  // namespace cutsim::test
