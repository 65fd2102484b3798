#include "cutsim/compare/compare.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <mutex>
#include <optional>

#include <openvdb/openvdb.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "cutsim/stock/level_set_mesher.h"

namespace cutsim::compare {

namespace {
// Centre of a block's voxels (a block cut by the ROI has fewer than 8).
Vec3 block_centre(const stock::VoxelBlock& b, double h) {
  return b.first_center + 0.5 * h * Vec3(b.n[0] - 1, b.n[1] - 1, b.n[2] - 1);
}

double fraction(double d, double h) { return std::clamp(0.5 - d / h, 0.0, 1.0); }

// Stock value `s` and target distance `t` both material, or both air, at
// least h deep: the voxel adds nothing to either volume, and both regions'
// level sets keep their fill (+h) there.
bool agree_beyond_h(double s, double t, double h) { return (s <= -h && t <= -h) || (s >= h && t >= h); }

// A region's level set over the blocks where it exists, clamped to +-h and
// kept in 8 bits (it is only drawn; the volumes are summed before), on
// cells of 2^shift voxels: a cell keeps the least of its voxels' values, so
// any voxel in the region keeps its cell in. A block is coarsened as soon
// as the regions outgrow the budget for its cell size, so a fine voxel over
// a large region never holds 512 bytes a block.
struct RegionBlock {
  openvdb::Coord origin;  // first voxel, index from the ROI lattice's origin (>= 0)
  int n[3];               // voxels
  int shift = 0;          // cells of 2^shift voxels (a block's cells stay in its 8-voxel lattice cell)
  std::vector<std::int8_t> v;  // (x * s + y) * s + z, s = 8 >> shift; 127 (= +h) where no voxel

  int side() const { return 8 >> shift; }
  /// The cell holding voxel `a` (a lattice index) along `k`, from the block's first cell.
  int cell(int a, int k) const { return (a >> shift) - (origin[k] >> shift); }
  void coarsen(int to) {
    if (to <= shift) return;
    const int s0 = side(), up = to - shift;
    const int base[3] = {origin.x() >> shift, origin.y() >> shift, origin.z() >> shift};
    // Only the cells that hold voxels: past them (a block the ROI cut,
    // starting inside its lattice cell) the array's slots would map beyond
    // the lattice cell.
    int used[3];
    for (int k = 0; k < 3; ++k) used[k] = cell(origin[k] + n[k] - 1, k) + 1;
    std::vector<std::int8_t> out(static_cast<std::size_t>((8 >> to) * (8 >> to) * (8 >> to)), 127);
    const int s1 = 8 >> to;
    for (int x = 0; x < used[0]; ++x)
      for (int y = 0; y < used[1]; ++y)
        for (int z = 0; z < used[2]; ++z) {
          const int cx = ((base[0] + x) >> up) - (origin.x() >> to), cy = ((base[1] + y) >> up) - (origin.y() >> to),
                    cz = ((base[2] + z) >> up) - (origin.z() >> to);
          std::int8_t& c = out[static_cast<std::size_t>((cx * s1 + cy) * s1 + cz)];
          c = std::min(c, v[static_cast<std::size_t>((x * s0 + y) * s0 + z)]);
        }
    v.swap(out);
    shift = to;
  }
};

std::int8_t quantize(double v, double h) {
  return static_cast<std::int8_t>(std::floor(std::clamp(v / h, -1.0, 1.0) * 127 + 0.5));
}

// Meshes the region on its blocks' cells (all of one size, 2^shift voxels).
TriMesh mesh_region(const std::vector<RegionBlock>& blocks, const Vec3& lattice_origin, double h, int shift,
                    double adaptivity) {
  TriMesh out;
  if (blocks.empty()) return out;
  openvdb::initialize();
  const int k = 1 << shift;
  const double hk = h * k;
  auto grid = openvdb::FloatGrid::create(static_cast<float>(h));
  grid->setTransform(openvdb::math::Transform::createLinearTransform(hk));
  auto acc = grid->getAccessor();
  for (const auto& b : blocks) {
    const int s = b.side();
    const openvdb::Coord c0(b.origin.x() >> shift, b.origin.y() >> shift, b.origin.z() >> shift);
    const openvdb::Coord c1((b.origin.x() + b.n[0] - 1) >> shift, (b.origin.y() + b.n[1] - 1) >> shift,
                            (b.origin.z() + b.n[2] - 1) >> shift);
    for (int x = c0.x(); x <= c1.x(); ++x)
      for (int y = c0.y(); y <= c1.y(); ++y)
        for (int z = c0.z(); z <= c1.z(); ++z)
          acc.setValue(openvdb::Coord(x, y, z),
                       static_cast<float>(b.v[static_cast<std::size_t>(((x - c0.x()) * s + (y - c0.y())) * s + (z - c0.z()))] * (h / 127)));
  }
  // Meshed at +h/4 so that a region thinner than a voxel still shows.
  stock::LevelSetMesh m = stock::mesh_level_set(grid->tree(), adaptivity, static_cast<float>(0.25 * h));
  const Vec3 origin = lattice_origin + Vec3::Constant(0.5 * (k - 1) * h);  // centre of cell (0, 0, 0)
  out.positions.reserve(m.points.size());
  for (const Vec3& p : m.points) out.positions.push_back(origin + hk * p);
  out.triangles = std::move(m.triangles);
  return out;
}

// The target's signed distance at every block centre of the ROI lattice,
// or, where the surface is farther than the block's reach, only its sign.
//
// A bounded query per block finds the near ones. A far block (no surface
// within R = hd + h of its centre) takes its sign from a neighbour: two
// neighbouring centres are at most 8h apart, and the balls of radius R
// around them (or R and |d| > h, for a known neighbour) cover the segment
// between them, which therefore does not cross the surface. Only a region
// of far blocks with no known neighbour needs an unbounded query.
struct TargetBlocks {
  std::array<int, 3> dims{};
  std::vector<float> d;           // signed distance at the centre; far: +-far_value
  std::vector<std::int8_t> state; // 0 far and unsigned, 1 far and signed, 2 known
  float far_value = 0;

