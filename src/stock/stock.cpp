#include <algorithm>
#include <array>
#include <cmath>
#include <atomic>
#include <bit>
#include <chrono>
#include <cstdint>
#include <mutex>
#include <sstream>
#include <type_traits>

#include <openvdb/tools/Interpolation.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <unistd.h>

#include "cutsim/core/error.h"
#include "cutsim/core/interrupt.h"
#include "stock_impl.h"
#include "voxel_kernels.h"

namespace cutsim::stock {

using detail::boxes_reach;
using detail::CentrePlane;
using detail::lower_by_ball_line;
using detail::lower_by_joint;
using detail::lower_by_prism;
using detail::overlap_candidates;
using detail::planes_below;
using detail::prism_distances;
using detail::quarter_offset;
using detail::quarter_reach;
using openvdb::Coord;
using openvdb::CoordBBox;
using LeafT = openvdb::FloatTree::LeafNodeType;

namespace {

constexpr int kLeafDim = 8;
constexpr int kNode1Dim = 128;
// The tree's internal nodes: 4096^3 voxels (Node2T) and 128^3 (Node1T).
using Node2T = openvdb::FloatTree::RootNodeType::ChildNodeType;
using Node1T = Node2T::ChildNodeType;
static_assert(Node1T::DIM == kNode1Dim && LeafT::DIM == kLeafDim, "the tree's 128^3 nodes and 8^3 leaves");

std::once_flag g_init;

std::size_t physical_memory_bytes() {
  const long pages = sysconf(_SC_PHYS_PAGES);
  const long page = sysconf(_SC_PAGE_SIZE);
  return pages > 0 && page > 0 ? static_cast<std::size_t>(pages) * static_cast<std::size_t>(page) : (8ull << 30);
}

// Area of the box's faces that lie within `region` (both world boxes).
double face_area_within(const Aabb& box, const Aabb& region) {
  double area = 0;
  for (int k = 0; k < 3; ++k) {
    const int u = (k + 1) % 3, v = (k + 2) % 3;
    const double du = std::max(0.0, std::min(box.max[u], region.max[u]) - std::max(box.min[u], region.min[u]));
    const double dv = std::max(0.0, std::min(box.max[v], region.max[v]) - std::max(box.min[v], region.min[v]));
    for (double c : {box.min[k], box.max[k]})
      if (c >= region.min[k] && c <= region.max[k]) area += du * dv;
  }
  return area;
}

Coord floor_coord(const Vec3& v) {
  return Coord(static_cast<int>(std::floor(v.x())), static_cast<int>(std::floor(v.y())),
               static_cast<int>(std::floor(v.z())));
}
Coord ceil_coord(const Vec3& v) {
  return Coord(static_cast<int>(std::ceil(v.x())), static_cast<int>(std::ceil(v.y())),
               static_cast<int>(std::ceil(v.z())));
}

// A profile prism's section plane at `c` (sweep::prism_section_plane),
// lowered by far more than the arithmetic's rounding (a voxel is 1e-4 mm
// or more); false for other pieces.
bool lowered_section_plane(const sweep::Primitive& p, const Vec3& c, sweep::SectionPlane* sec) {
  if (!sweep::prism_section_plane(p, c, sec)) return false;
  sec->c -= 1e-12;
  sec->lo -= 1e-12;
  sec->hi += 1e-12;
  return true;
}

// Smallest value of a leaf's 512 (x-major) values. Lanes of 8 kept apart
// and `a < b ? a : b` (what a vector min does) let the compiler vectorise;
// one running std::min is a serial chain of 511 compares.
float leaf_min(const float* v) {
  float lane[8];
  for (int k = 0; k < 8; ++k) lane[k] = v[k];
  for (int i = 8; i < 512; i += 8)
    for (int k = 0; k < 8; ++k) lane[k] = v[i + k] < lane[k] ? v[i + k] : lane[k];
  float lo = lane[0];
  for (int k = 1; k < 8; ++k) lo = std::min(lo, lane[k]);
  return lo;
}

// A value rounded to a float no greater than it.
float float_below(double x) {
  const auto f = static_cast<float>(x);
  return static_cast<double>(f) > x ? std::nextafter(f, -std::numeric_limits<float>::infinity()) : f;
}

// Smallest value of the 4^3 quarter of a leaf at offset (qx, qy, qz), the
// same way: 16 rows of 4 into 4 lanes.
float quarter_min(const float* data, int qx, int qy, int qz) {
  const float* r0 = data + ((qx << 6) | (qy << 3) | qz);
  float lane[4] = {r0[0], r0[1], r0[2], r0[3]};
  for (int x = 0; x < 4; ++x)
    for (int y = 0; y < 4; ++y) {
      const float* r = r0 + ((x << 6) | (y << 3));
      for (int k = 0; k < 4; ++k) lane[k] = r[k] < lane[k] ? r[k] : lane[k];
    }
  return std::min(std::min(lane[0], lane[1]), std::min(lane[2], lane[3]));
}

// Calls leaf(origin) for each leaf-sized block of `bb`, going down through
// the 128-, 32- and 16-voxel cubes that `keep(centre, half_diagonal,
// origin, dim)` accepts (world centre; the half diagonal reaches the cube's
// farthest voxel centre; the cube's first voxel and its width). The 16^3
// cubes too: a 32^3 block within reach of a thin piece's surface has most
// of its leaves out of reach (blade 2 um: 204 M leaves visited without
// them, 137 M with them, for 27 M more block tests). With kSubLevel the
// leaves come 16^3 cube by 16^3 cube; without it, in x, y, z order over
// the 32^3 cube (the order the contact check breaks ties in).
//
// With kSubLevel, `keep_subs` (when given) tests a 32^3 cube's 16^3 cubes
// together in place of `keep`: keep_subs(n, x, y, z, hd) returns the bits
// of those of the n centres (x[k], y[k], z[k]) to keep, as keep would.
constexpr int kMid = 1 << Stock::Impl::kBlockLog2;  // the occupancy map's blocks
static_assert(kNode1Dim == 1 << Stock::Impl::kNodeLog2, "the node map's nodes are the tree's 128^3 nodes");
constexpr int kSub = 2 * kLeafDim;

template <bool kSubLevel = false, class Keep, class Leaf, class KeepSubs = std::nullptr_t>
void for_each_leaf_block(const Vec3& origin, double h, const CoordBBox& bb, Keep keep, Leaf leaf,
                         KeepSubs keep_subs = nullptr) {
  const double hd1 = std::sqrt(3.0) * 0.5 * (kNode1Dim - 1) * h, hd2 = std::sqrt(3.0) * 0.5 * (kMid - 1) * h,
               hd3 = std::sqrt(3.0) * 0.5 * (kSub - 1) * h;
  auto centre = [&](int x, int y, int z, int dim) {
    return Vec3(origin + h * (Vec3(x, y, z).array() + 0.5 * (dim - 1)).matrix());
  };
  const Coord q0(bb.min().x() & ~(kNode1Dim - 1), bb.min().y() & ~(kNode1Dim - 1), bb.min().z() & ~(kNode1Dim - 1));
  for (int x1 = q0.x(); x1 <= bb.max().x(); x1 += kNode1Dim)
    for (int y1 = q0.y(); y1 <= bb.max().y(); y1 += kNode1Dim)
      for (int z1 = q0.z(); z1 <= bb.max().z(); z1 += kNode1Dim) {
        if (!keep(centre(x1, y1, z1, kNode1Dim), hd1, Coord(x1, y1, z1), kNode1Dim)) continue;
        CoordBBox part = CoordBBox::createCube(Coord(x1, y1, z1), kNode1Dim);
        part.intersect(bb);
        if (part.empty()) continue;
        const Coord m0(part.min().x() & ~(kMid - 1), part.min().y() & ~(kMid - 1), part.min().z() & ~(kMid - 1));
        for (int x2 = m0.x(); x2 <= part.max().x(); x2 += kMid)
          for (int y2 = m0.y(); y2 <= part.max().y(); y2 += kMid)
            for (int z2 = m0.z(); z2 <= part.max().z(); z2 += kMid) {
              if (!keep(centre(x2, y2, z2, kMid), hd2, Coord(x2, y2, z2), kMid)) continue;
              CoordBBox mid = CoordBBox::createCube(Coord(x2, y2, z2), kMid);
              mid.intersect(part);
              if (mid.empty()) continue;
              // The leaves of `blk` that `take(x, y, z)` (their first voxel) accepts, in x, y, z order.
              auto leaves_of = [&](const CoordBBox& blk, auto take) {
                const Coord p0(blk.min().x() & ~(kLeafDim - 1), blk.min().y() & ~(kLeafDim - 1),
                               blk.min().z() & ~(kLeafDim - 1));
                for (int x = p0.x(); x <= blk.max().x(); x += kLeafDim)
                  for (int y = p0.y(); y <= blk.max().y(); y += kLeafDim)
                    for (int z = p0.z(); z <= blk.max().z(); z += kLeafDim)
                      if (take(x, y, z)) leaf(Coord(x, y, z));
              };
              if constexpr (!kSubLevel) {
                // The 16^3 cubes tested first (with a hair of slack, so that
                // no leaf their test passes over would pass its own), then
                // the leaves of those kept, still in x, y, z order over the
                // 32^3 cube (the contact scan's blocks within a 32^3 cube of
                // a V tool's flank: seven leaves in eight failed their test).
                bool kept[2][2][2];
                for (int sx = 0; sx < 2; ++sx)
                  for (int sy = 0; sy < 2; ++sy)
                    for (int sz = 0; sz < 2; ++sz) {
                      const Coord so(x2 + sx * kSub, y2 + sy * kSub, z2 + sz * kSub);
                      CoordBBox sub = CoordBBox::createCube(so, kSub);
                      sub.intersect(mid);
                      kept[sx][sy][sz] = !sub.empty() && keep(centre(so.x(), so.y(), so.z(), kSub),
                                                              hd3 * (1 + 1e-12) + 1e-12, so, kSub);
                    }
                leaves_of(mid, [&](int x, int y, int z) { return kept[(x - x2) / kSub][(y - y2) / kSub][(z - z2) / kSub]; });
                continue;
              }
              const Coord s0(mid.min().x() & ~(kSub - 1), mid.min().y() & ~(kSub - 1), mid.min().z() & ~(kSub - 1));
              if constexpr (!std::is_same_v<KeepSubs, std::nullptr_t>) {
                // (The same cubes in the same order; their centres as `centre` has them.)
                std::array<Coord, 8> so;
                std::array<double, 8> cx, cy, cz;
                int n = 0;
                for (int x3 = s0.x(); x3 <= mid.max().x(); x3 += kSub)
                  for (int y3 = s0.y(); y3 <= mid.max().y(); y3 += kSub)
                    for (int z3 = s0.z(); z3 <= mid.max().z(); z3 += kSub) {
                      so[n] = Coord(x3, y3, z3);
                      cx[n] = origin.x() + h * (x3 + 0.5 * (kSub - 1));
                      cy[n] = origin.y() + h * (y3 + 0.5 * (kSub - 1));
                      cz[n] = origin.z() + h * (z3 + 0.5 * (kSub - 1));
                      ++n;
                    }
                const unsigned kept = keep_subs(n, cx.data(), cy.data(), cz.data(), hd3);
                for (int k = 0; k < n; ++k) {
                  if (!(kept >> k & 1u)) continue;
                  CoordBBox sub = CoordBBox::createCube(so[k], kSub);
                  sub.intersect(mid);
                  if (!sub.empty()) leaves_of(sub, [](int, int, int) { return true; });
                }
                continue;
              }
              for (int x3 = s0.x(); x3 <= mid.max().x(); x3 += kSub)
                for (int y3 = s0.y(); y3 <= mid.max().y(); y3 += kSub)
                  for (int z3 = s0.z(); z3 <= mid.max().z(); z3 += kSub) {
                    if (!keep(centre(x3, y3, z3, kSub), hd3, Coord(x3, y3, z3), kSub)) continue;
                    CoordBBox sub = CoordBBox::createCube(Coord(x3, y3, z3), kSub);
                    sub.intersect(mid);
                    if (!sub.empty()) leaves_of(sub, [](int, int, int) { return true; });
                  }
            }
      }
}

// Calls fn(box) for each tile above the leaves whose value passes keep, in
// no set order, reading the internal nodes' tables directly: the tree's
// value iterator took some 10 ns an entry, and a 100 mm box at 0.1 mm
// has half a million entries, nearly all of them background.
template <class Keep, class Fn>
void for_each_tile(const openvdb::FloatTree& tree, Keep keep, Fn fn) {
  const auto& root = tree.root();
  for (auto it = root.cbeginValueAll(); it; ++it)
    if (keep(*it)) fn(CoordBBox::createCube(it.getCoord(), Node2T::DIM));
  for (auto c2 = root.cbeginChildOn(); c2; ++c2) {
    const Node2T& n2 = *c2;
    const auto* t2 = n2.getTable();
    for (openvdb::Index i = 0; i < Node2T::NUM_VALUES; ++i) {
      if (!n2.getChildMask().isOn(i)) {
        if (keep(t2[i].getValue())) fn(CoordBBox::createCube(n2.offsetToGlobalCoord(i), Node1T::DIM));
        continue;
      }
      const Node1T& n1 = *t2[i].getChild();
      const auto* t1 = n1.getTable();
      for (openvdb::Index j = 0; j < Node1T::NUM_VALUES; ++j)
        if (!n1.getChildMask().isOn(j) && keep(t1[j].getValue()))
          fn(CoordBBox::createCube(n1.offsetToGlobalCoord(j), kLeafDim));
    }
  }
}

// The leaf at a leaf's origin, or null and the tile value there, read from
// the 16^3 node's tables without touching the leaf: a ValueAccessor's
// probeConstLeaf caches the leaf's buffer pointer, which reads the leaf
// node, a cache miss for each leaf where only its presence is asked (the
// blade's binning: half of its own time). Keeps the last 128^3 node.
class LeafLookup {
 public:
  explicit LeafLookup(const openvdb::FloatTree& tree) : tree_(tree) {}
  const LeafT* leaf(const Coord& o, float* tile) {
    const Coord n1(o.x() & ~(kNode1Dim - 1), o.y() & ~(kNode1Dim - 1), o.z() & ~(kNode1Dim - 1));
    if (n1 != origin_) {
      origin_ = n1;
      node_ = tree_.probeConstNode<Node1T>(n1);
      if (!node_) value_ = tree_.getValue(n1);  // one tile above the node's level
    }
    if (!node_) {
      *tile = value_;
      return nullptr;
    }
    const openvdb::Index i = Node1T::coordToOffset(o);
    if (node_->isChildMaskOn(i)) return node_->getTable()[i].getChild();
    *tile = node_->getTable()[i].getValue();
    return nullptr;
  }

 private:
  const openvdb::FloatTree& tree_;
  Coord origin_{std::numeric_limits<int>::max()};
  const Node1T* node_ = nullptr;
  float value_ = 0;
};

}  // namespace

std::size_t estimate_memory_bytes(const Aabb& box, const Aabb& roi, const StockOptions& opt) {
  const double h = opt.voxel_mm;
  const Aabb region = roi.intersected(box.expanded(opt.half_band_voxels * h + h)).expanded(8 * h);
  // Leaves straddling the faces: the band crosses a leaf boundary about
  // half the time, hence 1.5 layers; machined surfaces add about as much
  // again as the faces they replace, hence the factor 2.
  const double leaf_area = (kLeafDim * h) * (kLeafDim * h);
  const double leaves = 2.0 * 1.5 * face_area_within(box, region) / leaf_area;
  const double bytes_per_leaf = sizeof(float) * 512 + 64 + 96;
  return static_cast<std::size_t>(leaves * bytes_per_leaf) + (16u << 20);
}

Stock::Impl::LeafPlanes Stock::Impl::LeafPlanes::of_leaf(const float* data, double h, float gamma) {
  // The least value of each slab across each axis, then each axis's
  // offsets added to its slabs'. Voxels at the band's edge in air are left
  // out: a cut writes no more than that, so they never change.
  float slab[3][kLeafDim];
  for (auto& a : slab)
    for (float& v : a) v = std::numeric_limits<float>::infinity();
  for (int x = 0; x < kLeafDim; ++x)
    for (int y = 0; y < kLeafDim; ++y)
      for (int z = 0; z < kLeafDim; ++z) {
        float v = data[(x << 6) | (y << 3) | z];
        if (v >= gamma) v = std::numeric_limits<float>::infinity();
        slab[0][x] = std::min(slab[0][x], v);
        slab[1][y] = std::min(slab[1][y], v);
        slab[2][z] = std::min(slab[2][z], v);
      }
  LeafPlanes lp;
  double low = std::numeric_limits<double>::infinity();
  for (int k = 0; k < 3; ++k) {
    double up = std::numeric_limits<double>::infinity(), down = up;
    for (int i = 0; i < kLeafDim; ++i) {
      const double off = h * (i - 0.5 * (kLeafDim - 1));
      up = std::min(up, slab[k][i] + off);
      down = std::min(down, slab[k][i] - off);
      low = std::min(low, static_cast<double>(slab[k][i]));
    }
    lp.up[k] = float_below(up);
    lp.down[k] = float_below(down);
  }
  lp.low = float_below(low);
  return lp;
}

Stock::Impl::LeafPlanes Stock::Impl::LeafPlanes::of_tile(float value, double h, float gamma) {
  if (value >= gamma) value = std::numeric_limits<float>::infinity();
  LeafPlanes lp;
  lp.low = value;
  const float side = float_below(value - 0.5 * (kLeafDim - 1) * h);
  for (int k = 0; k < 3; ++k) lp.up[k] = lp.down[k] = side;
  return lp;
}

double Stock::Impl::LeafPlanes::least(const Vec3& g, double h) const {
  // Along the axis g leans most: min over the leaf of v(p) + l (p_k - c_k)
  // is concave in l (a least of lines), so above its chord from l = 0
  // (low) to l = +-1 (up, down); past +-1 (rounding) it falls at most by
  // the half extent. Each other axis adds at most |g_j| times that.
  if (low == std::numeric_limits<float>::infinity()) return low;  // all at the band's edge in air
  const double e = 0.5 * (kLeafDim - 1) * h;
  int k = 0;
  for (int j = 1; j < 3; ++j)
    if (std::fabs(g[j]) > std::fabs(g[k])) k = j;
  const double a = std::fabs(g[k]);
  const double side = g[k] > 0 ? up[k] : down[k];
  double f = a >= 1 ? side - (a - 1) * e : (1 - a) * low + a * side;
  for (int j = 0; j < 3; ++j)
    if (j != k) f -= std::fabs(g[j]) * e;
  return f;
}

void Stock::Impl::start_leaf_planes() {
  std::vector<const LeafT*> leaves;
  for (auto l = grid->tree().cbeginLeaf(); l; ++l) leaves.push_back(l.getLeaf());
  std::vector<LeafPlanes> planes(leaves.size());
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, leaves.size()), [&](const auto& r) {
    for (std::size_t i = r.begin(); i != r.end(); ++i) planes[i] = LeafPlanes::of_leaf(leaves[i]->buffer().data(), h, gamma);
  });
  leaf_planes.clear();
  leaf_planes.reserve(leaves.size());
  for (std::size_t i = 0; i < leaves.size(); ++i) leaf_planes.emplace(leaves[i]->origin(), planes[i]);
  planes_on = true;
}

void Stock::Impl::rebuild_occupancy() {
  occ.reset(kBlockLog2, grid_index);
  auto mark = [&](CoordBBox b) {
    b.intersect(grid_index);
    if (b.empty()) return;
    for (int x = b.min().x() >> kBlockLog2; x <= b.max().x() >> kBlockLog2; ++x)
      for (int y = b.min().y() >> kBlockLog2; y <= b.max().y() >> kBlockLog2; ++y)
        for (int z = b.min().z() >> kBlockLog2; z <= b.max().z() >> kBlockLog2; ++z)
          occ.set(occ.index(Coord(x << kBlockLog2, y << kBlockLog2, z << kBlockLog2)), true);
  };
  const auto& tree = grid->tree();
  for (auto l = tree.cbeginLeaf(); l; ++l) mark(CoordBBox::createCube(l->origin(), kLeafDim));
  for_each_tile(tree, [](float v) { return v <= 0; }, mark);  // (air tiles hold none)
  nodes.reset(kNodeLog2, grid_index);
  for (int x = 0; x < nodes.nx; ++x)
    for (int y = 0; y < nodes.ny; ++y)
      for (int z = 0; z < nodes.nz; ++z)
        update_node_bit(Coord((nodes.lo.x() + x) << kNodeLog2, (nodes.lo.y() + y) << kNodeLog2, (nodes.lo.z() + z) << kNodeLog2));
}

void Stock::Impl::update_node_bit(const Coord& o) {
  const std::int64_t i = nodes.index(o);
  if (i < 0) return;
  constexpr int kDim = 1 << kBlockLog2, kNode = 1 << kNodeLog2;
  bool any = false;
  for (int x = 0; x < kNode && !any; x += kDim)
    for (int y = 0; y < kNode && !any; y += kDim)
      for (int z = 0; z < kNode && !any; z += kDim) any = may_hold_material(o.offsetBy(x, y, z));
  nodes.set(i, any);
}

void Stock::Impl::refresh_occupancy(std::vector<Coord> blocks) {
  std::sort(blocks.begin(), blocks.end());
  blocks.erase(std::unique(blocks.begin(), blocks.end()), blocks.end());
  // Which of the blocks marked may-hold-material hold none now, on both
  // threads (the tree is only read; the blade's roughing at 1 um checks
  // 740k); then their bits and their nodes', on one.
  constexpr int kDim = 1 << kBlockLog2;
  std::vector<char> emptied(blocks.size(), 0);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, blocks.size(), 64), [&](const auto& r) {
    LeafLookup lookup(grid->tree());
    for (std::size_t j = r.begin(); j != r.end(); ++j) {
      const Coord& b = blocks[j];
      const std::int64_t i = occ.index(b);
      if (i < 0 || !occ.test(i)) continue;
      bool material = false;
      for (int lx = 0; lx < kDim && !material; lx += kLeafDim)
        for (int ly = 0; ly < kDim && !material; ly += kLeafDim)
          for (int lz = 0; lz < kDim && !material; lz += kLeafDim) {
            float tile = 0;
            material = lookup.leaf(b.offsetBy(lx, ly, lz), &tile) || tile <= 0;
          }
      emptied[j] = !material;
    }
  });
  constexpr int kMask = ~((1 << kNodeLog2) - 1);
  std::vector<Coord> touched;  // their nodes (in order, as the blocks are)
  for (std::size_t j = 0; j < blocks.size(); ++j) {
    if (!emptied[j]) continue;
    occ.set(occ.index(blocks[j]), false);
    const Coord node(blocks[j].x() & kMask, blocks[j].y() & kMask, blocks[j].z() & kMask);
    if (touched.empty() || touched.back() != node) touched.push_back(node);
  }
  std::sort(touched.begin(), touched.end());
  touched.erase(std::unique(touched.begin(), touched.end()), touched.end());
  for (const Coord& node : touched) update_node_bit(node);
}

double Stock::Impl::grid_volume() const {
  const auto& tree = grid->tree();
  // Material tiles: the tree's values above the leaves only (whole voxel
  // counts, so their sum does not depend on the order).
  double vol = 0;
  for_each_tile(tree, [](float v) { return v < 0; }, [&](CoordBBox tb) {
    tb.intersect(roi_index);
    if (!tb.empty()) vol += static_cast<double>(tb.volume());
  });
  // Leaves, in parallel; each leaf's sum kept apart and added in the
  // tree's order, so the figure repeats exactly.
  std::vector<const LeafT*> leaves;
  leaves.reserve(tree.leafCount());
  for (auto l = tree.cbeginLeaf(); l; ++l) leaves.push_back(l.getLeaf());
  std::vector<double> sums(leaves.size(), 0.0);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, leaves.size()), [&](const auto& r) {
    for (std::size_t i = r.begin(); i != r.end(); ++i) {
      const LeafT& leaf = *leaves[i];
      const Coord o = leaf.origin();
      const bool whole = roi_index.isInside(CoordBBox::createCube(o, kLeafDim));
      const float* data = leaf.buffer().data();
      double sum = 0;
      for (int idx = 0; idx < 512; ++idx) {
        const float v = data[idx];
        if (v >= gamma) continue;
        if (!whole && !roi_index.isInside(o.offsetBy(idx >> 6, (idx >> 3) & 7, idx & 7))) continue;
        sum += std::clamp(0.5 - static_cast<double>(v) / h, 0.0, 1.0);
      }
      sums[i] = sum;
    }
  });
  for (double s : sums) vol += s;
  return vol * h * h * h;
}

Stock::Stock(const Aabb& box, const Aabb& roi_in, const StockOptions& opt) : impl_(std::make_unique<Impl>()) {
  std::call_once(g_init, [] { openvdb::initialize(); });
  if (box.empty() || (box.size().array() <= 0).any())
    throw GeometryError({}, "the stock box is empty");
  if (!(opt.voxel_mm > 0) || !std::isfinite(opt.voxel_mm))
    throw GeometryError({}, "voxel size must be positive");
  // (Finer ended in OpenVDB's "Non-zero scale values required", an internal error.)
  if (opt.voxel_mm < kFinestVoxelMm) {
    std::ostringstream os;
    os << "voxel size " << opt.voxel_mm * 1000 << " um is finer than the stock grid can hold (" << kFinestVoxelMm * 1000
       << " um at least)";
    throw GeometryError({}, os.str());
  }
  Impl& m = *impl_;
  m.box = box;
  m.h = opt.voxel_mm;
  m.gamma = static_cast<float>(opt.half_band_voxels * m.h);
  m.max_pairs = std::max<std::size_t>(1, opt.max_update_pairs);
  m.measure_band_every = opt.measure_band_every;
  const Aabb roi = roi_in.intersected(box.expanded(m.gamma + m.h));
  if (roi.empty()) throw GeometryError({}, "the region the tools reach does not meet the stock");

  const std::size_t limit = opt.memory_limit_bytes ? opt.memory_limit_bytes : physical_memory_bytes() / 4 * 3;
  const std::size_t need = estimate_memory_bytes(box, roi, opt);
  if (need > limit) {
    // Memory scales with 1/h^2: suggest the voxel that fits.
    const double fit = m.h * std::sqrt(static_cast<double>(need) / static_cast<double>(limit)) * 1.05;
    std::ostringstream os;
    os << "the stock grid would need about " << need / (1u << 20) << " MiB at " << m.h * 1000
       << " um voxels, over the limit of " << limit / (1u << 20) << " MiB; a voxel of "
       << std::ceil(fit * 1e4) / 10 << " um or coarser would fit (or narrow the region of interest)";
    throw GeometryError({}, os.str());
  }
  const double roi_extent = roi.size().maxCoeff() / m.h;
  if (roi_extent > 1e9) throw GeometryError({}, "the region of interest spans too many voxels");

  m.origin = (roi.center() / m.h).array().round() * m.h;
  m.roi_index = CoordBBox(floor_coord((roi.min - m.origin) / m.h), ceil_coord((roi.max - m.origin) / m.h));
  m.roi = Aabb{m.origin + m.h * (Vec3(m.roi_index.min().x(), m.roi_index.min().y(), m.roi_index.min().z()).array() - 0.5).matrix(),
               m.origin + m.h * (Vec3(m.roi_index.max().x(), m.roi_index.max().y(), m.roi_index.max().z()).array() + 0.5).matrix()};
  // In whole leaves: where the padding ended inside a leaf, the leaf held
  // material on one side and air on the other, a leaf for every voxel
  // column of the material the ROI's faces cut.
  const CoordBBox pad = m.roi_index.expandBy(kLeafDim);
  m.grid_index = CoordBBox(Coord(pad.min().x() & ~(kLeafDim - 1), pad.min().y() & ~(kLeafDim - 1), pad.min().z() & ~(kLeafDim - 1)),
                           Coord(pad.max().x() | (kLeafDim - 1), pad.max().y() | (kLeafDim - 1), pad.max().z() | (kLeafDim - 1)));

  m.grid = openvdb::FloatGrid::create(m.gamma);
  m.grid->setTransform(openvdb::math::Transform::createLinearTransform(m.h));
  m.grid->setGridClass(openvdb::GRID_LEVEL_SET);
  m.grid->setName("stock");
  auto& tree = m.grid->tree();

  const double g = m.gamma;
  auto sd_at = [&](const Vec3& local) { return box_signed_distance(box, m.origin + local); };
  const Vec3 box_c = box.center(), box_half = 0.5 * (box.max - box.min);
  std::vector<Coord> leaf_origins;
  // (Tiles through an accessor, which keeps the path down from the root
  // between neighbours: the blade's listing at 1 um, which makes most of
  // its deep leaves tiles, 0.46-0.60 s -> 0.38-0.41 s.)
  openvdb::tree::ValueAccessor<openvdb::FloatTree> tiles(tree);
  const Coord lo = m.grid_index.min(), hi = m.grid_index.max();
  const Coord lo1(lo.x() & ~(kNode1Dim - 1), lo.y() & ~(kNode1Dim - 1), lo.z() & ~(kNode1Dim - 1));
  const double hd1 = std::sqrt(3.0) * 0.5 * (kNode1Dim - 1) * m.h;
  for (int x1 = lo1.x(); x1 <= hi.x(); x1 += kNode1Dim)
    for (int y1 = lo1.y(); y1 <= hi.y(); y1 += kNode1Dim)
      for (int z1 = lo1.z(); z1 <= hi.z(); z1 += kNode1Dim) {
        if (interrupted()) throw InterruptedError({}, interrupt_signal().load(), "interrupted while building the stock grid");
        const CoordBBox nb = CoordBBox::createCube(Coord(x1, y1, z1), kNode1Dim);
        CoordBBox part = nb;
        part.intersect(m.grid_index);
        if (part.empty()) continue;
        const Vec3 c1 = m.h * (Vec3(x1, y1, z1).array() + 0.5 * (kNode1Dim - 1)).matrix();
        const double s1 = sd_at(c1);
        if (s1 > g + hd1) continue;
        if (s1 < -(g + hd1) && part == nb) {
          tiles.addTile(2, nb.min(), -m.gamma, false);
          continue;
        }
        const Coord p0(part.min().x() & ~(kLeafDim - 1), part.min().y() & ~(kLeafDim - 1), part.min().z() & ~(kLeafDim - 1));
        for (int x = p0.x(); x <= part.max().x(); x += kLeafDim)
          for (int y = p0.y(); y <= part.max().y(); y += kLeafDim)
            for (int z = p0.z(); z <= part.max().z(); z += kLeafDim) {
              const CoordBBox lb = CoordBBox::createCube(Coord(x, y, z), kLeafDim);
              CoordBBox lpart = lb;
              lpart.intersect(m.grid_index);
              if (lpart.empty()) continue;
              // The box's distance over the leaf's voxel centres, exactly (a
              // bound from the centre would make a leaf of constant values
              // for every face twice in three): outside, the gap between the
              // two boxes; inside, the depth of the nearest face.
              const Vec3 cmin = m.origin + m.h * Vec3(lpart.min().x(), lpart.min().y(), lpart.min().z());
              const Vec3 cmax = m.origin + m.h * Vec3(lpart.max().x(), lpart.max().y(), lpart.max().z());
              // (As the voxels will hold them: in float, against the float band.)
              const double gap = (box.min - cmax).cwiseMax(cmin - box.max).cwiseMax(0.0).norm();
              const double depth = (cmin - box.min).cwiseMin(box.max - cmax).minCoeff();
              if (static_cast<float>(gap) >= m.gamma) continue;  // air
              if (static_cast<float>(depth) >= m.gamma && lpart == lb) {
                tiles.addTile(1, lb.min(), -m.gamma, false);
                continue;
              }
              leaf_origins.emplace_back(x, y, z);
            }
      }
  tiles.clear();
  // The leaves are made on both threads, then put in the tree on one: the
  // blade's box at 1 um has about a million, and making them (2 KB each,
  // first touched) cost two thirds of the build on one thread.
  std::vector<std::unique_ptr<LeafT>> leaves(leaf_origins.size());
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, leaves.size()), [&](const auto& r) {
    if (interrupted()) return;  // abandoned: the caller throws below
    for (std::size_t i = r.begin(); i != r.end(); ++i) {
      const Coord o = leaf_origins[i];
      leaves[i] = std::make_unique<LeafT>(o, m.gamma, false);
      LeafT* leaf = leaves[i].get();
      const bool whole = m.grid_index.isInside(CoordBBox::createCube(o, kLeafDim));
      float* data = leaf->buffer().data();
      auto& mask = leaf->getValueMask();
      // The box's distance from per-axis offsets, each axis's eight worked
      // out once per leaf (the same arithmetic as box_signed_distance at
      // each voxel, a third of the build's time when done there).
      std::array<std::array<double, kLeafDim>, 3> q;
      for (int a = 0; a < 3; ++a)
        for (int j = 0; j < kLeafDim; ++j) {
          const double p = m.origin[a] + m.h * static_cast<double>(o[a] + j);
          q[a][j] = std::abs(p - box_c[a]) - box_half[a];
        }
      // A leaf held deeper than the band on two axes (a face's, away from
      // its edges: nearly all of them) has its values along the third only:
      // there the offset on that axis is the largest or the voxel clamps to
      // -g either way. Eight distances, then copies.
      int deep_axes = 0, free_axis = 2;
      for (int a = 0; a < 3; ++a) {
        bool deep = true;
        for (int j = 0; j < kLeafDim; ++j) deep = deep && q[a][j] <= -g;
        if (deep) ++deep_axes;
        else free_axis = a;
      }
      if (whole && deep_axes >= 2) {
        std::array<float, kLeafDim> line;
        for (int j = 0; j < kLeafDim; ++j) {
          Vec3 qj(q[0][0], q[1][0], q[2][0]);
          qj[free_axis] = q[free_axis][j];
          line[static_cast<std::size_t>(j)] = static_cast<float>(std::clamp(box_signed_distance_q(qj), -g, g));
        }
        // By rows of eight along z: row n is (ix, iy) = (n >> 3, n & 7), and
        // the mask's n-th byte.
        std::uint8_t zbits = 0;
        for (int j = 0; j < kLeafDim; ++j)
          if (std::fabs(line[static_cast<std::size_t>(j)]) < m.gamma) zbits |= std::uint8_t(1u << j);
        for (openvdb::Index n = 0; n < 64; ++n) {
          float* row = data + 8 * n;
          std::uint8_t& bits = mask.getWord<std::uint8_t>(n);
          if (free_axis == 2) {
            std::copy(line.begin(), line.end(), row);
            bits = zbits;
          } else {
            const std::size_t j = free_axis == 1 ? (n & 7) : (n >> 3);
            std::fill(row, row + 8, line[j]);
            bits = (zbits >> j) & 1 ? 0xff : 0;
          }
        }
        continue;
      }
      for (int ix = 0; ix < kLeafDim; ++ix)
        for (int iy = 0; iy < kLeafDim; ++iy)
          for (int iz = 0; iz < kLeafDim; ++iz) {
            float v = m.gamma;
            if (whole || m.grid_index.isInside(o.offsetBy(ix, iy, iz))) {
              const double s = box_signed_distance_q(Vec3(q[0][ix], q[1][iy], q[2][iz]));
              v = static_cast<float>(std::clamp(s, -g, g));
            }
            const auto idx = static_cast<openvdb::Index>((ix << 6) | (iy << 3) | iz);
            data[idx] = v;
            mask.set(idx, std::fabs(v) < m.gamma);
          }
    }
  });
  if (interrupted()) throw InterruptedError({}, interrupt_signal().load(), "interrupted while building the stock grid");
  {
    openvdb::tree::ValueAccessor<openvdb::FloatTree> tacc(tree);
    for (auto& leaf : leaves) tacc.addLeaf(leaf.release());
  }
  m.initial_grid_volume = m.grid_volume();
  m.rebuild_occupancy();
}