  std::size_t index(const int* l) const {
    return (static_cast<std::size_t>(l[0]) * dims[1] + static_cast<std::size_t>(l[1])) * dims[2] +
           static_cast<std::size_t>(l[2]);
  }
};

// Calls fn(index) for the group's blocks in the lattice until it returns false.
template <class Fn>
bool for_each_in(const stock::BlockGroup& g, const TargetBlocks& tb, Fn fn) {
  for (int x = g.lo[0]; x < g.hi[0]; ++x)
    for (int y = g.lo[1]; y < g.hi[1]; ++y)
      for (int z = g.lo[2]; z < g.hi[2]; ++z) {
        const int l[3] = {x, y, z};
        if (!fn(tb.index(l))) return false;
      }
  return true;
}

TargetBlocks classify_blocks(const stock::Stock& stock, const Target& target, double h, double reach) {
  TargetBlocks tb;
  tb.dims = stock.roi_block_dims();
  const std::size_t n = static_cast<std::size_t>(tb.dims[0]) * tb.dims[1] * tb.dims[2];
  tb.d.assign(n, 0.0f);
  tb.state.assign(n, -1);  // -1: not in the ROI (never visited)
  tb.far_value = static_cast<float>(reach);
  stock.for_each_roi_block(
      [&](const stock::VoxelBlock& b) {
        const std::size_t i = tb.index(b.leaf);
        const Vec3 c = block_centre(b, h);
        if (const auto d = target.signed_distance_if_within(c, reach)) {
          tb.d[i] = static_cast<float>(*d);
          tb.state[i] = 2;
        } else {
          tb.state[i] = 0;
        }
      },
      false,
      // A group with no surface within reach of any of its block centres:
      // every block far, on the side of the group's centre (one query for
      // up to 4096 blocks; the blade's ROI at 1 um has 47 M).
      [&](const stock::BlockGroup& g) {
        if (target.signed_distance_if_within(g.centre, g.radius + reach)) return true;
        const float s = target.signed_distance(g.centre) < 0 ? -tb.far_value : tb.far_value;
        for_each_in(g, tb, [&](std::size_t i) {
          tb.state[i] = 1;
          tb.d[i] = s;
          return true;
        });
        return false;
      });
  // Breadth-first over the lattice from every block whose sign can pass on.
  std::vector<std::size_t> queue;
  for (std::size_t i = 0; i < n; ++i)
    if (tb.state[i] == 2 && std::fabs(tb.d[i]) > h) queue.push_back(i);
  const std::size_t stride[3] = {static_cast<std::size_t>(tb.dims[1]) * tb.dims[2],
                                 static_cast<std::size_t>(tb.dims[2]), 1};
  auto spread = [&]() {
    while (!queue.empty()) {
      const std::size_t i = queue.back();
      queue.pop_back();
      const float s = tb.d[i] < 0 ? -tb.far_value : tb.far_value;
      std::size_t rest = i;
      for (int k = 0; k < 3; ++k) {
        const auto l = static_cast<int>(rest / stride[k]);
        rest %= stride[k];
        if (l > 0 && tb.state[i - stride[k]] == 0) {
          tb.state[i - stride[k]] = 1;
          tb.d[i - stride[k]] = s;
          queue.push_back(i - stride[k]);
        }
        if (l + 1 < tb.dims[static_cast<std::size_t>(k)] && tb.state[i + stride[k]] == 0) {
          tb.state[i + stride[k]] = 1;
          tb.d[i + stride[k]] = s;
          queue.push_back(i + stride[k]);
        }
      }
    }
  };
  spread();
  // A far region with no known neighbour: one unbounded query, at the
  // centre of its lattice cell (within 3.5h sqrt 3 < reach of the block's
  // own centre, so on the same side).
  const Vec3 lattice = stock.roi_lattice_origin();
  for (std::size_t i = 0; i < n; ++i) {
    if (tb.state[i] != 0) continue;
    const std::size_t l[3] = {i / stride[0], (i / stride[1]) % static_cast<std::size_t>(tb.dims[1]),
                              i % static_cast<std::size_t>(tb.dims[2])};
    const Vec3 p = lattice + h * (8.0 * Vec3(double(l[0]), double(l[1]), double(l[2])) + Vec3::Constant(3.5));
    tb.d[i] = target.signed_distance(p) < 0 ? -tb.far_value : tb.far_value;
    tb.state[i] = 1;
    queue.push_back(i);
    spread();
  }
  return tb;
}

// The target's distance at a block's voxels, clamped to +-h. Voxels nearer
// the centre than |d_c| - h are saturated; the rest ask for the surface
// within 1.5h. A voxel with none that near (|d| > 1.5h) has the sign of any
// neighbour whose sign is known: its ball of radius |d| holds the neighbour
// h away with half a voxel to spare (so a neighbour on the surface, whose
// sign is a coin toss, cannot pass one on). Flooding from the known voxels
// (and from the centre, within h of some voxel) reaches every voxel.
void block_target_distances(const stock::VoxelBlock& b, const Vec3& centre, double dc, const Target& target,
                            double h, float* dt) {
  constexpr float kUnknown = std::numeric_limits<float>::quiet_NaN();
  const float hf = static_cast<float>(h);
  // First per 4^3 quarter (centre to farthest voxel hq): with no surface
  // within hq + 1.5h of its centre, none is within 1.5h of its voxels; with
  // |d| >= hq + h there, all its voxels are saturated.
  const double hq = std::sqrt(3.0) * 1.5 * h;
  // Every query below is within hq + 1.5h of a quarter's centre, or 1.5h
  // of a voxel: the triangles that near the block hold them all. One search
  // of the mesh for the block, then each query tries only those few.
  double reach = std::sqrt(3.0) * 3.5 * h;  // the centre's farthest voxel in a whole block
  for (int q = 0; q < 8; ++q) {
    const int qx = (q >> 2) * 4, qy = ((q >> 1) & 1) * 4, qz = (q & 1) * 4;
    if (qx >= b.n[0] || qy >= b.n[1] || qz >= b.n[2]) continue;
    reach = std::max(reach, (b.first_center + h * Vec3(qx + 1.5, qy + 1.5, qz + 1.5) - centre).norm() + hq);
  }
  // (And each quarter's own, from those.)
  thread_local std::vector<unsigned> near;
  thread_local std::array<std::vector<unsigned>, 8> qnear;
  // And each quarter's eighths' (2^3 voxels), made the first time one of
  // their voxels asks: the snowflake's voxels tried 10.3 triangles each
  // from their quarter's list, 2.6 from their eighth's. A subset in the
  // same order, so the nearest (the first of equally near) stays the same.
  thread_local std::array<std::vector<unsigned>, 64> enear;
  std::array<bool, 64> eighth_ready{};
  auto eighth_near = [&](int x, int y, int z, std::size_t q) -> const std::vector<unsigned>& {
    const std::size_t e = (q << 3) | static_cast<std::size_t>((((x >> 1) & 1) << 2) | (((y >> 1) & 1) << 1) | ((z >> 1) & 1));
    if (!eighth_ready[e]) {
      const Vec3 ce = b.first_center + h * Vec3((x & ~1) + 0.5, (y & ~1) + 0.5, (z & ~1) + 0.5);
      target.triangles_near(ce, std::sqrt(3.0) * 0.5 * h + 1.5 * h, qnear[q], enear[e]);
      eighth_ready[e] = true;
    }
    return enear[e];
  };
  target.triangles_near(centre, reach + 1.5 * h, near);
  // A flat stretch of the target (the snowflake's top and its pocket's
  // floor): every voxel lies at least 1.5h inside the ball `near` covers,
  // so the plane's distance clamped to +-h is the surface's.
  // (The voxel's place from scalars, as in the loop below: built as
  // first_center + h (x, y, z), each voxel stored x and y to the stack and
  // loaded them again as a pair: a fifth of the own samples of the
  // comparison's block loop on the snowflake. The same sums and products.)
  if (const auto plane = target.common_plane(near)) {
    for (int x = 0; x < b.n[0]; ++x) {
      const double px = b.first_center.x() + h * x;
      for (int y = 0; y < b.n[1]; ++y) {
        const double py = b.first_center.y() + h * y;
        for (int z = 0; z < b.n[2]; ++z)
          dt[(x * 8 + y) * 8 + z] = static_cast<float>(
              std::clamp(plane->signed_distance(Vec3(px, py, b.first_center.z() + h * z)), -h, h));
      }
    }
    return;
  }
  std::array<std::optional<double>, 8> dq;
  std::array<bool, 8> quarter_far{};
  for (int q = 0; q < 8; ++q) {
    const int qx = (q >> 2) * 4, qy = ((q >> 1) & 1) * 4, qz = (q & 1) * 4;
    if (qx >= b.n[0] || qy >= b.n[1] || qz >= b.n[2]) continue;
    const Vec3 cq = b.first_center + h * Vec3(qx + 1.5, qy + 1.5, qz + 1.5);
    const auto qi = static_cast<std::size_t>(q);
    qnear[qi].clear();
    if ((cq - centre).norm() + hq <= std::fabs(dc) - h) continue;  // saturated from the block's centre
    target.triangles_near(cq, hq + 1.5 * h, near, qnear[qi]);
    dq[qi] = target.signed_distance_if_within(cq, hq + 1.5 * h, qnear[qi]);
    quarter_far[qi] = !dq[qi];
  }
  // The saturation tests below on squared lengths: most voxels of a block
  // near the surface end at one of the first two, and a square root each
  // was a third of this function's time. (Where r and r^2 round to
  // different sides of a radius, the voxel is at least h from the surface
  // either way, so both branches write the same +-h.)
  const double sat_c = std::fabs(dc) - h;
  const double sat_c2 = sat_c >= 0 ? sat_c * sat_c : -1.0;
  std::array<double, 8> sat_q2;
  std::array<Vec3, 8> centre_q;
  for (int q = 0; q < 8; ++q) {
    const auto qi = static_cast<std::size_t>(q);
    centre_q[qi] = b.first_center + h * Vec3((q >> 2) * 4 + 1.5, ((q >> 1) & 1) * 4 + 1.5, (q & 1) * 4 + 1.5);
    const double t = dq[qi] ? std::fabs(*dq[qi]) - h : -1.0;
    sat_q2[qi] = t >= 0 ? t * t : -1.0;
  }
  int unknown = 0;
  // The voxels that ask for the surface, by their eighth: asked four at a
  // time (Target::signed_distances_if_within) once the loop has found
  // them all, each eighth's together (they share its triangles).
  struct Ask {
    std::uint16_t i;      // the voxel
    bool centre_in_ball;  // r2 <= h^2: the centre lies in its empty ball
  };
  std::array<std::array<Ask, 8>, 64> asks;
  std::array<std::uint8_t, 64> n_asks{};
  std::uint64_t asked = 0;  // eighths with asks
  // (The voxel's place and its offsets from the centres on scalars: built
  // as a Vec3 on the stack, each voxel waited for its two halves to be
  // stored and loaded again, a quarter of this loop's time. The same
  // values, summed in the same order as squaredNorm's.)
  for (int x = 0; x < b.n[0]; ++x) {
    const double px = b.first_center.x() + h * x;
    for (int y = 0; y < b.n[1]; ++y) {
      const double py = b.first_center.y() + h * y;
      for (int z = 0; z < b.n[2]; ++z) {
        const int i = (x * 8 + y) * 8 + z;
        const auto q = static_cast<std::size_t>(((x >> 2) << 2) | ((y >> 2) << 1) | (z >> 2));
        const double pz = b.first_center.z() + h * z;
        const double cx = px - centre.x(), cy = py - centre.y(), cz = pz - centre.z();
        const double r2 = cx * cx + cy * cy + cz * cz;
        if (r2 <= sat_c2) {
          dt[i] = dc < 0 ? -hf : hf;
        } else if (const double qx = px - centre_q[q].x(), qy = py - centre_q[q].y(), qz = pz - centre_q[q].z();
                   qx * qx + qy * qy + qz * qz <= sat_q2[q]) {
          dt[i] = *dq[q] < 0 ? -hf : hf;
        } else if (!quarter_far[q]) {
          const std::size_t e = (q << 3) | static_cast<std::size_t>((((x >> 1) & 1) << 2) | (((y >> 1) & 1) << 1) | ((z >> 1) & 1));
          asks[e][n_asks[e]++] = {static_cast<std::uint16_t>(i), r2 <= h * h};
          asked |= std::uint64_t{1} << e;
        } else if (r2 <= h * h) {
          dt[i] = dc < 0 ? -hf : hf;  // the centre lies in this voxel's empty ball
        } else {
          dt[i] = kUnknown;
          ++unknown;
        }
      }
    }
  }
  for (; asked != 0; asked &= asked - 1) {
    const auto e = static_cast<std::size_t>(std::countr_zero(asked));
    // (eighth_near takes a voxel of the eighth: its first.)
    const int i0 = asks[e][0].i;
    const std::vector<unsigned>& near = eighth_near(i0 >> 6, (i0 >> 3) & 7, i0 & 7, e >> 3);
    for (int k0 = 0; k0 < n_asks[e]; k0 += 4) {
      const int n = std::min(4, n_asks[e] - k0);
      double ax[4], ay[4], az[4], d[4];
      for (int k = 0; k < n; ++k) {
        const int i = asks[e][static_cast<std::size_t>(k0 + k)].i;
        ax[k] = b.first_center.x() + h * (i >> 6);
        ay[k] = b.first_center.y() + h * ((i >> 3) & 7);
        az[k] = b.first_center.z() + h * (i & 7);
      }
      target.signed_distances_if_within(n, ax, ay, az, 1.5 * h, near, d);
      for (int k = 0; k < n; ++k) {
        const Ask& a = asks[e][static_cast<std::size_t>(k0 + k)];
        if (!std::isnan(d[k])) {
          dt[a.i] = static_cast<float>(std::clamp(d[k], -h, h));
        } else if (a.centre_in_ball) {
          dt[a.i] = dc < 0 ? -hf : hf;  // the centre lies in this voxel's empty ball
        } else {
          dt[a.i] = kUnknown;
          ++unknown;
        }
      }
    }
  }
  if (unknown == 0) return;
  int stack[512];
  int top = 0;
  for (int x = 0; x < b.n[0]; ++x)
    for (int y = 0; y < b.n[1]; ++y)
      for (int z = 0; z < b.n[2]; ++z) {
        const int i = (x * 8 + y) * 8 + z;
        if (!std::isnan(dt[i]) && std::fabs(dt[i]) > 0) stack[top++] = i;
      }
  while (top > 0) {
    const int i = stack[--top];
    const int c[3] = {i >> 6, (i >> 3) & 7, i & 7};
    const float s = dt[i] < 0 ? -hf : hf;
    for (int k = 0; k < 3; ++k)
      for (int dir = -1; dir <= 1; dir += 2) {
        const int q = c[k] + dir;
        if (q < 0 || q >= b.n[k]) continue;
        const int j = i + dir * (k == 0 ? 64 : k == 1 ? 8 : 1);
        if (std::isnan(dt[j])) {
          dt[j] = s;
          stack[top++] = j;
        }
      }
  }
  // Unreachable by the argument above; an unbounded query keeps it safe.
  for (int x = 0; x < b.n[0]; ++x)
    for (int y = 0; y < b.n[1]; ++y)
      for (int z = 0; z < b.n[2]; ++z) {
        const int i = (x * 8 + y) * 8 + z;
        if (std::isnan(dt[i]))
          dt[i] = static_cast<float>(std::clamp(target.signed_distance(b.first_center + h * Vec3(x, y, z)), -h, h));
      }
}

}  // namespace

CompareResult compare(const stock::Stock& stock, const Target& target, const TriMesh& machined,
                      const CompareOptions& opt) {
  CompareResult r;
  r.tolerance_mm = opt.tolerance_mm;
  const double h = stock.voxel_mm();
  const double hd = std::sqrt(3.0) * 3.5 * h;  // block centre to its farthest voxel centre
  const TargetBlocks tb = classify_blocks(stock, target, h, hd + h);

  // Volumes: blocks summed into per-block slots, then added in a fixed
  // order so the answer does not depend on threading.
  struct Sum { Vec3 key; double over = 0, under = 0; };
  std::vector<Sum> sums;
  std::vector<RegionBlock> over_blocks, under_blocks;
  std::atomic<int> shift{0};  // the region meshes' cells: 2^shift voxels
  std::mutex mu;
  const Vec3 lattice = stock.roi_lattice_origin();
  // A block's region level sets kept, under the lock, coarsened to the
  // present cells.
  auto keep = [&](const stock::VoxelBlock& b, double over, double under, RegionBlock&& ro, RegionBlock&& ru) {
    std::lock_guard<std::mutex> lock(mu);
    sums.push_back({b.first_center, over, under});
    if (over > 0) over_blocks.push_back(std::move(ro));
    if (under > 0) under_blocks.push_back(std::move(ru));
    // A region's blocks on a k-voxel grid number about blocks / k^2 (regions
    // are mostly layers along the surface): k = 2^shift, the finest within
    // the budget, up to 8. It only grows, so blocks coarsened early are
    // what the end would make of them.
    int sh = shift.load();
    while (sh < 3 && over_blocks.size() + under_blocks.size() > opt.region_block_budget << (2 * sh)) ++sh;
    if (sh != shift.load()) {
      shift.store(sh);
      for (auto* v : {&over_blocks, &under_blocks})
        for (auto& rb : *v) rb.coarsen(sh);
    } else {
      if (over > 0) over_blocks.back().coarsen(sh);
      if (under > 0) under_blocks.back().coarsen(sh);
    }
  };
  auto region_block = [&](const stock::VoxelBlock& b) {
    RegionBlock rb;
    const Vec3 idx = (b.first_center - lattice) / h;
    rb.origin = openvdb::Coord(static_cast<int>(std::lround(idx.x())), static_cast<int>(std::lround(idx.y())),
                               static_cast<int>(std::lround(idx.z())));
    for (int k = 0; k < 3; ++k) rb.n[k] = b.n[k];
    rb.shift = shift.load();
    const int s = rb.side();
    rb.v.assign(static_cast<std::size_t>(s * s * s), 127);
    return rb;
  };
  // The overcut's and undercut's blocks for `b`, only those it has (an
  // empty one for the other), on the same cells: one reading of `shift`,
  // which another thread may raise meanwhile (keep() coarsens them to it).
  auto region_blocks = [&](const stock::VoxelBlock& b, bool over, bool under) {
    std::pair<RegionBlock, RegionBlock> both;
    RegionBlock rb = region_block(b);
    if (over && under) both.second = rb;
    (over ? both.first : both.second) = std::move(rb);
    return both;
  };
  // A uniform block (a tile: all material or all air) where the target is
  // uniform too (+-h at every voxel): every voxel adds the same to the
  // volumes and the same value to its cell, so the sums are products and
  // the cells are filled. Only where each voxel adds 0 or 1 (a tile's
  // +-band against +-h): then the products are the voxel loop's sums
  // exactly. (The blade's undercut under its roughing, 0.4 mm3 at 1 um,
  // some 770k blocks of 512 voxels, was most of its comparison's time.)
  // False: left to the voxel loop.
  auto uniform_block = [&](const stock::VoxelBlock& b, float tv) {
    const double sv = b.value;
    const double fs = fraction(sv, h), ft = fraction(tv, h);
    const double x = std::max(0.0, ft - fs), y = std::max(0.0, fs - ft);
    if ((x != 0 && x != 1) || (y != 0 && y != 1)) return false;
    if (agree_beyond_h(sv, tv, h)) return true;  // nothing to count or draw
    const double nvox = static_cast<double>(b.n[0] * b.n[1] * b.n[2]);
    const double over = x * nvox, under = y * nvox;
    if (over == 0 && under == 0) return true;
    auto [ro, ru] = region_blocks(b, over > 0, under > 0);
    const double cs = std::clamp<double>(sv, -h, h);
    if (!agree_beyond_h(cs, tv, h)) {
      const std::int8_t qo = quantize(std::max<double>(tv, -cs), h), qu = quantize(std::max<double>(cs, -tv), h);
      const RegionBlock& geo = over > 0 ? ro : ru;
      const int s = geo.side();
      int c1[3];
      for (int k = 0; k < 3; ++k) c1[k] = geo.cell(geo.origin[k] + b.n[k] - 1, k);
      for (int cx = 0; cx <= c1[0]; ++cx)
        for (int cy = 0; cy <= c1[1]; ++cy)
          for (int cz = 0; cz <= c1[2]; ++cz) {
            const auto c = static_cast<std::size_t>((cx * s + cy) * s + cz);
            if (over > 0) ro.v[c] = std::min(ro.v[c], qo);
            if (under > 0) ru.v[c] = std::min(ru.v[c], qu);
          }
    }
    keep(b, over, under, std::move(ro), std::move(ru));
    return true;
  };
  stock.for_each_roi_block([&](const stock::VoxelBlock& b) {
    const std::size_t bi = tb.index(b.leaf);
    const double dc = tb.d[bi];
    float dt[512];
    if (tb.state[bi] == 1 || std::fabs(dc) >= hd + h) {
      // Both uniform on the same side (material under material, air in air):
      // nothing to count or draw.
      if (b.uniform && (b.value < 0) == (dc < 0) && std::fabs(b.value) >= 0.5 * h) return;
      if (b.uniform && uniform_block(b, static_cast<float>(dc < 0 ? -h : h))) return;
      std::fill(std::begin(dt), std::end(dt), static_cast<float>(dc < 0 ? -h : h));
    } else {
      block_target_distances(b, block_centre(b, h), dc, target, h, dt);
    }
    double over = 0, under = 0;
    for (int x = 0; x < b.n[0]; ++x)
      for (int y = 0; y < b.n[1]; ++y)
        for (int z = 0; z < b.n[2]; ++z) {
          const int i = (x * 8 + y) * 8 + z;
          const double sv = b.uniform ? b.value : b.values[i], tv = dt[i];
          if (agree_beyond_h(sv, tv, h)) continue;
          const double fs = fraction(sv, h);
          const double ft = fraction(tv, h);
          over += std::max(0.0, ft - fs);
          under += std::max(0.0, fs - ft);
        }
    if (over == 0 && under == 0) return;  // most blocks: stock and target agree
    auto [ro, ru] = region_blocks(b, over > 0, under > 0);
    const RegionBlock& geo = over > 0 ? ro : ru;
    const int s = geo.side();
    for (int x = 0; x < b.n[0]; ++x)
      for (int y = 0; y < b.n[1]; ++y)
        for (int z = 0; z < b.n[2]; ++z) {
          const int i = (x * 8 + y) * 8 + z;
          const double cs = std::clamp<double>(b.uniform ? b.value : b.values[i], -h, h);
          if (agree_beyond_h(cs, dt[i], h)) continue;  // (both regions' values 127, the fill)
          const auto c = static_cast<std::size_t>(
              (geo.cell(geo.origin.x() + x, 0) * s + geo.cell(geo.origin.y() + y, 1)) * s + geo.cell(geo.origin.z() + z, 2));
          if (over > 0) ro.v[c] = std::min(ro.v[c], quantize(std::max<double>(dt[i], -cs), h));
          if (under > 0) ru.v[c] = std::min(ru.v[c], quantize(std::max<double>(cs, -dt[i]), h));
        }
    keep(b, over, under, std::move(ro), std::move(ru));
  }, true,
  // A group the stock holds uniform (a tile) where every block is far from
  // the target on the tile's side: the blocks' own test, once for them all.
  [&](const stock::BlockGroup& g) {
    if (!g.uniform || !(std::fabs(g.value) >= 0.5 * h)) return true;
    return !for_each_in(g, tb, [&](std::size_t i) {
      const double dc = tb.d[i];
      return (tb.state[i] == 1 || std::fabs(dc) >= hd + h) && (g.value < 0) == (dc < 0);
    });
  });
  std::sort(sums.begin(), sums.end(), [](const Sum& a, const Sum& b) {
    return std::lexicographical_compare(a.key.data(), a.key.data() + 3, b.key.data(), b.key.data() + 3);
  });
  auto by_origin = [](const RegionBlock& a, const RegionBlock& b) { return a.origin < b.origin; };
  std::sort(over_blocks.begin(), over_blocks.end(), by_origin);
  std::sort(under_blocks.begin(), under_blocks.end(), by_origin);
  r.region_mesh_voxel_mm = (1 << shift.load()) * h;
  r.overcut_mesh = mesh_region(over_blocks, lattice, h, shift.load(), opt.region_mesh_adaptivity);
  r.undercut_mesh = mesh_region(under_blocks, lattice, h, shift.load(), opt.region_mesh_adaptivity);
  const double hv = h * h * h;
  for (const Sum& s : sums) {
    r.overcut_volume_mm3 += s.over * hv;
    r.undercut_volume_mm3 += s.under * hv;
  }

  // Deviation at every vertex of the machined surface.
  const std::size_t nv = machined.positions.size();
  r.vertex_deviation_mm.resize(nv);
  // Neighbouring vertices are near each other in the mesher's order, and
  // distance is 1-Lipschitz: |d(v)| <= |d(u)| + |v - u| bounds the search.
  // The triangles near a recent vertex are kept: while a vertex's search
  // ball lies inside theirs, it tries only those. Which way a vertex is
  // measured (a flat stretch's plane, or its triangles) depends on the
  // vertices before it in its range, and the two differ in the last bits
  // (5e-11 mm against 0 on the four-axis case): the ranges are fixed
  // (split down to the grain, whatever the threads), so the colours are
  // the same bytes in every run.
  constexpr std::size_t kDeviationGrain = 8192;
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nv, kDeviationGrain), [&](const auto& range) {
    double last = -1;
    Vec3 last_p = Vec3::Zero();
    std::vector<unsigned> kept;
    Vec3 kept_c = Vec3::Zero();
    double kept_r = -1;
    std::optional<Target::Plane> kept_plane;
    for (std::size_t i = range.begin(); i != range.end(); ++i) {
      const Vec3& p = machined.positions[i];
      double d;
      if (last < 0) {
        d = target.signed_distance(p);
      } else {
        const double radius = (last + (p - last_p).norm()) * (1 + 1e-9) + 1e-12;
        if (radius > 8 * h) {  // far from the target: a ball that large would keep too many
          d = target.signed_distance_within(p, radius);
        } else {
        if ((p - kept_c).norm() + radius > kept_r) {
          kept_c = p;
          kept_r = radius + 6 * h;
          target.triangles_near(kept_c, kept_r, kept);
          kept_plane = target.common_plane(kept);
        }
        // The ball of `radius` around p lies in the kept one and holds
        // the surface: on a flat stretch, the plane's distance is it.
        if (kept_plane) {
          d = kept_plane->signed_distance(p);
        } else {
          const auto near = target.signed_distance_if_within(p, radius, kept);
          d = near ? *near : target.signed_distance(p);
        }
        }
      }
      r.vertex_deviation_mm[i] = static_cast<float>(d);
      last = std::fabs(d);
      last_p = p;
    }
  }, tbb::simple_partitioner());
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