Stock::~Stock() = default;
Stock::Stock(Stock&&) noexcept = default;
Stock& Stock::operator=(Stock&&) noexcept = default;


void Stock::subtract(const sweep::Sweep& sw) {
  std::vector<const sweep::Primitive*> prims;
  prims.reserve(sw.prims.size());
  for (const auto& p : sw.prims) prims.push_back(&p);
  subtract_prims(prims, std::vector<std::uint32_t>(prims.size(), 0));
}

void Stock::subtract(const std::vector<sweep::Sweep>& batch) {
  std::vector<const sweep::Primitive*> prims;
  std::vector<std::uint32_t> owner;
  for (std::size_t i = 0; i < batch.size(); ++i)
    for (const auto& p : batch[i].prims) {
      prims.push_back(&p);
      owner.push_back(static_cast<std::uint32_t>(i));
    }
  subtract_prims(prims, owner);
}

void Stock::release_scratch() {
  Impl& m = *impl_;
  std::vector<std::uint64_t>().swap(m.scratch_pairs);
  std::vector<std::uint64_t>().swap(m.scratch_sort);
  std::vector<double>().swap(m.scratch_d);
  std::vector<Vec3>().swap(m.scratch_g);
  m.scratch_bins.clear();
}

namespace {

// Sorts keys of `bits` significant bits, least significant 11-bit digit
// first, through `tmp`. The (leaf, piece) keys are unique, so this is the
// order std::sort gives; at 1 um the blade sorts some 10^8 of them, and the
// comparison sort on both threads took ~25 ns a key. Each pass counts and
// scatters in parallel over fixed slices (slice order kept within a digit,
// so the result is the same on any number of threads): on one thread the
// blade's sorts took 1.5 s.
void radix_sort(std::vector<std::uint64_t>& v, std::vector<std::uint64_t>& tmp, int bits) {
  if (v.size() < 2048) {
    std::sort(v.begin(), v.end());
    return;
  }
  constexpr int kDigit = 11;
  constexpr std::size_t kBuckets = std::size_t(1) << kDigit;
  // Keys per slice: up to 2^18, but at least eight slices down to 2^14
  // keys each (raster40k sorts ~100k keys a batch: one slice was one
  // thread).
  const std::size_t n = v.size();
  const std::size_t kSlice = std::clamp<std::size_t>((n + 7) / 8, std::size_t(1) << 14, std::size_t(1) << 18);
  const std::size_t slices = (n + kSlice - 1) / kSlice;
  tmp.resize(n);
  std::vector<std::size_t> count(slices * kBuckets);  // slice s's counts at s * kBuckets
  for (int shift = 0; shift < bits; shift += kDigit) {
    tbb::parallel_for(std::size_t(0), slices, [&](std::size_t sl) {
      std::size_t* c = count.data() + sl * kBuckets;
      std::fill(c, c + kBuckets, 0);
      const std::size_t e = std::min(n, (sl + 1) * kSlice);
      for (std::size_t i = sl * kSlice; i < e; ++i) ++c[(v[i] >> shift) & (kBuckets - 1)];
    });
    const std::size_t first = (v.front() >> shift) & (kBuckets - 1);
    std::size_t all = 0;
    for (std::size_t sl = 0; sl < slices; ++sl) all += count[sl * kBuckets + first];
    if (all == n) continue;  // one digit for all
    // Where each slice's keys of each digit start: digit by digit, slice by slice.
    std::size_t at = 0;
    for (std::size_t d = 0; d < kBuckets; ++d)
      for (std::size_t sl = 0; sl < slices; ++sl) {
        std::size_t& c = count[sl * kBuckets + d];
        const std::size_t k = c;
        c = at;
        at += k;
      }
    tbb::parallel_for(std::size_t(0), slices, [&](std::size_t sl) {
      std::size_t* c = count.data() + sl * kBuckets;
      const std::size_t e = std::min(n, (sl + 1) * kSlice);
      for (std::size_t i = sl * kSlice; i < e; ++i) tmp[c[(v[i] >> shift) & (kBuckets - 1)]++] = v[i];
    });
    v.swap(tmp);
  }
}

int bits_for(std::uint64_t n) {  // bits to hold 0 .. n - 1
  int b = 0;
  while (b < 64 && (std::uint64_t(1) << b) < n) ++b;
  return b;
}

// (leaf, piece) packed in one integer, sorted by leaf: the leaf's indices
// relative to the ROI's first leaf, then the piece.
struct LeafKeys {
  Coord lo;  // first leaf of the ROI, in leaf units
  int by = 0, bz = 0, bp = 0, total = 0;
  LeafKeys(const CoordBBox& roi, std::size_t pieces) {
    lo = Coord(roi.min().x() >> 3, roi.min().y() >> 3, roi.min().z() >> 3);
    const int bx = bits_for(std::uint64_t((roi.max().x() >> 3) - lo.x() + 1));
    by = bits_for(std::uint64_t((roi.max().y() >> 3) - lo.y() + 1));
    bz = bits_for(std::uint64_t((roi.max().z() >> 3) - lo.z() + 1));
    bp = bits_for(pieces);
    total = bx + by + bz + bp;
  }
  std::uint64_t key(const Coord& o, std::uint32_t piece) const {
    const std::uint64_t leaf = (std::uint64_t((o.x() >> 3) - lo.x()) << (by + bz)) |
                               (std::uint64_t((o.y() >> 3) - lo.y()) << bz) | std::uint64_t((o.z() >> 3) - lo.z());
    return (leaf << bp) | piece;
  }
  std::uint64_t leaf_of(std::uint64_t k) const { return k >> bp; }
  std::uint32_t piece(std::uint64_t k) const { return static_cast<std::uint32_t>(k & ((std::uint64_t(1) << bp) - 1)); }
  Coord origin(std::uint64_t k) const {
    const std::uint64_t leaf = k >> bp;
    const auto x = static_cast<int>(leaf >> (by + bz)), y = static_cast<int>((leaf >> bz) & ((std::uint64_t(1) << by) - 1)),
               z = static_cast<int>(leaf & ((std::uint64_t(1) << bz) - 1));
    return Coord((x + lo.x()) * 8, (y + lo.y()) * 8, (z + lo.z()) * 8);
  }
};

// A piece's distance at a block's centre as a bound for the block's voxels
// (less their offset): where the distance is 1-Lipschitz, or outside.
double bounded_key(double d, const sweep::Primitive& p) {
  return d > 0 || sweep::lipschitz(p) ? d : -std::numeric_limits<double>::infinity();
}

// Picks the leaves StockOptions::measure_band_every samples: a hash of
// the origin (MurmurHash3's 64-bit finalizer, for its mixing), so the
// same leaves in every run.
std::uint64_t leaf_hash(const Coord& o) {
  std::uint64_t x = (static_cast<std::uint64_t>(static_cast<std::uint32_t>(o.x())) << 42) ^
                    (static_cast<std::uint64_t>(static_cast<std::uint32_t>(o.y())) << 21) ^
                    static_cast<std::uint32_t>(o.z());
  x ^= x >> 33;
  x *= 0xff51afd7ed558ccdULL;
  x ^= x >> 33;
  x *= 0xc4ceb9fe1a85ec53ULL;
  return x ^ (x >> 33);
}

// The voxels of `box` (indices) nearer than `g` to one of `pieces`. A
// piece's distance is exact outside it and of the right sign inside, so
// at a voxel y from the box's centre it is at most max(d, 0) + |y| (d + |y|
// where it is 1-Lipschitz) and, for d >= 0, at least d - |y|: boxes the
// bounds settle count whole, the others are halved down to voxels.
std::uint64_t near_voxels(const Stock::Impl& m, const CoordBBox& box, const std::vector<const sweep::Primitive*>& pieces,
                          double g) {
  const Coord n = box.dim();
  const Vec3 lo = m.index_to_world(box.min());
  const Vec3 c = lo + 0.5 * m.h * Vec3(n.x() - 1, n.y() - 1, n.z() - 1);
  const double r = 0.5 * m.h * Vec3(n.x() - 1, n.y() - 1, n.z() - 1).norm();
  double up = std::numeric_limits<double>::infinity();
  bool far = true;
  for (const sweep::Primitive* p : pieces) {
    const double d = sweep::distance(*p, c);
    up = std::min(up, (d >= 0 || r == 0 || sweep::lipschitz(*p) ? d : 0.0) + r);
    far = far && d >= 0 && d - r >= g;
    if (up < g) return box.volume();
  }
  if (far || r == 0) return 0;
  std::uint64_t count = 0;
  const Coord half(std::max(1, n.x() / 2), std::max(1, n.y() / 2), std::max(1, n.z() / 2));
  for (int i = 0; i < 2; ++i)
    for (int j = 0; j < 2; ++j)
      for (int k = 0; k < 2; ++k) {
        const Coord a(box.min().x() + i * half.x(), box.min().y() + j * half.y(), box.min().z() + k * half.z());
        const Coord b(i ? box.max().x() : std::min(box.max().x(), a.x() + half.x() - 1),
                      j ? box.max().y() : std::min(box.max().y(), a.y() + half.y() - 1),
                      k ? box.max().z() : std::min(box.max().z(), a.z() + half.z() - 1));
        if (a.x() > b.x() || a.y() > b.y() || a.z() > b.z()) continue;
        count += near_voxels(m, CoordBBox(a, b), pieces, g);
      }
  return count;
}

// Leaves above this count in a piece's box are culled block by block on
// the piece's distance instead of listed whole.
constexpr std::int64_t kListLeaves = 4096;

// Pieces binned per parallel chunk, at most: a chunk is sized from the
// pairs per piece so far, so large pieces after small ones (roughing at
// 1 um: ~450k pairs each) bin at most this many before the budget is seen.
// Past that, only while the leaves of the further pieces' boxes (more
// than they can bin) fit in the room left, up to kBinChunkMax: a chunk is
// a parallel loop of its own, and raster40k's 0.5 mm moves came 64 to a
// loop, some 600 loops (its binning 0.121 -> 0.103 s in 4096s).
constexpr std::size_t kBinChunk = 64;
constexpr std::size_t kBinChunkMax = 4096;
// Keys a thread's binning array keeps between applies (Impl::scratch_bins).
constexpr std::size_t kKeepBinKeys = std::size_t(1) << 18;

// Drops from `sub` (key, index) the pieces that no voxel within `hw` (per
// axis) of `c` can have strictly nearer than the one of least key. That
// one, if its distance is its core's less a radius (a ball end, a hull, a
// torus: sweep::core_radius), is bounded above at every voxel by the
// distance to its nearest core point at c, which lies within |y|^2 / 2D of
// its tangent plane there; a piece whose lower bound (its plane at c,
// `plane(k, &value, &gradient)`, or else its key less the half diagonal
// `hd`) clears that bound everywhere in the box changes no voxel there. A
// fly-cut's leaf is reached by some 1,400 tori within the band, of which
// a few dozen can matter.
// `least`: the place in `sub` of its least (key, index).
template <class Piece, class Plane>
void drop_beyond_nearest(std::vector<std::pair<double, std::uint32_t>>& sub, std::size_t least, const Vec3& c, double hw,
                         double hd, Piece piece, Plane plane) {
  const std::uint32_t kref = sub[least].second;
  const sweep::Primitive& p0 = piece(kref);
  const double rho = sweep::core_radius(p0);
  double d0 = 0, D0 = 0;
  Vec3 g0;
  if (std::isnan(rho) || !sweep::convex_distance(p0, c, &d0, &g0) || !((D0 = d0 + rho) > 0)) return;
  constexpr double kMargin = 1e-9;  // mm: far above the arithmetic's rounding
  const double bend = 3 * hw * hw / (2 * D0);                // |y|^2 / 2D at the box's corners
  const double top = d0 + hw * g0.cwiseAbs().sum() + bend;  // the upper bound's highest
  auto beyond = [&](const std::pair<double, std::uint32_t>& e) {
    const std::uint32_t k = e.second;
    if (k == kref) return false;
    double ck = 0;
    Vec3 gk;
    if (!plane(k, &ck, &gk)) return e.first - hd >= top + kMargin;
    return ck - d0 - hw * (gk - g0).cwiseAbs().sum() - bend >= kMargin;
  };
  // (std::erase_if's, without a branch on the verdict: it went either way
  // in raster40k's quarters, and its mispredictions were a third of this.)
  std::size_t kept = 0;
  for (std::size_t i = 0; i < sub.size(); ++i) {
    const auto e = sub[i];
    sub[kept] = e;
    kept += beyond(e) ? 0 : 1;
  }
  sub.resize(kept);
}

}  // namespace

void Stock::subtract_prims(const std::vector<const sweep::Primitive*>& prims, const std::vector<std::uint32_t>& owner) {
  Impl& m = *impl_;
  if (prims.empty()) return;
  m.grid_volume_now.reset();
  auto& tree = m.grid->tree();
  const double g = m.gamma;
  const double h = m.h;
  const double hd0 = std::sqrt(3.0) * 0.5 * (kLeafDim - 1) * h;

  // 1. Bin the pieces by leaf: (leaf, piece) keys for every leaf a
  //    piece's box (grown by the band) reaches, in parallel per piece.
  // (Piece number prims.size() marks a leaf some piece holds deeper than
  // the band and the leaf's half diagonal: it becomes air whatever the
  // other pieces, so classifying it needs no distance. Only where the
  // mark fits in the key without splitting the batch: where a batch is
  // split changes which uniform leaves end as tiles, and so which of
  // equally deep voxels a contact reports.)
  const LeafKeys keys_marked(m.roi_index, prims.size() + 1);
  // (Not when measuring the bands' reach: that counts a deep leaf once per
  // move, so it needs the pieces.)
  const bool marks = keys_marked.total <= 64 && !m.measure_band_every;
  const LeafKeys keys = marks ? keys_marked : LeafKeys(m.roi_index, prims.size());
  const auto kDeep = marks ? static_cast<std::uint32_t>(prims.size()) : std::numeric_limits<std::uint32_t>::max();
  if (keys.total > 64) {
    // More pieces than the key holds beside this ROI's leaves: halves (the
    // union removed does not depend on the split).
    if (prims.size() == 1) throw GeometryError({}, "the region of interest has too many leaves to index");
    const auto mid = prims.begin() + static_cast<std::ptrdiff_t>(prims.size() / 2);
    const auto omid = owner.begin() + (mid - prims.begin());
    subtract_prims(std::vector<const sweep::Primitive*>(prims.begin(), mid), std::vector<std::uint32_t>(owner.begin(), omid));
    subtract_prims(std::vector<const sweep::Primitive*>(mid, prims.end()), std::vector<std::uint32_t>(omid, owner.end()));
    return;
  }
  if (!m.planes_on && std::any_of(prims.begin(), prims.end(),
                                  [](const sweep::Primitive* p) { return std::holds_alternative<sweep::TorusPrim>(*p); }))
    m.start_leaf_planes();
  auto t_lap = std::chrono::steady_clock::now();
  auto lap = [&t_lap](double& acc) {
    const auto t = std::chrono::steady_clock::now();
    acc += std::chrono::duration<double>(t - t_lap).count();
    t_lap = t;
  };
  // Blocks of 32^3 or 128^3 voxels that some 1-Lipschitz piece holds
  // deeper than the band and the block's half diagonal: every voxel of
  // them becomes air whatever the other pieces do, so the binning lists
  // none of their leaves (a roughing piece holds most of what it reaches
  // this way: millions of leaves at 1 um) and they are set to air first.
  struct AirBlock {
    Coord origin;
    int dim;
  };
  std::vector<std::vector<AirBlock>> air_per_prim(prims.size());
  // Steps 2-4 on the pairs binned so far (sorted here), after the blocks
  // the pieces [from, to) hold (step 1b).
  auto apply = [&](std::vector<std::uint64_t>& pairs, std::size_t from, std::size_t to) {
    std::vector<Coord> aired;  // 32^3 blocks that may now hold only air
    auto block_of = [](const Coord& o) { return Coord(o.x() & ~(kMid - 1), o.y() & ~(kMid - 1), o.z() & ~(kMid - 1)); };
    // (Leaves come in key order, a block's mostly one after another: the
    // blade's roughing listed each block 8 times, 6 M a run, to sort.)
    auto air_block = [&aired](const Coord& b) {
      if (aired.empty() || aired.back() != b) aired.push_back(b);
    };
    // 1b. Topology, on one thread: the blocks held deep inside a piece
    //    become air tiles; the pairs in them are then passed over as air.
    //    Pieces of a batch overlap, so most blocks come more than once.
    {
      std::vector<AirBlock> blocks;
      for (std::size_t i = from; i < to; ++i) {
        blocks.insert(blocks.end(), air_per_prim[i].begin(), air_per_prim[i].end());
        std::vector<AirBlock>().swap(air_per_prim[i]);
      }
      auto before = [](const AirBlock& a, const AirBlock& b) { return a.dim != b.dim ? a.dim > b.dim : a.origin < b.origin; };
      std::sort(blocks.begin(), blocks.end(), before);
      blocks.erase(std::unique(blocks.begin(), blocks.end(),
                               [](const AirBlock& a, const AirBlock& b) { return a.dim == b.dim && a.origin == b.origin; }),
                   blocks.end());
      openvdb::tree::ValueAccessor<openvdb::FloatTree> tacc(tree);
      for (const AirBlock& b : blocks) {
        if (b.dim == kNode1Dim) {
          // (the binning listed it only if one of its 32^3 blocks may hold material)
          for (int x = 0; x < kNode1Dim; x += kMid)
            for (int y = 0; y < kNode1Dim; y += kMid)
              for (int z = 0; z < kNode1Dim; z += kMid) {
                const Coord bo = b.origin.offsetBy(x, y, z);
                if (!m.may_hold_material(bo)) continue;
                aired.push_back(bo);
                ++m.blocks_aired;
                if (m.measure_band_every) m.band_voxels += kMid * kMid * kMid;
              }
          tacc.addTile(2, b.origin, m.gamma, false);
          continue;
        }
        bool changed = false;
        for (int x = 0; x < b.dim; x += kLeafDim)
          for (int y = 0; y < b.dim; y += kLeafDim)
            for (int z = 0; z < b.dim; z += kLeafDim) {
              const Coord o = b.origin.offsetBy(x, y, z);
              if (!tacc.probeLeaf(o) && tacc.getValue(o) > 0) continue;  // air already
              tacc.addTile(1, o, m.gamma, false);
              changed = true;
              if (m.measure_band_every) m.band_voxels += kLeafDim * kLeafDim * kLeafDim;
            }
        if (!changed) continue;
        aired.push_back(b.origin);
        ++m.blocks_aired;
      }
    }
    if (pairs.empty() || interrupted()) {
      m.refresh_occupancy(std::move(aired));
      lap(m.bin_s);
      return;
    }
    ++m.grid_updates;
    radix_sort(pairs, m.scratch_sort, keys.total);
    std::vector<std::size_t> group;  // start of each leaf's run of keys
    for (std::size_t i = 0; i < pairs.size(); ++i)
      if (i == 0 || keys.leaf_of(pairs[i]) != keys.leaf_of(pairs[i - 1])) group.push_back(i);
    group.push_back(pairs.size());
    const std::size_t ng = group.size() - 1;
    lap(m.bin_s);

    // 2. Classify each leaf, in parallel (the tree is only read): by the
    //    distance at its centre, a lower bound for its voxels outside the
    //    cut, against the deepest material it holds.
    enum Action : char { skip, to_air, update };
    std::vector<char> action(ng, skip);
    // Each piece's distance at the leaf's centre: outside the piece (d > 0)
    // it is exact, so d - |p - centre| bounds the piece's distance at p.
    // A ball end's piece is convex: its gradient there too, so the tangent
    // plane at the centre bounds it over the leaf (NaN for other pieces).
    std::vector<double>& pair_d = m.scratch_d;  // every entry written below
    std::vector<Vec3>& pair_g = m.scratch_g;
    pair_d.resize(pairs.size());
    pair_g.resize(pairs.size());
    // The leaves the band splits from material tiles, made here on both
    // threads with the tile's value; the topology step only links them in
    // (at 1 um, made there, their allocation and first touch held the one
    // thread for much of the step).
    std::vector<std::unique_ptr<LeafT>> fresh(ng);
    // StockOptions::measure_band_every: the voxels of leaf o that each move
    // (a run of pieces) among pairs [k0, k1) holds nearer than the band;
    // pair_d is written for them.
    const std::size_t measure = m.measure_band_every;
    auto band_reach = [&](const Coord& o, std::size_t k0, std::size_t k1, bool whole) -> std::uint64_t {
      const bool sampled = measure == 1 || leaf_hash(o) % measure == 0;
      const CoordBBox vox = CoordBBox::createCube(o, kLeafDim);
      const CoordBBox in(Coord::maxComponent(vox.min(), m.roi_index.min()), Coord::minComponent(vox.max(), m.roi_index.max()));
      std::uint64_t n = 0;
      std::vector<const sweep::Primitive*> run;
      for (std::size_t a = k0; a < k1;) {
        const std::uint32_t mv = owner[keys.piece(pairs[a])];
        double dm = std::numeric_limits<double>::infinity();  // proven: every voxel within dm + hd0
        run.clear();
        for (; a < k1 && owner[keys.piece(pairs[a])] == mv; ++a) {
          const sweep::Primitive* piece = prims[keys.piece(pairs[a])];
          dm = std::min(dm, pair_d[a] >= 0 || sweep::lipschitz(*piece) ? pair_d[a] : 0.0);
          if (!(pair_d[a] >= 0 && pair_d[a] - hd0 >= g)) run.push_back(piece);  // (else no voxel here is near)
        }
        if (whole && dm + hd0 < g) n += 512;
        else if (sampled && !run.empty()) n += near_voxels(m, in, run, g) * measure;
      }
      return n;
    };
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, ng), [&](const auto& r) {
      if (interrupted()) return;
      LeafLookup lookup(tree);
      std::uint64_t band = 0;  // (measure_band_every)
      for (std::size_t gi = r.begin(); gi != r.end(); ++gi) {
        if (interrupted()) return;
        const Coord o = keys.origin(pairs[group[gi]]);
        // Marked deep (the mark sorts last): air, and nothing to measure.
        if (keys.piece(pairs[group[gi + 1] - 1]) == kDeep) {
          action[gi] = to_air;
          continue;
        }
        // An air tile (step 1b's blocks) stays air: no distances either.
        float tile = 0;
        const LeafT* leaf = lookup.leaf(o, &tile);
        if (!leaf && tile > 0) continue;
        const Vec3 c0 = m.origin + h * (Vec3(o.x(), o.y(), o.z()).array() + 0.5 * (kLeafDim - 1)).matrix();
        const bool whole = m.roi_index.isInside(CoordBBox::createCube(o, kLeafDim));
        double d = std::numeric_limits<double>::infinity();
        for (std::size_t k = group[gi]; k < group[gi + 1]; ++k) {
          const sweep::Primitive& piece = *prims[keys.piece(pairs[k])];
          if (!sweep::convex_distance(piece, c0, &pair_d[k], &pair_g[k])) {
            pair_d[k] = sweep::distance(piece, c0);
            pair_g[k] = Vec3::Constant(std::numeric_limits<double>::quiet_NaN());
          }
          d = std::min(d, pair_d[k]);
          if (d < -(g + hd0) && whole && !measure) break;  // air, whatever the rest
        }
        if (measure) band += band_reach(o, group[gi], group[gi + 1], whole);
        if (d > g + hd0) continue;
        if (d < -(g + hd0) && whole) {
          action[gi] = to_air;
          continue;
        }
        // Only d(p) < -v(p) changes a voxel, and d(p) >= d - hd0 outside the
        // cut: a leaf whose deepest material is shallower than that stays.
        const double vmin = leaf ? leaf_min(leaf->buffer().data()) : tile;
        if (d - hd0 >= std::max(-vmin, 0.0)) continue;
        action[gi] = update;
        if (!leaf) fresh[gi] = std::make_unique<LeafT>(o, tile, false);  // tiles are inactive
      }
      if (band) m.band_voxels.fetch_add(band, std::memory_order_relaxed);
    });
    lap(m.classify_s);
    if (interrupted()) return;

    // 3. Topology, on one thread: split the material tiles the band reaches
    //    into leaves (else the cut is lost); leaves wholly inside the cut
    //    become air tiles.
    std::vector<LeafT*> leaves;
    std::vector<std::size_t> leaf_group;
    // The leaves come in key order, neighbours mostly: an accessor keeps
    // the path down from the root between them.
    openvdb::tree::ValueAccessor<openvdb::FloatTree> tacc(tree);
    for (std::size_t gi = 0; gi < ng; ++gi) {
      if (action[gi] == skip) continue;
      const Coord o = keys.origin(pairs[group[gi]]);
      if (action[gi] == to_air) {
        if (tacc.probeLeaf(o) || tacc.getValue(o) <= 0) {
          tacc.addTile(1, o, m.gamma, false);
          air_block(block_of(o));
        }
        continue;
      }
      if (fresh[gi]) {
        leaves.push_back(fresh[gi].get());
        tacc.addLeaf(fresh[gi].release());
      } else {
        leaves.push_back(tacc.touchLeaf(o));
      }
      leaf_group.push_back(gi);
    }
    if (leaves.empty()) {
      m.refresh_occupancy(std::move(aired));
      lap(m.topology_s);
      return;
    }
    lap(m.topology_s);

    // 4. Voxels, in parallel: new = max(old, -tool), clamped to the band.
    const double hd_sub = std::sqrt(3.0) * 1.5 * h;
    // A leaf with no material left becomes an air tile; one the band split
    // from a material tile but left whole, a material tile again.
    enum : char { kLeaf, kAir, kSolid };
    std::vector<char> tiled(leaves.size(), kLeaf);
    auto leaf_state = [gamma = m.gamma](const float* data) {
      bool air = true, solid = true;
      for (int idx = 0; idx < 512 && (air || solid); ++idx) {
        air = air && data[idx] >= gamma;
        solid = solid && data[idx] <= -gamma;
      }
      return air ? kAir : solid ? kSolid : kLeaf;
    };
    // A voxel's offset from its quarter's centre, and its length, by its
    // place in the quarter.
    std::array<Vec3, 64> quarter_y;
    std::array<double, 64> quarter_off, quarter_yx, quarter_yy, quarter_yz;  // (the offsets by field too)
    for (int q = 0; q < 64; ++q) {
      quarter_y[q] = Vec3(quarter_offset(q >> 4, h), quarter_offset((q >> 2) & 3, h), quarter_offset(q & 3, h));
      quarter_off[q] = quarter_y[q].norm();
      quarter_yx[q] = quarter_y[q].x();
      quarter_yy[q] = quarter_y[q].y();
      quarter_yz[q] = quarter_y[q].z();
    }
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, leaves.size()), [&](const auto& r) {
      std::vector<const sweep::Primitive*> cand;
      std::vector<Aabb> cbox;
      std::vector<double> ckey, seed_d;
      std::vector<Vec3> cgrad;
      std::vector<char> clip;  // sweep::lipschitz, asked once per leaf (it is out of line)
      // The same by field, where every piece of the leaf is convex and none
      // interior-only (a ball end's raster, a hull's finish): the quarters
      // then take their pieces four at a time (quarter_pieces).
      struct {
        std::vector<double> key, lox, loy, loz, hix, hiy, hiz, gx, gy, gz, g1, clip;
      } fields;
      std::vector<std::pair<double, std::uint32_t>> order, sub;
      // A piece near a quarter, in the order tried (positions relative to
      // the quarter's centre).
      struct Near {
        double key;  // distance at the quarter's centre (bounded_key)
        const sweep::Primitive* prim;
        const Aabb* box;
        bool plane;  // convex: d(y) >= c + grad . y
        double c;
        Vec3 grad;
        bool inner;  // only its inside matters (sweep::interior_only)
        bool section = false;  // a prism's bound instead (sweep::section_bound; c its A at the centre)
        sweep::SectionPlane sec;
      };
      std::vector<Near> near;
      // Runs of kRun pieces in that order, bounded together from their
      // planes at the quarter's centre: min c + mean grad . y - spread |y|.
      constexpr std::size_t kRun = 8;
      struct Run {
        double c, spread;
        Vec3 grad;
      };
      std::vector<Run> runs;
      if (interrupted()) return;  // the run is abandoned; stop quickly
      // (Counted per range: an atomic add per leaf bounced its cache line
      // between the threads.)
      std::uint64_t evaluated = 0, quarter_aired = 0;
      for (std::size_t i = r.begin(); i != r.end(); ++i) {
        if (interrupted()) return;
        LeafT* leaf = leaves[i];
        const std::size_t gi = leaf_group[i];
        const Coord o = leaf->origin();
        const Vec3 lmin = m.origin + h * Vec3(o.x(), o.y(), o.z());
        const Vec3 lc = lmin + Vec3::Constant(0.5 * h * (kLeafDim - 1));
        const Aabb lbox{lmin, lmin + Vec3::Constant(h * (kLeafDim - 1))};
        // Nearest pieces first, by their distance at the centre: the running
        // minimum then lets the rest be cut off by that distance less the
        // voxel's offset from the centre. That bounds a piece outside it, and
        // inside too where its distance is 1-Lipschitz there (a ball end's
        // line): the pieces a voxel is deep in are tried first, and the many
        // that overlap it less deeply are passed over. Other pieces the
        // centre is inside of have no bound (key -inf).
        order.clear();
        for (std::size_t k = group[gi]; k < group[gi + 1]; ++k) {
          const std::uint32_t id = keys.piece(pairs[k]);
          if (sweep::bounds(*prims[id]).expanded(sweep::interior_only(*prims[id]) ? 0.0 : g).overlaps(lbox))
            order.emplace_back(bounded_key(pair_d[k], *prims[id]), static_cast<std::uint32_t>(k));
        }
        if (order.empty()) {  // split from a tile for nothing
          tiled[i] = leaf_state(leaf->buffer().data());
          continue;
        }
        // Pieces no voxel of the leaf can have nearer than the nearest (its
        // quarters then do the same with their own centres).
        if (order.size() > kRun)
          drop_beyond_nearest(order, static_cast<std::size_t>(std::min_element(order.begin(), order.end()) - order.begin()),
                              lc, 0.5 * (kLeafDim - 1) * h, hd0,
                              [&](std::uint32_t k) -> const sweep::Primitive& { return *prims[keys.piece(pairs[k])]; },
                              [&](std::uint32_t k, double* c, Vec3* gr) {
                                if (std::isnan(pair_g[k].x())) return false;
                                *c = pair_d[k];
                                *gr = pair_g[k];
                                return true;
                              });
        std::sort(order.begin(), order.end());
        cand.clear();
        cbox.clear();
        ckey.clear();
        cgrad.clear();
        clip.clear();
        for (const auto& [key, k] : order) {
          cand.push_back(prims[keys.piece(pairs[k])]);
          cbox.push_back(sweep::bounds(*cand.back()));
          ckey.push_back(key);
          cgrad.push_back(pair_g[k]);
          clip.push_back(sweep::lipschitz(*cand.back()));
        }
        seed_d.resize(cand.size());
        bool fielded = true;
        for (std::size_t k = 0; k < cand.size() && fielded; ++k)
          fielded = !std::isnan(cgrad[k].x()) && !sweep::interior_only(*cand[k]);
        detail::LeafPieces leaf_pieces{};
        if (fielded) {
          auto& f = fields;
          // (Sized, then written by place: push_back's checks, twelve per
          // piece, read 5 % of raster40k's voxel step.)
          for (auto* fv : {&f.key, &f.lox, &f.loy, &f.loz, &f.hix, &f.hiy, &f.hiz, &f.gx, &f.gy, &f.gz, &f.g1, &f.clip})
            fv->resize(cand.size());
          for (std::size_t k = 0; k < cand.size(); ++k) {
            f.key[k] = ckey[k];
            f.lox[k] = cbox[k].min.x();
            f.loy[k] = cbox[k].min.y();
            f.loz[k] = cbox[k].min.z();
            f.hix[k] = cbox[k].max.x();
            f.hiy[k] = cbox[k].max.y();
            f.hiz[k] = cbox[k].max.z();
            f.gx[k] = cgrad[k].x();
            f.gy[k] = cgrad[k].y();
            f.gz[k] = cgrad[k].z();
            f.g1[k] = cgrad[k].cwiseAbs().sum();
            f.clip[k] = clip[k] ? 1.0 : 0.0;
          }
          leaf_pieces = {f.key.data(), f.lox.data(), f.loy.data(), f.loz.data(), f.hix.data(), f.hiy.data(),
                         f.hiz.data(), f.gx.data(),  f.gy.data(),  f.gz.data(),  f.g1.data(),  f.clip.data()};
        }
        const bool partial = !m.roi_index.isInside(CoordBBox::createCube(o, kLeafDim));
        float* data = leaf->buffer().data();
        auto& mask = leaf->getValueMask();
        bool air = true;
        // Calls fn(index, place in the quarter, value, centre) for each voxel
        // of the quarter at (bx, by, bz) that holds material, within the ROI.
        auto material_voxels = [&](int bx, int by, int bz, auto&& fn) {
          for (int ix = bx; ix < bx + 4; ++ix)
            for (int iy = by; iy < by + 4; ++iy)
              for (int iz = bz; iz < bz + 4; ++iz) {
                const int idx = (ix << 6) | (iy << 3) | iz;
                const float v = data[idx];
                if (v >= m.gamma) continue;
                if (partial && !m.roi_index.isInside(Coord(o.x() + ix, o.y() + iy, o.z() + iz))) continue;
                fn(idx, ((ix - bx) << 4) | ((iy - by) << 2) | (iz - bz), v, lmin + h * Vec3(ix, iy, iz));
              }
        };
        // As material_voxels, in the same order, but only for the voxels
        // whose need (-v; `inner`: min(-v, 0)) lies above `key` less their
        // offset and, with `sec`, above its section bound: those bounds
        // taken for the whole quarter first (quarter_reach), or voxel by
        // voxel where the ROI cuts the leaf.
        auto reached_voxels = [&](int bx, int by, int bz, double key, bool inner, const sweep::SectionPlane* sec,
                                  auto&& fn) {
          if (partial) {
            material_voxels(bx, by, bz, [&](int idx, int q, float v, const Vec3& p) {
              const double need = inner ? std::min(-static_cast<double>(v), 0.0) : -static_cast<double>(v);
              if (key - quarter_off[q] >= need) return;
              if (sec && sweep::section_bound(*sec, quarter_y[q]) >= need) return;
              fn(idx, q, v, p);
            });
            return;
          }
          const int first = (bx << 6) | (by << 3) | bz;
          for (std::uint64_t bits = quarter_reach(data, first, m.gamma, key, quarter_off.data(), inner, sec,
                                                  quarter_yx.data(), quarter_yy.data(), quarter_yz.data());
               bits != 0; bits &= bits - 1) {
            const int q = std::countr_zero(bits);
            const int ix = bx + (q >> 4), iy = by + ((q >> 2) & 3), iz = bz + (q & 3);
            const int idx = (ix << 6) | (iy << 3) | iz;
            fn(idx, q, data[idx], lmin + h * Vec3(ix, iy, iz));
          }
        };
        // A voxel of value v where the nearest piece is d away: -d where that
        // is more (less material), clamped to the band.
        auto cut_voxel = [&](int idx, float v, double d) {
          if (-d > v) {
            const float nv = static_cast<float>(std::min(-d, g));
            data[idx] = nv;
            mask.set(static_cast<openvdb::Index>(idx), nv < m.gamma && nv > -m.gamma);
          }
        };
        // Each 4 x 4 x 4 quarter of the leaf on its own: the pieces' distances
        // at its centre bound its voxels' more tightly than the leaf's.
        for (int sb = 0; sb < 8; ++sb) {
          const int bx = (sb >> 2) * 4, by = ((sb >> 1) & 1) * 4, bz = (sb & 1) * 4;
          const float vmin = quarter_min(data, bx, by, bz);
          if (vmin >= m.gamma) continue;  // all air: stays air
          air = false;
          const double need_max = -static_cast<double>(vmin);  // the largest -v here
          const Vec3 cb = lmin + h * Vec3(bx + 1.5, by + 1.5, bz + 1.5);
          const double oc = (cb - lc).norm();
          const double hq = 1.5 * h;  // the quarter's half width between voxel centres
          sub.clear();
          std::size_t least = 0;  // (fielded: the place of sub's least)
          if (fielded) {
            const Vec3 r = cb - lc;
            sub.resize(cand.size());
            int at = 0;
            sub.resize(static_cast<std::size_t>(detail::quarter_pieces(
                leaf_pieces, static_cast<int>(cand.size()), {cb.x(), cb.y(), cb.z(), r.x(), r.y(), r.z(), oc, need_max, hd_sub, hq},
                seed_d.data(), sub.data(), &at)));
            least = static_cast<std::size_t>(at);
          } else {
            for (std::size_t k = 0; k < cand.size(); ++k) {
              if (ckey[k] - oc - hd_sub >= need_max) break;  // and every piece after it
              const double b2 = sweep::detail::box_distance2(cbox[k], cb);
              const bool inner = sweep::interior_only(*cand[k]);  // matters only where negative
              const double reach = (inner ? std::min(need_max, 0.0) : need_max) + hd_sub;
              if (b2 > 0 && (reach <= 0 || b2 >= reach * reach)) continue;
              const Vec3& gl = cgrad[k];
              double dk;
              if (!std::isnan(gl.x())) {
                // Convex: the tangent plane at the leaf's centre, at its lowest
                // over the quarter's voxels, bounds the piece there; its value
                // at the quarter's centre (a lower bound, so a valid key) seeds
                // the voxels' bounds.
                dk = ckey[k] + gl.dot(cb - lc);
                if (dk - hq * gl.cwiseAbs().sum() >= need_max) continue;
                seed_d[k] = dk;
              } else {
                dk = sweep::distance_inline(*cand[k], cb);
                seed_d[k] = std::numeric_limits<double>::quiet_NaN();
              }
              const double key = dk > 0 || clip[k] ? dk : -std::numeric_limits<double>::infinity();  // bounded_key
              if (key - hd_sub >= (inner ? std::min(need_max, 0.0) : need_max)) continue;
              sub.emplace_back(key, static_cast<std::uint32_t>(k));
            }
          }
          if (sub.empty()) continue;
          // Pieces no voxel of the quarter can have nearer than the nearest.
          if (sub.size() > kRun)
            drop_beyond_nearest(sub, fielded ? least : static_cast<std::size_t>(std::min_element(sub.begin(), sub.end()) - sub.begin()),
                                cb, hq, hd_sub, [&](std::uint32_t k) -> const sweep::Primitive& { return *cand[k]; },
                                [&](std::uint32_t k, double* c, Vec3* gr) {
                                  if (std::isnan(seed_d[k])) return false;
                                  *c = seed_d[k];
                                  *gr = cgrad[k];
                                  return true;
                                });
          std::sort(sub.begin(), sub.end());
          // A quarter deeper inside one 1-Lipschitz piece than the band and
          // its half diagonal: each voxel's distance is at most -g, so each is
          // clamped to air whatever the other pieces (what the voxel loop
          // would write, without a distance per voxel). The old surface's
          // band under a cut is mostly such quarters.
          if (const sweep::Primitive& p0 = *cand[sub[0].second];
              clip[sub[0].second] && sweep::distance_inline(p0, cb) + hd_sub <= -g - 1e-6 * h) {
            material_voxels(bx, by, bz, [&](int idx, int, float, const Vec3&) {
              data[idx] = m.gamma;
              mask.setOff(static_cast<openvdb::Index>(idx));
              ++quarter_aired;
            });
            continue;
          }
          // One piece (two in three of the snowflake's evaluated voxels, two
          // in five of the blade's): the loop below without its bookkeeping,
          // to the same values. Until a voxel is evaluated (for good, where
          // the piece is 1-Lipschitz and the loop below would then try it
          // first, unbounded) the piece's plane at the centre and its box
          // may pass a voxel over; after that, whatever else would bound it
          // saves some 3 % of the distances for more than that in upkeep.
          if (sub.size() == 1) {
            const std::size_t k0 = sub[0].second;
            const sweep::Primitive& p0 = *cand[k0];
            const double key0 = sub[0].first, c0 = seed_d[k0];
            const bool seeded = !std::isnan(c0), reuse0 = clip[k0] != 0;
            const Vec3 g0 = cgrad[k0];
            const Aabb& box0 = cbox[k0];
            const bool inner = sweep::interior_only(p0);
            bool bounded = true;
            // A profile prism's section plane at the centre: over the whole
            // quarter, then at each voxel. (A fifth of the snowflake's
            // voxels the key left were passed over by it; a quarter of its
            // one-piece quarters changed no voxel.)
            sweep::SectionPlane sec;
            const bool sectioned = !seeded && !inner && lowered_section_plane(p0, cb, &sec);
            if (sectioned && sweep::section_bound_over(sec, hq) >= need_max) continue;
            // A profile prism's distances (the snowflake's V tool), four
            // at a time once the voxels that need one are listed.
            const auto* pp0 = std::get_if<sweep::ProfilePrim>(&p0);
            const bool listed = !inner && pp0 && pp0->prism;
            struct Listed {
              std::array<int, 64> idx;
              std::array<float, 64> v;
              std::array<double, 64> px, py, pz, d;
            };
            Listed list;
            int nl = 0;
            reached_voxels(bx, by, bz, key0, inner, sectioned ? &sec : nullptr, [&](int idx, int q, float v, const Vec3& p) {
              const double need = inner ? std::min(-static_cast<double>(v), 0.0) : -static_cast<double>(v);
              ++evaluated;
              if (bounded) {
                if (seeded && c0 + g0.dot(quarter_y[q]) >= need) return;
                const double b2 = sweep::detail::box_distance2(box0, p);
                if (b2 > 0 && (need <= 0 || b2 >= need * need)) return;
                bounded = !reuse0;
              }
              if (listed) {
                const auto i = static_cast<std::size_t>(nl++);
                list.idx[i] = idx;
                list.v[i] = v;
                list.px[i] = p.x();
                list.py[i] = p.y();
                list.pz[i] = p.z();
              } else if (!inner) {
                cut_voxel(idx, v, sweep::distance_inline(p0, p));
              } else if (const double d = sweep::distance_below(p0, p, need); d < need) {
                cut_voxel(idx, v, d);  // (else only a bound, and the voxel stays)
              }
            });
            if (nl > 0) {
              // (A voxel's cut changes only its own value: the list's
              // voxels read theirs before any was cut.)
              prism_distances(*pp0, nl, list.px.data(), list.py.data(), list.pz.data(), list.d.data());
              for (std::size_t i = 0; i < static_cast<std::size_t>(nl); ++i) cut_voxel(list.idx[i], list.v[i], list.d[i]);
            }
            continue;
          }
          // Every piece 1-Lipschitz (a ball end's raster, a hull's 5-axis
          // finish, a V tool's planing with its joints): piece by piece over
          // the quarter's voxels, nearest first, each voxel taking a piece
          // only where a bound leaves it below the voxel's bar (its value,
          // or the nearest piece so far; a joint's, below zero too): a
          // convex piece's plane at the centre, else its value at the voxel
          // it was last evaluated at less the step (starting from its key at
          // the centre), and its box. The bar falls with each piece; a piece
          // passed over cannot be nearer than it, so each voxel ends with
          // what the loop below would give it (the least distance where it
          // is below -v, a joint's only where negative, clamped alike beyond
          // -g), in a loop over a few pieces per quarter instead of a few
          // tests per piece per voxel.
          bool lipschitz_all = true;
          for (const auto& [key, k] : sub) lipschitz_all = lipschitz_all && clip[k];
          if (lipschitz_all) {
            // The quarter's voxels that may change ("bars"), by field: the
            // planes' test runs over them in a loop of its own, before any
            // distance (a voxel's bar depends only on its own pieces, so
            // the order does not matter).
            struct Bars {
              std::array<int, 64> idx;
              std::array<float, 64> v;
              std::array<double, 64> d;     // nearest piece's distance so far
              std::array<double, 64> need;  // -v
              std::array<double, 64> yx, yy, yz;  // offset from the quarter's centre
              std::array<double, 64> px, py, pz;  // the voxel's centre
            };
            Bars bars;
            int nb = 0;
            reached_voxels(bx, by, bz, sub[0].first, false, nullptr, [&](int idx, int q, float v, const Vec3& p) {
              const auto b = static_cast<std::size_t>(nb++);
              bars.idx[b] = idx;
              bars.v[b] = v;
              bars.d[b] = std::numeric_limits<double>::infinity();
              bars.need[b] = -static_cast<double>(v);
              bars.yx[b] = quarter_y[q].x();
              bars.yy[b] = quarter_y[q].y();
              bars.yz[b] = quarter_y[q].z();
              bars.px[b] = p.x();
              bars.py[b] = p.y();
              bars.pz[b] = p.z();
            });
            evaluated += static_cast<std::uint64_t>(nb);
            for (const auto& [key, k] : sub) {
              const sweep::Primitive& pk = *cand[k];
              const Aabb& bk = cbox[k];
              // The voxels one piece may lower: `inner` a joint's (only its
              // inside counts), `plane` whether its plane at the centre bounds
              // it, `boxed` whether its box is tested too.
              auto take = [&](auto&& dist, auto inner, auto plane, auto boxed) {
                // The piece's distance at a voxel, lowering its bar.
                auto evaluate = [&](std::size_t b, double lim) {
                  const double dj = dist(Vec3(bars.px[b], bars.py[b], bars.pz[b]), lim);
                  if constexpr (inner) {
                    if (dj < lim) bars.d[b] = dj;  // (else only a bound)
                  } else {
                    bars.d[b] = std::min(bars.d[b], dj);
                  }
                  return dj;
                };
                // A voxel whose bar is above the piece's bound there: its box,
                // then its distance.
                auto at_voxel = [&](std::size_t b, double lim) {
                  if constexpr (boxed) {
                    const double b2 = sweep::detail::box_distance2(bk, Vec3(bars.px[b], bars.py[b], bars.pz[b]));
                    if (b2 > 0 && (lim <= 0 || b2 >= lim * lim)) return;
                  }
                  evaluate(b, lim);
                };
                if constexpr (plane) {
                  static_assert(!inner, "a joint has no plane");
                  const double ck = seed_d[k], gx = cgrad[k].x(), gy = cgrad[k].y(), gz = cgrad[k].z();
                  // (-g: clamped to air whatever the rest)
                  for (std::uint64_t below = planes_below(bars.d.data(), bars.need.data(), bars.yx.data(), bars.yy.data(),
                                                          bars.yz.data(), nb, {ck, gx, gy, gz}, -g);
                       below != 0; below &= below - 1) {
                    const auto b = static_cast<std::size_t>(std::countr_zero(below));
                    at_voxel(b, std::min(bars.d[b], bars.need[b]));
                  }
                } else {
                  static_assert(decltype(boxed)::value, "the cone's voxels are those its box leaves");
                  double cc = key;  // cone: the value at `at` (first, the key at the centre)
                  Vec3 at = Vec3::Zero();
                  // The voxels not clamped to air (at or below -g: air
                  // whatever the rest) that the box leaves, first (its test
                  // does not depend on the order), then the cone's test.
                  for (std::uint64_t reach = boxes_reach(bars.d.data(), bars.need.data(), bars.px.data(), bars.py.data(),
                                                         bars.pz.data(), nb, bk, inner, -g);
                       reach != 0; reach &= reach - 1) {
                    const auto b = static_cast<std::size_t>(std::countr_zero(reach));
                    const double thr = std::min(bars.d[b], bars.need[b]);
                    const double lim = inner ? std::min(thr, 0.0) : thr;
                    // (On squared lengths: a fly-cutter's tori all cut within
                    // a voxel of each other, and a root per test was a
                    // quarter of the update there.)
                    const Vec3 y(bars.yx[b], bars.yy[b], bars.yz[b]);
                    const double margin = cc - lim;
                    if (margin >= 0 && margin * margin >= (y - at).squaredNorm()) continue;
                    const double dj = evaluate(b, lim);
                    cc = dj;  // (a joint's: at most its value, still a bound)
                    at = y;
                  }
                }
              };
              using yes = std::true_type;
              using no = std::false_type;
              const bool seeded = !std::isnan(seed_d[k]);
              // (Where the CPU has AVX2, a V tool's prism, the snowflake's
              // piece, and its joints: what the cone below does, without
              // it, in fours. Of the voxels the box leaves the cone passed
              // over a third; four at a time the rest cost less than the
              // cone's one by one. The portable versions keep the cone.)
              const bool wide = use_avx2();
              const auto* jp = wide ? std::get_if<sweep::JointPrim>(&pk) : nullptr;
              const auto* pp = wide ? std::get_if<sweep::ProfilePrim>(&pk) : nullptr;
              if (jp) {
                lower_by_joint(*jp, boxes_reach(bars.d.data(), bars.need.data(), bars.px.data(), bars.py.data(),
                                                bars.pz.data(), nb, bk, true, -g),
                               bars.px.data(), bars.py.data(), bars.pz.data(), bars.need.data(), bars.d.data());
              } else if (sweep::interior_only(pk)) {
                take([&pk](const Vec3& x, double lim) { return sweep::distance_below(pk, x, lim); }, yes{}, no{}, yes{});
              } else if (const auto* lp = std::get_if<sweep::LinearPrim>(&pk); lp && lp->env.disk_radius == 0 && seeded) {
                // (A ball end's line, the raster's piece, with its arithmetic
                // inlined; where its plane passes a voxel its box passed over
                // 4 % of raster40k's: the test cost more than the distances.)
                // (what take(ball_line_distance, no, yes, no) does, in fours)
                lower_by_ball_line(*lp,
                                   planes_below(bars.d.data(), bars.need.data(), bars.yx.data(), bars.yy.data(),
                                                bars.yz.data(), nb, {seed_d[k], cgrad[k].x(), cgrad[k].y(), cgrad[k].z()}, -g),
                                   bars.px.data(), bars.py.data(), bars.pz.data(), bars.d.data());
              } else if (seeded) {
                take([&pk](const Vec3& x, double) { return sweep::distance_inline(pk, x); }, no{}, yes{}, yes{});
              } else if (pp && pp->prism) {
                lower_by_prism(*pp, boxes_reach(bars.d.data(), bars.need.data(), bars.px.data(), bars.py.data(),
                                                bars.pz.data(), nb, bk, false, -g),
                               bars.px.data(), bars.py.data(), bars.pz.data(), bars.d.data());
              } else {
                take([&pk](const Vec3& x, double) { return sweep::distance_inline(pk, x); }, no{}, no{}, yes{});
              }
            }
            for (int b = 0; b < nb; ++b) {
              const auto i = static_cast<std::size_t>(b);
              cut_voxel(bars.idx[i], bars.v[i], bars.d[i]);
            }
            continue;
          }
          // Some piece not 1-Lipschitz (a general line, a profile prism
          // sheared sideways or with a round nose): voxel by voxel, each
          // trying the pieces nearest first and only those its plane at the
          // centre (a convex piece's), its key and its box leave below the
          // bar (no bound from a value at another voxel: a first-order
          // distance would make the voxels depend on the order the pieces
          // are tried in).
          near.clear();
          for (const auto& [key, k] : sub) {
            Near& n = near.emplace_back(
                Near{key, cand[k], &cbox[k], false, 0, Vec3::Zero(), sweep::interior_only(*cand[k]), false, {}});
            if (!std::isnan(seed_d[k])) {  // a convex piece's plane at the centre
              n.plane = true;
              n.c = seed_d[k];
              n.grad = cgrad[k];
            } else if (lowered_section_plane(*cand[k], cb, &n.sec)) {
              // A round nose's or a sideways prism's section plane (a voxel
              // inside several, as a slow tool servo's turns overlap, then
              // takes only those it leaves below the deepest so far).
              n.section = true;
              n.c = n.sec.c;
            }
          }
          // The pieces with no bound from their key (inside, not 1-Lipschitz)
          // come first, in any order (each voxel takes the least of the
          // pieces no bound passes over): the deepest sections first, so
          // that the rest are passed over.
          {
            const auto unkeyed = std::partition_point(near.begin(), near.end(), [](const Near& n) {
              return n.key == -std::numeric_limits<double>::infinity();
            });
            std::stable_sort(near.begin(), unkeyed, [](const Near& a, const Near& b) {
              return (a.section ? a.c : std::numeric_limits<double>::infinity()) <
                     (b.section ? b.c : std::numeric_limits<double>::infinity());
            });
          }
          // A run whose pieces are all convex gets one bound for all of them
          // (its planes at the centre are nearly parallel where many short
          // pieces of one path pass a voxel); else it is never skipped whole.
          runs.clear();
          for (std::size_t j0 = 0; j0 < near.size(); j0 += kRun) {
            const std::size_t j1 = std::min(j0 + kRun, near.size());
            Run r{std::numeric_limits<double>::infinity(), 0, Vec3::Zero()};
            bool convex = true;
            for (std::size_t j = j0; j < j1; ++j) {
              convex = convex && near[j].plane;
              r.c = std::min(r.c, near[j].c);
              r.grad += near[j].grad;
            }
            if (!convex) {
              runs.push_back({-std::numeric_limits<double>::infinity(), 0, Vec3::Zero()});
              continue;
            }
            r.grad /= static_cast<double>(j1 - j0);
            for (std::size_t j = j0; j < j1; ++j) r.spread = std::max(r.spread, (near[j].grad - r.grad).norm());
            runs.push_back(r);
          }
          material_voxels(bx, by, bz, [&](int idx, int q, float v, const Vec3& p) {
            const Vec3& y = quarter_y[q];  // p - cb
            const double off = quarter_off[q];
            const double need = -static_cast<double>(v);
            if (near[0].key - off >= need) return;
            // Only d < -v changes the voxel; a piece farther than that (or
            // than the nearest piece so far) cannot matter.
            double d = std::numeric_limits<double>::infinity();
            for (std::size_t j = 0; j < near.size() && d > -g; ++j) {  // at -g: clamped to air whatever the rest
              const double thr = std::min(d, need);
              const Near& n = near[j];
              if (n.key - off >= thr) break;  // and every piece after it
              // (A joint's outside is no nearer than its prisms: it matters
              // only where it is negative; its value at or above `lim` is
              // only a bound, and not a candidate.)
              const double lim = n.inner ? std::min(thr, 0.0) : thr;
              if (n.inner && n.key - off >= lim) continue;
              if (j % kRun == 0) {
                const Run& r = runs[j / kRun];
                if (r.c + r.grad.dot(y) - r.spread * off >= thr) {
                  j += kRun - 1;  // the whole run
                  continue;
                }
              }
              if (n.plane && n.c + n.grad.dot(y) >= lim) continue;
              if (n.section && sweep::section_bound(n.sec, y) >= lim) continue;
              const double b2 = sweep::detail::box_distance2(*n.box, p);
              if (b2 > 0 && (lim <= 0 || b2 >= lim * lim)) continue;
              const double dj = n.inner ? sweep::distance_below(*n.prim, p, lim) : sweep::distance_inline(*n.prim, p);
              if (n.inner && dj >= lim) continue;
              d = std::min(d, dj);
            }
            ++evaluated;
            cut_voxel(idx, v, d);
          });
        }
        tiled[i] = air ? kAir : leaf_state(data);
      }
      m.voxel_evaluations.fetch_add(evaluated, std::memory_order_relaxed);
      m.voxels_aired.fetch_add(quarter_aired, std::memory_order_relaxed);
    });
    if (m.planes_on) {  // the leaves as the update left them
      std::vector<Impl::LeafPlanes> planes(leaves.size());
      tbb::parallel_for(tbb::blocked_range<std::size_t>(0, leaves.size()), [&](const auto& r) {
        for (std::size_t i = r.begin(); i != r.end(); ++i)
          if (tiled[i] == kLeaf) planes[i] = Impl::LeafPlanes::of_leaf(leaves[i]->buffer().data(), h, m.gamma);
      });
      for (std::size_t i = 0; i < leaves.size(); ++i) {
        if (tiled[i] == kLeaf) m.leaf_planes.insert_or_assign(leaves[i]->origin(), planes[i]);
        else m.leaf_planes.erase(leaves[i]->origin());
      }
    }
    lap(m.voxels_s);
    tacc.clear();  // (the voxel step changed no topology; tiles from here)
    for (std::size_t i = 0; i < leaves.size(); ++i) {
      if (tiled[i] == kLeaf) continue;
      const Coord o = leaves[i]->origin();
      if (tiled[i] == kAir) air_block(block_of(o));
      tacc.addTile(1, o, tiled[i] == kAir ? m.gamma : -m.gamma, false);
    }
    m.refresh_occupancy(std::move(aired));
    lap(m.topology_s);
  };

  // 1, in chunks of pieces: the pairs binned so far are applied whenever
  // they pass max_pairs (about 40 bytes each while they are: the key, the
  // piece's distance and gradient at the leaf's centre), so the binning's
  // memory is bounded by what the
  // pieces really reach, not by their boxes (a roughing piece at 1 um
  // reaches some 450k leaves). Where a batch is split follows the counts
  // only, so runs repeat exactly; the union removed does not depend on it.
  // (Each thread's pairs go to its own array, m.scratch_bins; which thread
  // binned a piece changes only their order before the sort.)
  auto binned_now = [&m] {
    std::size_t n = 0;
    for (const auto& v : m.scratch_bins) n += v.size();
    return n;
  };
  for (auto& v : m.scratch_bins) v.clear();  // (an interrupted update may have left some)
  // A piece's voxel box (grown by the band where it reaches out) in the
  // ROI, and the leaves it spans: no more than it can bin.
  auto piece_box = [&](const sweep::Primitive& p) {
    // (A piece whose inside only matters reaches no farther than its box.)
    const double reach = sweep::interior_only(p) ? 0.0 : g;
    const Aabb wb = sweep::bounds(p).expanded(reach + h);
    CoordBBox bb(floor_coord((wb.min - m.origin) / h), ceil_coord((wb.max - m.origin) / h));
    bb.intersect(m.roi_index);
    return bb;
  };
  auto box_leaves = [](const CoordBBox& bb) -> std::int64_t {
    if (bb.empty()) return 0;
    return std::int64_t((bb.max().x() >> 3) - (bb.min().x() >> 3) + 1) * ((bb.max().y() >> 3) - (bb.min().y() >> 3) + 1) *
           ((bb.max().z() >> 3) - (bb.min().z() >> 3) + 1);
  };
  auto bin = [&](const tbb::blocked_range<std::size_t>& r) {
    for (std::size_t i = r.begin(); i != r.end(); ++i) {
      if (interrupted()) return;  // abandoned: the caller throws
      const sweep::Primitive& p = *prims[i];
      const double reach = sweep::interior_only(p) ? 0.0 : g;
      const CoordBBox bb = piece_box(p);
      if (bb.empty()) continue;
      auto& out = m.scratch_bins.local();
      const auto id = static_cast<std::uint32_t>(i);
      const std::int64_t nl = box_leaves(bb);
      // Only the leaves step 2 would not pass over (the same test on the
      // same value), so they are neither sorted nor visited again: air
      // tiles, and leaves beyond the piece's reach. A long tool's piece
      // (a 3 mm flute on a tilted axis) has its box mostly in air or far
      // from its slanted core.
      LeafLookup lookup(tree);
      // The piece's least distance at the voxels of a cube about c (half
      // diagonal hd), `d` its distance at c: d - hd (outside, where it is
      // exact; the tests below use it only above 0), and for a torus on its
      // cutting side its tangent plane's least over the cube, tighter where
      // the surface lies along the cube's faces (a flat floor: 3.5 voxels,
      // not 6.1, for a leaf). Passing over more leaves here changes no
      // voxel: the plane bounds each of them above the band.
      // (A fly-cutter's torus: its binning and classifying fell 12 %. A
      // ball line's or a hull's plane cost more than it saved: raster40k's
      // binning 0.080 -> 0.092 s, the blade's at 2 um 2.44 -> 2.76 s.)
      const bool planes = std::holds_alternative<sweep::TorusPrim>(p);
      // (A ball end's line, the raster's piece, its distance inlined: what
      // sweep::distance gives it, less the call and dispatch per block.)
      const auto* ball = std::get_if<sweep::LinearPrim>(&p);
      if (ball && ball->env.disk_radius != 0) ball = nullptr;
      auto least = [&](const Vec3& c, double hd, double* d, Vec3* plane = nullptr) {
        Vec3 gr;
        if (!planes || !sweep::convex_distance(p, c, d, &gr)) {
          *d = ball ? sweep::detail::ball_line_distance(*ball, c) : sweep::distance(p, c);
          return *d - hd;
        }
        if (plane) *plane = gr;
        return std::max(*d - hd, *d - hd / std::sqrt(3.0) * gr.cwiseAbs().sum());
      };
      // Lists leaf o, which the piece reaches at distance d from its centre
      // (marked deep: the test step 2 makes on the smallest distance).
      auto list = [&](const Coord& o, double d) {
        const bool deep = marks && d < -(g + hd0) && m.roi_index.isInside(CoordBBox::createCube(o, kLeafDim));
        out.push_back(keys.key(o, deep ? kDeep : id));
      };
      auto leaf = [&](const Coord& o) {
        float tile_value = 0;
        const LeafT* lf = lookup.leaf(o, &tile_value);
        if (!lf && tile_value > 0) return;  // air tile
        const Vec3 c0 = m.origin + h * (Vec3(o.x(), o.y(), o.z()).array() + 0.5 * (kLeafDim - 1)).matrix();
        double d = 0;
        Vec3 gr = Vec3::Constant(std::numeric_limits<double>::quiet_NaN());
        if (least(c0, hd0, &d, &gr) > reach) return;
        // Its plane against the leaf's material (Impl::LeafPlanes): where
        // that leaves d(p) + v(p) >= 0 at every voxel, none changes. (The
        // margin: far above the arithmetic's rounding, far below a voxel.
        // Not when measuring the bands' reach: that counts such leaves.)
        if (m.planes_on && !m.measure_band_every && !std::isnan(gr.x())) {
          const Impl::LeafPlanes* lp = nullptr;
          Impl::LeafPlanes tile;
          if (lf) {
            const auto it = m.leaf_planes.find(o);
            if (it != m.leaf_planes.end()) lp = &it->second;
          } else {
            tile = Impl::LeafPlanes::of_tile(tile_value, h, m.gamma);
            lp = &tile;
          }
          if (lp && d + lp->least(gr, h) >= 1e-6 * h) return;
        }
        list(o, d);
      };
      // A ball end's line: the leaves that are not air are held and their
      // distances worked out eight at a time (lower_by_ball_line: four at
      // a time with AVX2, the same bits), then tested as `leaf` does. (The
      // order keys are listed in does not matter: they are sorted.)
      struct Held {
        std::array<Coord, 8> o;
        std::array<double, 8> x, y, z, d;
        int n = 0;
      } held;
      auto flush_held = [&] {
        if (held.n == 0) return;
        std::fill_n(held.d.begin(), held.n, std::numeric_limits<double>::infinity());
        lower_by_ball_line(*ball, (std::uint64_t(1) << held.n) - 1, held.x.data(), held.y.data(), held.z.data(),
                           held.d.data());
        for (std::size_t k = 0; k < static_cast<std::size_t>(held.n); ++k)
          if (!(held.d[k] - hd0 > reach)) list(held.o[k], held.d[k]);  // (as `leaf` tests)
        held.n = 0;
      };
      auto ball_leaf = [&](const Coord& o) {
        float tile_value = 0;
        const LeafT* lf = lookup.leaf(o, &tile_value);
        if (!lf && tile_value > 0) return;  // air tile
        const auto k = static_cast<std::size_t>(held.n++);
        held.o[k] = o;
        held.x[k] = m.origin.x() + h * (o.x() + 0.5 * (kLeafDim - 1));
        held.y[k] = m.origin.y() + h * (o.y() + 0.5 * (kLeafDim - 1));
        held.z[k] = m.origin.z() + h * (o.z() + 0.5 * (kLeafDim - 1));
        if (held.n == 8) flush_held();
      };
      const bool lip = sweep::lipschitz(p);
      if (nl <= kListLeaves && !lip) {
        for (int x = bb.min().x() & ~7; x <= bb.max().x(); x += kLeafDim)
          for (int y = bb.min().y() & ~7; y <= bb.max().y(); y += kLeafDim)
            for (int z = bb.min().z() & ~7; z <= bb.max().z(); z += kLeafDim) leaf(Coord(x, y, z));
      } else {
        auto keep = [&](const Vec3& c, double hd, const Coord& bo, int dim) {
          if (dim == kMid && !m.may_hold_material(bo)) return false;
          if (dim == kNode1Dim && !m.node_may_hold_material(bo)) return false;
          double d = 0;
          if (least(c, hd, &d) > reach) return false;
          if (dim == kSub) return true;  // (blocks set to air whole are the occupancy map's: 32^3 or 128^3)
          // Each voxel's distance is then at most -g: air (step 1b).
          if (lip && d <= -(g + hd) && m.roi_index.isInside(CoordBBox::createCube(bo, dim))) {
            air_per_prim[i].push_back({bo, dim});
            return false;
          }
          return true;
        };
        if (ball) {
          // (A 32^3 cube's 16^3 cubes, eight at a time: `least`'s test, the same bits.)
          // (flush_held's test, for cubes, written out again: through one
          // lambda shared by both, the binning read 2-4 ms slower in
          // alternating runs.)
          auto keep_subs = [&](int n, const double* x, const double* y, const double* z, double hd) {
            std::array<double, 8> d;
            d.fill(std::numeric_limits<double>::infinity());
            lower_by_ball_line(*ball, (std::uint64_t(1) << n) - 1, x, y, z, d.data());
            unsigned kept = 0;
            for (int k = 0; k < n; ++k)
              if (!(d[k] - hd > reach)) kept |= 1u << k;
            return kept;
          };
          for_each_leaf_block<true>(m.origin, h, bb, keep, ball_leaf, keep_subs);
          flush_held();
        } else {
          for_each_leaf_block<true>(m.origin, h, bb, keep, leaf);
        }
      }
    }
  };
  std::size_t first = 0, binned = 0, pairs_total = 0;  // first piece not applied; pairs since, in all
  for (std::size_t c0 = 0; c0 < prims.size();) {
    // Chunks sized from the pairs per piece so far, to stop near the budget.
    const std::size_t per = c0 > 0 ? std::max<std::size_t>(1, pairs_total / c0) : std::max<std::size_t>(1, m.max_pairs / 8);
    const std::size_t room = m.max_pairs > binned ? m.max_pairs - binned : 1;
    const std::size_t want = std::min(prims.size(), c0 + std::clamp<std::size_t>(room / per, 1, kBinChunkMax));
    std::size_t c1 = std::min(want, c0 + std::clamp<std::size_t>(room / per, 1, kBinChunk));
    // (What the first part bins is the estimate's; the rest must fit beside it.)
    for (std::size_t boxed = (c1 - c0) * per; c1 < want; ++c1) {
      boxed += static_cast<std::size_t>(box_leaves(piece_box(*prims[c1])));
      if (boxed > room) break;
    }
    tbb::parallel_for(tbb::blocked_range<std::size_t>(c0, c1), bin);
    if (interrupted()) return;  // abandoned: the caller throws
    const std::size_t chunk_pairs = binned_now() - binned;
    binned += chunk_pairs;
    pairs_total += chunk_pairs;
    c0 = c1;
    if (binned < m.max_pairs && c0 < prims.size()) continue;
    std::vector<std::uint64_t>& pairs = m.scratch_pairs;
    pairs.clear();
    pairs.reserve(binned);
    for (auto& v : m.scratch_bins) {
      pairs.insert(pairs.end(), v.begin(), v.end());
      // (Kept up to 2 MB each; larger, freed, as the blade's 1 um roughing
      // bins millions: held through the apply, they raised its peak RSS
      // by some 100 MB.)
      if (v.capacity() > kKeepBinKeys) std::vector<std::uint64_t>().swap(v);
      else v.clear();
    }
    const std::size_t from = first;
    first = c0;
    binned = 0;
    apply(pairs, from, c0);
    if (interrupted()) return;
  }
}

Overlap Stock::overlap(const Aabb& bounds, const std::function<double(const Vec3&)>& region,
                       const std::function<double(const Vec3&, double)>& removed, double min_depth_mm,
                       const std::function<double(const Vec3&, Vec3*)>& region_plane,
                       const std::function<double(const Vec3&, double)>& removed_cone) const {
  const Impl& m = *impl_;
  Overlap best;
  const Aabb wb = bounds.intersected(m.box.expanded(m.h));
  if (wb.empty()) return best;
  CoordBBox bb(floor_coord((wb.min - m.origin) / m.h), ceil_coord((wb.max - m.origin) / m.h));
  bb.intersect(m.roi_index);
  if (bb.empty()) return best;
  const double hd0 = std::sqrt(3.0) * 0.5 * (kLeafDim - 1) * m.h;
  const double hq = std::sqrt(3.0) * 1.5 * m.h;  // 4^3 quarter: centre to its farthest voxel
  // What a convex region's plane is lowered by (its values are some 1e-16
  // mm off in rounding; a voxel is 1e-4 mm or more).
  constexpr double kPlaneMargin = 1e-12;  // mm
  const bool plane = static_cast<bool>(region_plane);
  const auto& tree = m.grid->tree();
  // The blocks listed and not yet scanned, and the place of the first of
  // them in the listing's order.
  std::vector<std::pair<Coord, double>> blocks;
  std::size_t base = 0;
  std::mutex mu;
  // The result must not depend on how the threads share the blocks: of
  // equal depths the first block (in their fixed order) wins, and once a
  // block saturates only the blocks before it are still scanned.
  std::atomic<std::size_t> first_saturated{std::numeric_limits<std::size_t>::max()};
  std::size_t best_block = std::numeric_limits<std::size_t>::max();
  const double cap = m.gamma * (1 - 1e-6);
  // The region's distance is 1-Lipschitz, so its depth at a voxel is at
  // most the centre's depth plus the voxel's offset: voxels (and blocks)
  // whose material or region depth cannot beat the deepest overlap found
  // so far (in this chunk or the ones before it) are passed over without
  // evaluating the region.
  auto scan = [&](std::size_t i0, std::size_t i1, double floor0) {
    Overlap local;
    std::size_t local_block = 0;
    LeafLookup lookup(tree);
    for (std::size_t i = i0; i != i1 && base + i < first_saturated.load(std::memory_order_relaxed); ++i) {
      const Coord o = blocks[i].first;
      const double rc = blocks[i].second;
      float tile = 0;
      const LeafT* leaf = lookup.leaf(o, &tile);
      const float* data = leaf ? leaf->buffer().data() : nullptr;
      double floor = std::max(floor0, local.depth_mm);
      if (-rc + hd0 <= floor) continue;
      if (!data && -static_cast<double>(tile) <= floor) continue;
      // (Every quarter's centre is 2 sqrt(3) h from the block's, so the
      // cone from there reaches a quarter's voxels within hd0: the test
      // above again, per quarter against the floor as it has risen since,
      // with a hair of slack for the rounding of that sum.)
      const double block_reach = -rc + hd0 * (1 + 1e-12);
      CoordBBox part = CoordBBox::createCube(o, kLeafDim);
      part.intersect(bb);
      // A whole leaf deeper in what was removed than its reach (the
      // quarters' test below, once for their eight).
      if (removed_cone && part == CoordBBox::createCube(o, kLeafDim)) {
        const double lim = floor - hd0 * (1 + 1e-12) - kPlaneMargin;
        const Vec3 c0 = m.origin + m.h * (Vec3(o.x(), o.y(), o.z()).array() + 0.5 * (kLeafDim - 1)).matrix();
        if (removed_cone(c0, lim) <= lim) continue;
      }
      // Per 4^3 quarter: its deepest material, then the region at its
      // centre, bound the depth of its voxels before any is evaluated.
      for (int qx = 0; qx < kLeafDim; qx += 4)
        for (int qy = 0; qy < kLeafDim; qy += 4)
          for (int qz = 0; qz < kLeafDim; qz += 4) {
            const Coord q0 = o.offsetBy(qx, qy, qz);
            CoordBBox qb = CoordBBox::createCube(q0, 4);
            qb.intersect(part);
            if (qb.empty()) continue;
            if (block_reach <= floor) continue;
            const Vec3 cq = m.origin + m.h * (Vec3(q0.x(), q0.y(), q0.z()).array() + 1.5).matrix();
            if (data) {
              // The whole 4^3 quarter (voxels outside `bb` only make the
              // bound weaker).
              if (-static_cast<double>(quarter_min(data, qx, qy, qz)) <= floor) continue;
            }
            // A convex region: its plane at the centre, lowered by a margin
            // for rounding, bounds it at every voxel (far tighter than the
            // cone where the quarter straddles a face: the voxels beyond
            // the face are passed over); at the quarter's lowest, the whole.
            Vec3 gq = Vec3::Zero();
            const double rq = plane ? region_plane(cq, &gq) : region(cq);
            const double rq_low = rq - kPlaneMargin;
            if (-rq + hq <= floor) continue;
            if (plane && -(rq_low - 1.5 * m.h * gq.cwiseAbs().sum()) <= floor) continue;
            // A whole quarter deeper in what was removed than its reach: at
            // every voxel `removed` is at most the floor. (The flank of a V
            // tool lies just behind its edge: on the snowflake, three in four
            // of the scans' evaluations of `removed` were in such quarters.)
            const bool whole = qb == CoordBBox::createCube(q0, 4);
            if (removed_cone && whole) {
              const double lim = floor - hq * (1 + 1e-12) - kPlaneMargin;
              if (removed_cone(cq, lim) <= lim) continue;
            }
            // A voxel: its tests against the floor as it stands, then the region.
            auto visit = [&](int x, int y, int z) {
              double mat = data ? static_cast<double>(data[((x - o.x()) << 6) | ((y - o.y()) << 3) | (z - o.z())])
                                : static_cast<double>(tile);
              if (-mat <= floor) return;
              const Vec3 p = m.origin + m.h * Vec3(x, y, z);
              // The plane where there is one (a subgradient's length is
              // at most 1, so it is never below the cone by more than
              // the margin); else the cone -rq + |p - cq| <= floor, on
              // squared lengths (no root per voxel).
              if (plane) {
                if (-(rq_low + gq.dot(p - cq)) <= floor) return;
              } else if (const double reach = rq + floor; reach >= 0 && (p - cq).squaredNorm() <= reach * reach) {
                return;
              }
              const double rg = region(p);
              if (-rg <= floor) return;
              if (removed) {
                // The depth is at most what was removed here: below the
                // best so far it cannot count, and `removed` may stop early.
                const double r = removed(p, floor);
                if (r <= floor) return;
                mat = std::max(mat, -r);
              }
              // Past the cap the depth is only known to be at least the
              // band's: all such depths tie (at the band), so the first
              // saturated voxel in block order is the one reported, on
              // any number of threads (their values differ in the 7th
              // digit, and the deepest of them was whichever thread's).
              double depth = std::min(-rg, -mat);
              if (depth >= cap) depth = m.gamma;
              if (depth > floor) {
                local.depth_mm = depth;
                local.where = p;
                local.stock_value = data ? static_cast<double>(data[((x - o.x()) << 6) | ((y - o.y()) << 3) | (z - o.z())])
                                         : static_cast<double>(tile);
                local_block = base + i;
                floor = depth;
              }
            };
            if (data && whole) {
              // A whole quarter: the voxels whose material and plane pass
              // the floor at its start, in the loop's order (the floor only
              // rises, so a voxel passed over then stays passed over). The
              // plane lowered by a second margin: its offsets from the
              // centre are taken as h (i - 1.5), not as p - cq.
              const CentrePlane pl{rq_low - kPlaneMargin, gq.x(), gq.y(), gq.z()};
              for (std::uint64_t bits = overlap_candidates(data, (qx << 6) | (qy << 3) | qz, floor, plane ? &pl : nullptr, m.h);
                   bits; bits &= bits - 1) {
                const int q = std::countr_zero(bits);
                visit(q0.x() + (q >> 4), q0.y() + ((q >> 2) & 3), q0.z() + (q & 3));
              }
              continue;
            }
            for (int x = qb.min().x(); x <= qb.max().x(); ++x)
              for (int y = qb.min().y(); y <= qb.max().y(); ++y)
                for (int z = qb.min().z(); z <= qb.max().z(); ++z) visit(x, y, z);
          }
      if (local.depth_mm >= cap) {
        std::size_t f = first_saturated.load();
        while (base + i < f && !first_saturated.compare_exchange_weak(f, base + i)) {
        }
        break;
      }
    }
    if (local.depth_mm > 0) {
      std::lock_guard<std::mutex> lock(mu);
      if (local.depth_mm > best.depth_mm || (local.depth_mm == best.depth_mm && local_block < best_block)) {
        best = local;
        best_block = local_block;
      }
    }
  };
  // The blocks are scanned in chunks as they are listed, so that the
  // listing stops at the first chunk that saturates (the blocks after
  // that one would not be scanned). A chunk starts from the deepest depth
  // found before it: a later block's voxel no deeper could not win (the
  // first block wins a tie). Few blocks (one pose of a small region) are
  // not worth the threads' start-up.
  std::size_t chunk = 64;
  bool stop = false;
  auto scan_chunk = [&] {
    const double floor0 = std::max(min_depth_mm, best.depth_mm);
    if (blocks.size() <= 16) scan(0, blocks.size(), floor0);
    else
      tbb::parallel_for(tbb::blocked_range<std::size_t>(0, blocks.size()),
                        [&](const auto& r) { scan(r.begin(), r.end(), floor0); });
    base += blocks.size();
    blocks.clear();
    stop = first_saturated.load() != std::numeric_limits<std::size_t>::max();
    chunk = std::min<std::size_t>(2 * chunk, 1 << 14);
  };
  // Blocks the region can reach (its distance is a lower bound outside),
  // skipping air tiles; with the region's distance at their centre.
  // Air is tested first, from the node tables (most of a tool's body is
  // over air that earlier cuts left).
  LeafLookup lookup(tree);
  for_each_leaf_block(m.origin, m.h, bb,
                      [&](const Vec3& c, double hd, const Coord& bo, int dim) {
                        return !stop && (dim != kMid || m.may_hold_material(bo)) &&
                               (dim != kNode1Dim || m.node_may_hold_material(bo)) && region(c) <= hd - min_depth_mm;
                      },
                      [&](const Coord& o) {
                        if (stop) return;
                        float tile = 0;
                        if (!lookup.leaf(o, &tile) && tile > 0) return;  // air tile
                        const Vec3 c0 = m.origin + m.h * (Vec3(o.x(), o.y(), o.z()).array() + 0.5 * (kLeafDim - 1)).matrix();
                        const double rc = region(c0);
                        if (rc > hd0 - min_depth_mm) return;
                        blocks.emplace_back(o, rc);
                        if (blocks.size() >= chunk) scan_chunk();
                      });
  if (!blocks.empty() && !stop) scan_chunk();
  best.at_least = best.depth_mm >= cap;
  return best;
}

double Stock::initial_volume_mm3() const { return impl_->box.volume(); }

double Stock::removed_volume_mm3() const {
  // The coverage integral counts h^2/4 too much per mm of the box's own
  // edges inside the grid, so cutting everything away would "remove" a
  // little more than the box: keep the figures physical.
  Impl& m = *impl_;
  if (!m.grid_volume_now) m.grid_volume_now = m.grid_volume();
  return std::clamp(m.initial_grid_volume - *m.grid_volume_now, 0.0, m.box.volume());
}

double Stock::volume_mm3() const { return initial_volume_mm3() - removed_volume_mm3(); }

double Stock::sample(const Vec3& p) const {
  const Impl& m = *impl_;
  const Vec3 idx = (p - m.origin) / m.h;
  const openvdb::Vec3d ip(idx.x(), idx.y(), idx.z());
  if (!m.roi.contains(p)) return std::clamp(box_signed_distance(m.box, p), -double(m.gamma), double(m.gamma));
  auto acc = m.grid->getConstAccessor();
  return openvdb::tools::BoxSampler::sample(acc, ip);
}

double Stock::surface_height(double x, double y, double z_from) const {
  const Impl& m = *impl_;
  double z = std::min(z_from, m.roi.max.z());
  const double zmin = m.roi.min.z();
  double prev = sample(Vec3(x, y, z));
  const double step = 0.5 * m.h;
  while (z - step >= zmin) {
    const double zn = z - step;
    const double v = sample(Vec3(x, y, zn));
    if (prev > 0 && v <= 0) return z - step * prev / (prev - v);
    prev = v;
    z = zn;
  }
  return std::numeric_limits<double>::quiet_NaN();
}

void Stock::for_each_roi_block(const std::function<void(const VoxelBlock&)>& fn, bool values,
                               const std::function<bool(const BlockGroup&)>& group) const {
  const Impl& m = *impl_;
  const CoordBBox& r = m.roi_index;
  const Coord first(r.min().x() & ~(kLeafDim - 1), r.min().y() & ~(kLeafDim - 1), r.min().z() & ~(kLeafDim - 1));
  // The lattice by index, not as a list: a large ROI has tens of millions of blocks.
  const std::array<int, 3> dims = roi_block_dims();
  // The lattice's blocks in [lo, hi) (in the order of the lattice's index).
  auto blocks = [&](const std::array<int, 3>& lo, const std::array<int, 3>& hi,
                    openvdb::tree::ValueAccessor<const openvdb::FloatTree>& acc, VoxelBlock& b) {
    for (int lx = lo[0]; lx < hi[0]; ++lx)
      for (int ly = lo[1]; ly < hi[1]; ++ly)
        for (int lz = lo[2]; lz < hi[2]; ++lz) {
          const Coord origin = first.offsetBy(lx * kLeafDim, ly * kLeafDim, lz * kLeafDim);
          CoordBBox part = CoordBBox::createCube(origin, kLeafDim);
          part.intersect(r);
          if (part.empty()) continue;
          const Coord l0 = part.min();
          b.first_center = m.origin + m.h * Vec3(l0.x(), l0.y(), l0.z());
          const int l[3] = {lx, ly, lz};
          for (int k = 0; k < 3; ++k) {
            b.n[k] = part.max()[k] - l0[k] + 1;
            b.leaf[k] = l[k];
          }
          if (values) {
            const LeafT* leaf = acc.probeConstLeaf(l0);
            b.uniform = leaf == nullptr;
            if (b.uniform) {
              b.value = acc.getValue(l0);
            } else {
              // From the leaf's buffer (its voxels x-major like the block's), not
              // voxel by voxel through getValue.
              const float* data = leaf->buffer().data();
              const Coord d = l0 - leaf->origin();
              for (int x = 0; x < b.n[0]; ++x)
                for (int y = 0; y < b.n[1]; ++y)
                  for (int z = 0; z < b.n[2]; ++z)
                    b.values[(x * 8 + y) * 8 + z] = data[((d.x() + x) << 6) | ((d.y() + y) << 3) | (d.z() + z)];
            }
          }
          fn(b);
        }
  };
  // By groups (also without `group`, then all visited): the lattice cut
  // by the grid's 128^3 nodes (16^3 blocks each, as the lattice's blocks
  // are the grid's leaves).
  std::array<int, 3> gdims{}, g0{};
  for (int k = 0; k < 3; ++k) {
    // Lattice block l starts at index first[k] + 8 l; its node is floor of that / 128.
    g0[static_cast<std::size_t>(k)] = first[k] >> 7;
    gdims[static_cast<std::size_t>(k)] = ((first[k] + kLeafDim * (dims[static_cast<std::size_t>(k)] - 1)) >> 7) - g0[static_cast<std::size_t>(k)] + 1;
  }
  static_assert(kNode1Dim == 128, "groups are the tree's 128^3 nodes");
  const std::size_t ngroups = static_cast<std::size_t>(gdims[0]) * gdims[1] * gdims[2];
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, ngroups, 1), [&](const auto& range) {
    openvdb::tree::ValueAccessor<const openvdb::FloatTree> acc(m.grid->tree());
    VoxelBlock b;
    for (std::size_t gi = range.begin(); gi != range.end(); ++gi) {
      const int gl[3] = {static_cast<int>(gi / (static_cast<std::size_t>(gdims[1]) * gdims[2])),
                         static_cast<int>((gi / gdims[2]) % gdims[1]), static_cast<int>(gi % gdims[2])};
      BlockGroup g;
      const Coord node((g0[0] + gl[0]) * kNode1Dim, (g0[1] + gl[1]) * kNode1Dim, (g0[2] + gl[2]) * kNode1Dim);
      for (int k = 0; k < 3; ++k) {
        const auto uk = static_cast<std::size_t>(k);
        // Blocks whose first index lies in [node, node + 128).
        g.lo[uk] = std::max(0, (node[k] - first[k]) / kLeafDim);
        g.hi[uk] = std::min(dims[uk], (node[k] + kNode1Dim - first[k]) / kLeafDim);
      }
      if (g.lo[0] >= g.hi[0] || g.lo[1] >= g.hi[1] || g.lo[2] >= g.hi[2]) continue;
      CoordBBox vox(first.offsetBy(g.lo[0] * kLeafDim, g.lo[1] * kLeafDim, g.lo[2] * kLeafDim),
                    first.offsetBy(g.hi[0] * kLeafDim - 1, g.hi[1] * kLeafDim - 1, g.hi[2] * kLeafDim - 1));
      vox.intersect(r);
      if (vox.empty()) continue;
      const Vec3 a = m.origin + m.h * Vec3(vox.min().x(), vox.min().y(), vox.min().z());
      const Vec3 c = m.origin + m.h * Vec3(vox.max().x(), vox.max().y(), vox.max().z());
      g.centre = 0.5 * (a + c);
      g.radius = 0.5 * (c - a).norm() * (1 + 1e-12) + 1e-12;
      if (group && values) {
        const auto* n1 = acc.template probeConstNode<Node1T>(node);
        if (!n1) {
          g.uniform = true;
          g.value = acc.getValue(node);
        } else if (n1->getChildMask().isOff()) {
          g.uniform = true;
          g.value = n1->getFirstValue();
          for (auto it = n1->cbeginValueAll(); it; ++it)
            if (*it != g.value) {
              g.uniform = false;
              break;
            }
        }
      }
      if (group && !group(g)) continue;
      blocks(g.lo, g.hi, acc, b);
    }
  });
}

Vec3 Stock::roi_lattice_origin() const {
  const Impl& m = *impl_;
  const CoordBBox& r = m.roi_index;
  return m.index_to_world(Coord(r.min().x() & ~(kLeafDim - 1), r.min().y() & ~(kLeafDim - 1), r.min().z() & ~(kLeafDim - 1)));
}

std::array<int, 3> Stock::roi_block_dims() const {
  const CoordBBox& r = impl_->roi_index;
  std::array<int, 3> d{};
  for (int k = 0; k < 3; ++k) d[static_cast<std::size_t>(k)] = (r.max()[k] >> 3) - (r.min()[k] >> 3) + 1;
  return d;
}

const Aabb& Stock::box() const { return impl_->box; }
const Aabb& Stock::roi() const { return impl_->roi; }
double Stock::voxel_mm() const { return impl_->h; }
double Stock::band_mm() const { return impl_->gamma; }

StockStats Stock::stats() const {
  StockStats s;
  s.voxel_evaluations = impl_->voxel_evaluations.load();
  s.voxels_aired = impl_->voxels_aired.load();
  s.band_voxels = impl_->band_voxels.load();
  s.blocks_aired = impl_->blocks_aired;
  s.grid_updates = impl_->grid_updates;
  s.bin_s = impl_->bin_s;
  s.classify_s = impl_->classify_s;
  s.topology_s = impl_->topology_s;
  s.voxels_s = impl_->voxels_s;
  s.leaf_nodes = impl_->grid->tree().leafCount();
  s.active_voxels = impl_->grid->tree().activeVoxelCount();
  s.memory_bytes = impl_->grid->tree().memUsage();
  for (auto l = impl_->grid->tree().cbeginLeaf(); l; ++l) s.idle_leaves += l->isValueMaskOff() ? 1 : 0;
  const Impl& m = *impl_;
  std::size_t held = 0;
  for (std::uint64_t w : m.occ.words) held += static_cast<std::size_t>(std::popcount(w));
  s.air_blocks = m.occ.size() - held;
  return s;
}

}  // namespace cutsim::stock
