// The stock's surface from its leaves, on both threads: see
// level_set_mesher.h for what is made. Two passes over the leaves, in
// chunks of a fixed number of leaves so that the output's order does not
// depend on the threads:
//  1. per leaf, the 10^3 voxels from -1 to 8 (its own and its neighbours'
//     next to it, a tile's value where there is no leaf), its cells' points
//     and which cells share one (the merge);
//  2. per leaf, after the points are numbered, a polygon for every
//     sign-changing edge the leaf owns (the edge's first voxel is in it, or
//     that voxel is in a tile and the second is).
#include "cutsim/stock/level_set_mesher.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <stdexcept>
#include <unordered_map>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

namespace cutsim::stock {

namespace {

using openvdb::Coord;
using LeafT = openvdb::FloatTree::LeafNodeType;

constexpr int kBlock = 10;                 // voxels -1..8 of a leaf along each axis
constexpr std::size_t kChunk = 64;         // leaves per task
constexpr std::uint16_t kNoCell = 0xffff;  // a cell without a point

inline int block_index(int x, int y, int z) { return ((x + 1) * kBlock + (y + 1)) * kBlock + (z + 1); }
/// Which of the 3 neighbour slots along an axis holds voxel coordinate v (-1..8).
inline int slot_of(int v) { return v < 0 ? 0 : (v > 7 ? 2 : 1); }
inline int slot_index(int sx, int sy, int sz) { return (sx * 3 + sy) * 3 + sz; }
constexpr int kSelf = 13;  // slot_index(1, 1, 1)
inline int cell_index(int x, int y, int z) { return (x << 6) | (y << 3) | z; }

// A cell's corner o: bit 0 is +x, bit 1 +y, bit 2 +z.
constexpr int kCellEdges[12][2] = {{0, 1}, {2, 3}, {4, 5}, {6, 7}, {0, 2}, {1, 3},
                                   {4, 6}, {5, 7}, {0, 4}, {1, 5}, {2, 6}, {3, 7}};

// The sign configurations a merged block may have: some corners inside and
// some outside, the inside ones connected along the cube's edges and the
// outside ones too (one sheet; no face or body ambiguity).
const std::array<bool, 256>& adaptable() {
  static const std::array<bool, 256> table = [] {
    std::array<bool, 256> ok{};
    for (int cfg = 1; cfg < 255; ++cfg) {
      auto connected = [cfg](int inside) {
        int count = 0, start = -1;
        for (int o = 0; o < 8; ++o)
          if (((cfg >> o) & 1) == inside) {
            ++count;
            if (start < 0) start = o;
          }
        int stack[8], sp = 0, seen = 1 << start, reached = 1;
        stack[sp++] = start;
        while (sp > 0) {
          const int o = stack[--sp];
          for (int b = 0; b < 3; ++b) {
            const int n = o ^ (1 << b);
            if (((cfg >> n) & 1) == inside && !((seen >> n) & 1)) {
              seen |= 1 << n;
              ++reached;
              stack[sp++] = n;
            }
          }
        }
        return reached == count;
      };
      ok[static_cast<std::size_t>(cfg)] = connected(1) && connected(0);
    }
    return ok;
  }();
  return table;
}

// For the 27 samples of a block (i, j, k in 0..2, half a block apart), the
// corners (bit o) each lies between: itself for a corner, an edge's two,
// a face's four, all eight for the centre.
const std::array<std::uint8_t, 27>& sample_parents() {
  static const std::array<std::uint8_t, 27> table = [] {
    std::array<std::uint8_t, 27> p{};
    for (int s = 0; s < 27; ++s) {
      const int ijk[3] = {s / 9, (s / 3) % 3, s % 3};
      for (int o = 0; o < 8; ++o) {
        bool on = true;
        for (int a = 0; a < 3; ++a)
          if (ijk[a] != 1 && ijk[a] != 2 * ((o >> a) & 1)) on = false;
        if (on) p[static_cast<std::size_t>(s)] |= static_cast<std::uint8_t>(1u << o);
      }
    }
    return p;
  }();
  return table;
}

struct LeafInfo {
  std::array<std::int32_t, 27> nb{};  // neighbour leaves' indices (kSelf: this one), or -1
  std::array<float, 27> tile{};       // the value where there is no leaf
  std::uint32_t first_point = 0;      // global number of the leaf's first point
  std::uint32_t reps = UINT32_MAX;    // offset of its 512 cells' local points in the chunk's reps
  std::uint32_t boundary_begin = 0, boundary_end = 0;  // in the chunk's boundary cells
  bool mixed = false;  // its 10^3 voxels hold both signs
  std::uint32_t signs = 0;  // where mixed: its Block::in in the chunk's signs
};

// A cell whose first corner lies in a tile, kept by the first leaf (in
// corner order) that holds one of its corners.
struct BoundaryCell {
  Coord cell;  // global index of its first corner
  std::uint16_t point;
};

// in[x + 1][y + 1], bit z + 1: voxel (x, y, z) of a leaf (-1..8) is inside.
using SignRows = std::array<std::array<std::uint16_t, kBlock>, kBlock>;

// The leaf's voxels from -1 to 8 along each axis, and which are inside.
struct Block {
  std::array<float, kBlock * kBlock * kBlock> v;
  SignRows in;
};
struct Chunk {
  std::vector<Vec3> points;  // index space
  std::vector<Eigen::Vector3f> normals;
  std::vector<std::uint16_t> reps;  // 512 local point numbers (or kNoCell) per leaf with cells
  std::vector<BoundaryCell> boundary;
  std::vector<SignRows> signs;  // the mixed leaves' (pass 2 needs only these)
  std::vector<std::array<std::uint32_t, 3>> triangles;
  std::size_t merged = 0;
};

constexpr std::uint16_t kAllIn = (1u << kBlock) - 1;

// (Less the isovalue: the surface is where the block's values cross 0.)
void gather(const LeafInfo& info, const std::vector<const LeafT*>& leaves, float iso, Block& b) {
  const float* data[27];
  for (int s = 0; s < 27; ++s) data[s] = info.nb[static_cast<std::size_t>(s)] >= 0
                                             ? leaves[static_cast<std::size_t>(info.nb[static_cast<std::size_t>(s)])]->buffer().data()
                                             : nullptr;
  auto tile = [&](int s) { return info.tile[static_cast<std::size_t>(s)]; };
  for (int x = -1; x <= 8; ++x) {
    const int sx = slot_of(x), lx = x & 7;
    for (int y = -1; y <= 8; ++y) {
      const int sy = slot_of(y), ly = y & 7;
      float* row = b.v.data() + block_index(x, y, -1);
      const int s0 = slot_index(sx, sy, 0), s1 = s0 + 1, s2 = s0 + 2;
      row[0] = (data[s0] ? data[s0][cell_index(lx, ly, 7)] : tile(s0)) - iso;
      if (data[s1]) {
        const float* src = data[s1] + cell_index(lx, ly, 0);
        for (int z = 0; z < 8; ++z) row[z + 1] = src[z] - iso;
      } else {
        std::fill_n(row + 1, 8, tile(s1) - iso);
      }
      row[9] = (data[s2] ? data[s2][cell_index(lx, ly, 0)] : tile(s2)) - iso;
      std::uint16_t bits = 0;
      for (int z = 0; z < kBlock; ++z) bits |= static_cast<std::uint16_t>((row[z] < 0 ? 1u : 0u) << z);
      b.in[static_cast<std::size_t>(x + 1)][static_cast<std::size_t>(y + 1)] = bits;
    }
  }
}

// Sign configuration of the cell whose first corner is (x, y, z) (-1..7),
// with its corner values.
inline std::uint8_t cell_config(const float* v, int x, int y, int z, float* cv) {
  std::uint8_t cfg = 0;
  for (int o = 0; o < 8; ++o) {
    cv[o] = v[block_index(x + (o & 1), y + ((o >> 1) & 1), z + ((o >> 2) & 1))];
    if (cv[o] < 0) cfg |= static_cast<std::uint8_t>(1u << o);
  }
  return cfg;
}

// The mean of the cell's edges' zero crossings, relative to its first corner.
inline void cell_point(const float* cv, std::uint8_t cfg, double* p) {
  double sum[3] = {0, 0, 0};
  int n = 0;
  for (const auto& e : kCellEdges) {
    if (((cfg >> e[0]) & 1) == ((cfg >> e[1]) & 1)) continue;
    const double t = static_cast<double>(cv[e[0]]) / (static_cast<double>(cv[e[0]]) - cv[e[1]]);
    const int axis_bit = e[0] ^ e[1];
    for (int a = 0; a < 3; ++a) sum[a] += (1 << a) == axis_bit ? t : static_cast<double>((e[0] >> a) & 1);
    ++n;
  }
  for (int a = 0; a < 3; ++a) p[a] = sum[a] / n;
}

// The cell's gradient direction (outwards), from its corners' differences.
inline void cell_normal(const float* cv, float* n) {
  const float gx = (cv[1] - cv[0]) + (cv[3] - cv[2]) + (cv[5] - cv[4]) + (cv[7] - cv[6]);
  const float gy = (cv[2] - cv[0]) + (cv[3] - cv[1]) + (cv[6] - cv[4]) + (cv[7] - cv[5]);
  const float gz = (cv[4] - cv[0]) + (cv[5] - cv[1]) + (cv[6] - cv[2]) + (cv[7] - cv[3]);
  const float len = std::sqrt(gx * gx + gy * gy + gz * gz);
  if (len > 0) {
    n[0] = gx / len;
    n[1] = gy / len;
    n[2] = gz / len;
  } else {
    n[0] = n[1] = 0;
    n[2] = 1;
  }
}

// One sheet in the block of s cells from (x, y, z) (the test above).
bool block_is_simple(const float* v, int x, int y, int z, int s) {
  const int half = s / 2;
  std::uint32_t inside = 0;  // bit per sample
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      for (int k = 0; k < 3; ++k)
        if (v[block_index(x + i * half, y + j * half, z + k * half)] < 0) inside |= 1u << ((i * 3 + j) * 3 + k);
  std::uint8_t cfg = 0;
  for (int o = 0; o < 8; ++o) {
    const int sample = ((2 * (o & 1)) * 3 + 2 * ((o >> 1) & 1)) * 3 + 2 * ((o >> 2) & 1);
    if ((inside >> sample) & 1) cfg |= static_cast<std::uint8_t>(1u << o);
  }
  if (!adaptable()[cfg]) return false;
  const auto& parents = sample_parents();
  for (int sample = 0; sample < 27; ++sample) {
    const std::uint8_t p = parents[static_cast<std::size_t>(sample)];
    const bool in = (inside >> sample) & 1;
    if (in ? (cfg & p) == 0 : (~cfg & p) == 0) return false;
  }
  return true;
}

}  // namespace

LevelSetMesh mesh_level_set(const openvdb::FloatTree& tree, double adaptivity, float isovalue) {
  std::vector<const LeafT*> leaves;
  leaves.reserve(tree.leafCount());
  for (auto l = tree.cbeginLeaf(); l; ++l) leaves.push_back(l.getLeaf());
  // Leaf indices by origin: a table of 16^3 leaves per 128^3 node, the
  // nodes in a hash (a leaf's neighbours are nearly all in its own node).
  constexpr int kNodeLeaves = 16 * 16 * 16;
  std::unordered_map<Coord, std::size_t> node_of;  // (OpenVDB's std::hash<Coord>)
  std::vector<std::int32_t> node_tables;
  auto node_origin = [](const Coord& o) { return Coord(o.x() & ~127, o.y() & ~127, o.z() & ~127); };
  auto in_node = [](const Coord& o) {
    return static_cast<std::size_t>((((o.x() & 127) >> 3) << 8) | (((o.y() & 127) >> 3) << 4) | ((o.z() & 127) >> 3));
  };
  for (std::size_t i = 0; i < leaves.size(); ++i) {
    const Coord o = leaves[i]->origin();
    auto [it, fresh] = node_of.emplace(node_origin(o), node_tables.size());
    if (fresh) node_tables.resize(node_tables.size() + kNodeLeaves, -1);
    node_tables[it->second + in_node(o)] = static_cast<std::int32_t>(i);
  }

  const std::size_t n_chunks = (leaves.size() + kChunk - 1) / kChunk;
  std::vector<LeafInfo> infos(leaves.size());
  std::vector<Chunk> chunks(n_chunks);
  const bool merge = adaptivity > 1e-6;
  const float min_dot = static_cast<float>(1.0 - 0.5 * adaptivity);

  // Pass 1: neighbours, cells, points.
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n_chunks, 1), [&](const auto& range) {
    openvdb::tree::ValueAccessor<const openvdb::FloatTree> acc(tree);
    Block blk;
    Coord cached_node(INT32_MAX);
    const std::int32_t* cached_table = nullptr;
    std::array<std::uint8_t, 512> cfg{};
    std::array<std::array<double, 3>, 512> point{};
    std::array<std::array<float, 3>, 512> normal{};
    std::array<std::uint16_t, 512> rep{};
    std::vector<std::array<double, 3>> sums;
    std::vector<std::array<float, 3>> nsums;
    std::vector<std::uint32_t> counts;
    for (std::size_t c = range.begin(); c != range.end(); ++c) {
      Chunk& chunk = chunks[c];
      for (std::size_t li = c * kChunk; li < std::min(leaves.size(), (c + 1) * kChunk); ++li) {
        LeafInfo& info = infos[li];
        const Coord origin = leaves[li]->origin();
        for (int s = 0; s < 27; ++s) {
          const auto su = static_cast<std::size_t>(s);
          if (s == kSelf) {
            info.nb[su] = static_cast<std::int32_t>(li);
            continue;
          }
          const Coord o = origin.offsetBy((s / 9 - 1) * 8, ((s / 3) % 3 - 1) * 8, (s % 3 - 1) * 8);
          const Coord n = node_origin(o);
          if (n != cached_node) {
            cached_node = n;
            const auto it = node_of.find(n);
            cached_table = it == node_of.end() ? nullptr : node_tables.data() + it->second;
          }
          info.nb[su] = cached_table ? cached_table[in_node(o)] : -1;
          if (info.nb[su] < 0) info.tile[su] = acc.getValue(o);
        }
        gather(info, leaves, isovalue, blk);
        bool any_in = false, any_out = false;
        for (const auto& col : blk.in)
          for (std::uint16_t r : col) {
            any_in = any_in || r != 0;
            any_out = any_out || r != kAllIn;
          }
        info.mixed = any_in && any_out;
        info.boundary_begin = info.boundary_end = static_cast<std::uint32_t>(chunk.boundary.size());
        if (!info.mixed) continue;
        info.signs = static_cast<std::uint32_t>(chunk.signs.size());
        chunk.signs.push_back(blk.in);

        // The leaf's own cells: those whose eight corners are not all on
        // one side, found a row of eight at a time.
        bool any_cell = false;
        cfg.fill(0);
        rep.fill(kNoCell);
        for (int x = 0; x < 8; ++x)
          for (int y = 0; y < 8; ++y) {
            const auto ux = static_cast<std::size_t>(x + 1), uy = static_cast<std::size_t>(y + 1);
            const unsigned r00 = blk.in[ux][uy], r10 = blk.in[ux + 1][uy], r01 = blk.in[ux][uy + 1], r11 = blk.in[ux + 1][uy + 1];
            const unsigned any = r00 | r10 | r01 | r11, all = r00 & r10 & r01 & r11;
            unsigned cells = (((any | (any >> 1)) & ~(all & (all >> 1))) >> 1) & 0xffu;  // bit z: cell z
            while (cells) {
              const int z = std::countr_zero(cells);
              cells &= cells - 1;
              const int i = cell_index(x, y, z);
              float cv[8];
              const std::uint8_t k = cell_config(blk.v.data(), x, y, z, cv);
              cfg[static_cast<std::size_t>(i)] = k;
              any_cell = true;
              double p[3];
              cell_point(cv, k, p);
              point[static_cast<std::size_t>(i)] = {x + p[0], y + p[1], z + p[2]};
              cell_normal(cv, normal[static_cast<std::size_t>(i)].data());
            }
          }
        sums.clear();
        nsums.clear();
        counts.clear();
        auto add_to = [&](std::uint16_t id, const std::array<double, 3>& p, const std::array<float, 3>& n) {
          if (id == sums.size()) {
            sums.push_back({0, 0, 0});
            nsums.push_back({0, 0, 0});
            counts.push_back(0);
          }
          for (int a = 0; a < 3; ++a) {
            sums[id][static_cast<std::size_t>(a)] += p[static_cast<std::size_t>(a)];
            nsums[id][static_cast<std::size_t>(a)] += n[static_cast<std::size_t>(a)];
          }
          ++counts[id];
        };
        if (any_cell) {
          // Which aligned blocks of 2, 4 and 8 cells share a point.
          std::array<bool, 64> merged2{};
          std::array<bool, 8> merged4{};
          bool merged8 = false;
          if (merge) {
            // Whether the block of s cells at (x, y, z) may share a point
            // (its sub-blocks have each been merged or hold no cell).
            auto mergeable = [&](int x, int y, int z, int s) {
              float mean[3] = {0, 0, 0};
              bool any = false;
              for (int i = x; i < x + s; ++i)
                for (int j = y; j < y + s; ++j)
                  for (int k = z; k < z + s; ++k) {
                    const auto ci = static_cast<std::size_t>(cell_index(i, j, k));
                    if (cfg[ci] == 0 || cfg[ci] == 255) continue;
                    any = true;
                    for (int a = 0; a < 3; ++a) mean[a] += normal[ci][static_cast<std::size_t>(a)];
                  }
              if (!any) return false;
              const float len = std::sqrt(mean[0] * mean[0] + mean[1] * mean[1] + mean[2] * mean[2]);
              if (!(len > 0)) return false;
              for (float& m : mean) m /= len;
              for (int i = x; i < x + s; ++i)
                for (int j = y; j < y + s; ++j)
                  for (int k = z; k < z + s; ++k) {
                    const auto ci = static_cast<std::size_t>(cell_index(i, j, k));
                    if (cfg[ci] == 0 || cfg[ci] == 255) continue;
                    const auto& n = normal[ci];
                    if (n[0] * mean[0] + n[1] * mean[1] + n[2] * mean[2] < min_dot) return false;
                  }
              return block_is_simple(blk.v.data(), x, y, z, s);
            };
            // A block of s cells with no cell, or merged: its parent may merge.
            std::array<bool, 64> open2{};
            for (int b = 0; b < 64; ++b) {
              const int x = 2 * (b >> 4), y = 2 * ((b >> 2) & 3), z = 2 * (b & 3);
              bool any = false;
              for (int o = 0; o < 8; ++o) {
                const auto ci = static_cast<std::size_t>(cell_index(x + (o & 1), y + ((o >> 1) & 1), z + (o >> 2)));
                if (cfg[ci] != 0 && cfg[ci] != 255) any = true;
              }
              merged2[static_cast<std::size_t>(b)] = any && mergeable(x, y, z, 2);
              open2[static_cast<std::size_t>(b)] = !any || merged2[static_cast<std::size_t>(b)];
            }
            std::array<bool, 8> open4{};
            for (int b = 0; b < 8; ++b) {
              const int x = 4 * (b >> 2), y = 4 * ((b >> 1) & 1), z = 4 * (b & 1);
              bool children = true, any = false;
              for (int o = 0; o < 8; ++o) {
                const int cx = x / 2 + (o & 1), cy = y / 2 + ((o >> 1) & 1), cz = z / 2 + (o >> 2);
                const auto b2 = static_cast<std::size_t>((cx << 4) | (cy << 2) | cz);
                children = children && open2[b2];
                any = any || merged2[b2];
              }
              merged4[static_cast<std::size_t>(b)] = children && any && mergeable(x, y, z, 4);
              open4[static_cast<std::size_t>(b)] = merged4[static_cast<std::size_t>(b)] || (children && !any);
            }
            bool children = true, any = false;
            for (int b = 0; b < 8; ++b) {
              children = children && open4[static_cast<std::size_t>(b)];
              any = any || merged4[static_cast<std::size_t>(b)];
            }
            merged8 = children && any && mergeable(0, 0, 0, 8);
          }
          // Local point numbers, in cell order.
          std::int32_t id8 = -1;
          std::array<std::int32_t, 8> id4;
          std::array<std::int32_t, 64> id2;
          id4.fill(-1);
          id2.fill(-1);
          for (int i = 0; i < 512; ++i) {
            const auto ci = static_cast<std::size_t>(i);
            if (cfg[ci] == 0 || cfg[ci] == 255) continue;
            const int x = i >> 6, y = (i >> 3) & 7, z = i & 7;
            std::int32_t* group = nullptr;
            if (merged8) group = &id8;
            else if (merged4[static_cast<std::size_t>(((x >> 2) << 2) | ((y >> 2) << 1) | (z >> 2))])
              group = &id4[static_cast<std::size_t>(((x >> 2) << 2) | ((y >> 2) << 1) | (z >> 2))];
            else if (merged2[static_cast<std::size_t>(((x >> 1) << 4) | ((y >> 1) << 2) | (z >> 1))])
              group = &id2[static_cast<std::size_t>(((x >> 1) << 4) | ((y >> 1) << 2) | (z >> 1))];
            std::uint16_t id;
            if (group) {
              if (*group < 0) *group = static_cast<std::int32_t>(sums.size());
              else ++chunk.merged;
              id = static_cast<std::uint16_t>(*group);
            } else {
              id = static_cast<std::uint16_t>(sums.size());
            }
            rep[ci] = id;
            add_to(id, point[ci], normal[ci]);
          }
          info.reps = static_cast<std::uint32_t>(chunk.reps.size());
          chunk.reps.insert(chunk.reps.end(), rep.begin(), rep.end());
        }

        // Cells whose first corner lies in a tile, where this leaf holds
        // the first of their corners that lies in a leaf.
        bool lower_tile = false;  // a neighbour below in x, y or z without a leaf
        for (int s = 0; s < 27; ++s)
          if (s / 9 <= 1 && (s / 3) % 3 <= 1 && s % 3 <= 1 && info.nb[static_cast<std::size_t>(s)] < 0) lower_tile = true;
        for (int x = -1; x < 8 && lower_tile; ++x)
          for (int y = -1; y < 8; ++y)
            for (int z = -1; z < 8; ++z) {
              if (x >= 0 && y >= 0 && z >= 0) continue;
              if (info.nb[static_cast<std::size_t>(slot_index(slot_of(x), slot_of(y), slot_of(z)))] >= 0) continue;
              float cv[8];
              const std::uint8_t k = cell_config(blk.v.data(), x, y, z, cv);
              if (k == 0 || k == 255) continue;
              int owner = -1;
              for (int o = 0; o < 8 && owner < 0; ++o) {
                const int s = slot_index(slot_of(x + (o & 1)), slot_of(y + ((o >> 1) & 1)), slot_of(z + (o >> 2)));
                if (info.nb[static_cast<std::size_t>(s)] >= 0) owner = s;
              }
              if (owner != kSelf) continue;
              double p[3];
              cell_point(cv, k, p);
              std::array<float, 3> n;
              cell_normal(cv, n.data());
              const auto id = static_cast<std::uint16_t>(sums.size());
              add_to(id, {x + p[0], y + p[1], z + p[2]}, n);
              chunk.boundary.push_back({origin.offsetBy(x, y, z), id});
            }
        info.boundary_end = static_cast<std::uint32_t>(chunk.boundary.size());

        info.first_point = static_cast<std::uint32_t>(chunk.points.size());  // within the chunk, for now
        for (std::size_t id = 0; id < sums.size(); ++id) {
          const double w = 1.0 / counts[id];
          chunk.points.push_back(Vec3(origin.x() + sums[id][0] * w, origin.y() + sums[id][1] * w,
                                      origin.z() + sums[id][2] * w));
          const Eigen::Vector3f n(nsums[id][0], nsums[id][1], nsums[id][2]);
          const float len = n.norm();
          chunk.normals.push_back(len > 0 ? Eigen::Vector3f(n / len) : Eigen::Vector3f(0, 0, 1));
        }
      }
    }
  });

  // Number the points: the chunks' in order.
  LevelSetMesh out;
  {
    std::size_t total = 0;
    std::vector<std::size_t> base(n_chunks);
    for (std::size_t c = 0; c < n_chunks; ++c) {
      base[c] = total;
      total += chunks[c].points.size();
    }
    if (total >= UINT32_MAX) throw std::length_error("surface mesh: more than 2^32 points");
    for (std::size_t li = 0; li < leaves.size(); ++li) infos[li].first_point += static_cast<std::uint32_t>(base[li / kChunk]);
    out.points.resize(total);
    out.normals.resize(total);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n_chunks, 1), [&](const auto& range) {
      for (std::size_t c = range.begin(); c != range.end(); ++c) {
        std::copy(chunks[c].points.begin(), chunks[c].points.end(), out.points.begin() + static_cast<std::ptrdiff_t>(base[c]));
        std::copy(chunks[c].normals.begin(), chunks[c].normals.end(), out.normals.begin() + static_cast<std::ptrdiff_t>(base[c]));
        std::vector<Vec3>().swap(chunks[c].points);
        std::vector<Eigen::Vector3f>().swap(chunks[c].normals);
      }
    });
  }

  // Pass 2: a polygon per sign-changing edge.
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n_chunks, 1), [&](const auto& range) {
    for (std::size_t c = range.begin(); c != range.end(); ++c) {
      Chunk& chunk = chunks[c];
      for (std::size_t li = c * kChunk; li < std::min(leaves.size(), (c + 1) * kChunk); ++li) {
        const LeafInfo& info = infos[li];
        if (!info.mixed) continue;
        const SignRows& in = chunk.signs[info.signs];
        const Coord origin = leaves[li]->origin();
        // The point of the cell whose first corner is g (-1..7, leaf-local).
        auto point_of = [&](int gx, int gy, int gz) -> std::uint32_t {
          const std::int32_t n = info.nb[static_cast<std::size_t>(slot_index(slot_of(gx), slot_of(gy), slot_of(gz)))];
          if (n >= 0) {
            const LeafInfo& other = infos[static_cast<std::size_t>(n)];
            const Chunk& oc = chunks[static_cast<std::size_t>(n) / kChunk];
            const std::uint16_t id =
                other.reps == UINT32_MAX ? kNoCell : oc.reps[other.reps + static_cast<std::uint32_t>(cell_index(gx & 7, gy & 7, gz & 7))];
            if (id == kNoCell) throw std::logic_error("surface mesh: a sign-changing edge's cell has no point");
            return other.first_point + id;
          }
          const Coord g = origin.offsetBy(gx, gy, gz);
          for (int o = 0; o < 8; ++o) {
            const std::int32_t m = info.nb[static_cast<std::size_t>(
                slot_index(slot_of(gx + (o & 1)), slot_of(gy + ((o >> 1) & 1)), slot_of(gz + (o >> 2))))];
            if (m < 0) continue;
            const LeafInfo& owner = infos[static_cast<std::size_t>(m)];
            const Chunk& oc = chunks[static_cast<std::size_t>(m) / kChunk];
            for (std::uint32_t b = owner.boundary_begin; b < owner.boundary_end; ++b)
              if (oc.boundary[b].cell == g) return owner.first_point + oc.boundary[b].point;
            break;
          }
          throw std::logic_error("surface mesh: a sign-changing edge's cell in a tile has no point");
        };
        // The edge from voxel q along axis a, whose first voxel is inside
        // or not: the four cells around it, counter-clockwise about +a.
        auto edge = [&](int a, int qx, int qy, int qz, bool in0) {
          static constexpr int kAround[4][2] = {{-1, -1}, {0, -1}, {0, 0}, {-1, 0}};
          const int b = (a + 1) % 3, cax = (a + 2) % 3;
          std::uint32_t ids[4];
          for (int k = 0; k < 4; ++k) {
            int g[3] = {qx, qy, qz};
            g[b] += kAround[k][0];
            g[cax] += kAround[k][1];
            ids[k] = point_of(g[0], g[1], g[2]);
          }
          // Inside at the first voxel: the surface faces +a.
          if (!in0) std::swap(ids[1], ids[3]);
          std::uint32_t poly[4];
          int n = 0;
          for (std::uint32_t id : ids)
            if (n == 0 || poly[n - 1] != id) poly[n++] = id;
          if (n > 1 && poly[n - 1] == poly[0]) --n;
          if (n == 3) {
            chunk.triangles.push_back({poly[0], poly[1], poly[2]});
          } else if (n == 4 && poly[0] != poly[2] && poly[1] != poly[3]) {
            // Split along the diagonal whose two triangles face most nearly
            // the way the points' normals do (a quad of merged points is
            // far from flat, and the other split may fold).
            const Vec3* p[4];
            Eigen::Vector3f sum = Eigen::Vector3f::Zero();
            for (int k = 0; k < 4; ++k) {
              p[k] = &out.points[poly[k]];
              sum += out.normals[poly[k]];
            }
            const Vec3 ref = sum.cast<double>();
            auto facing = [&](int a, int b, int c) {
              const Vec3 f = (*p[b] - *p[a]).cross(*p[c] - *p[a]);
              const double len = f.norm();
              return len > 0 ? f.dot(ref) / len : 0.0;
            };
            const double along02 = std::min(facing(0, 1, 2), facing(0, 2, 3));
            const double along13 = std::min(facing(0, 1, 3), facing(1, 2, 3));
            if (along13 > along02) {
              chunk.triangles.push_back({poly[0], poly[1], poly[3]});
              chunk.triangles.push_back({poly[1], poly[2], poly[3]});
            } else {
              chunk.triangles.push_back({poly[0], poly[1], poly[2]});
              chunk.triangles.push_back({poly[0], poly[2], poly[3]});
            }
          }
        };
        // An edge whose first voxel lies in a tile below is this leaf's.
        auto lo = [&](int a) {
          int sl[3] = {1, 1, 1};
          sl[a] = 0;
          return info.nb[static_cast<std::size_t>(slot_index(sl[0], sl[1], sl[2]))] < 0 ? -1 : 0;
        };
        auto row = [&](int x, int y) -> unsigned { return in[static_cast<std::size_t>(x + 1)][static_cast<std::size_t>(y + 1)]; };
        // Sign changes along x and y between rows, along z within a row
        // (bit z + 1 of a row: voxel z).
        for (int x = lo(0); x < 8; ++x)
          for (int y = 0; y < 8; ++y) {
            unsigned d = (row(x, y) ^ row(x + 1, y)) & 0x1feu;
            while (d) {
              const int bit = std::countr_zero(d);
              d &= d - 1;
              edge(0, x, y, bit - 1, (row(x, y) >> bit) & 1);
            }
          }
        for (int x = 0; x < 8; ++x)
          for (int y = lo(1); y < 8; ++y) {
            unsigned d = (row(x, y) ^ row(x, y + 1)) & 0x1feu;
            while (d) {
              const int bit = std::countr_zero(d);
              d &= d - 1;
              edge(1, x, y, bit - 1, (row(x, y) >> bit) & 1);
            }
          }
        const unsigned zmask = lo(2) < 0 ? 0x1ffu : 0x1feu;  // edges from z = -1 or 0 to 7
        for (int x = 0; x < 8; ++x)
          for (int y = 0; y < 8; ++y) {
            const unsigned r = row(x, y);
            unsigned d = (r ^ (r >> 1)) & zmask;
            while (d) {
              const int bit = std::countr_zero(d);
              d &= d - 1;
              edge(2, x, y, bit - 1, (r >> bit) & 1);
            }
          }
      }
    }
  });

  std::size_t n_tris = 0;
  for (const Chunk& c : chunks) {
    n_tris += c.triangles.size();
    out.merged_cells += c.merged;
  }
  out.triangles.reserve(n_tris);
  for (Chunk& c : chunks) {
    out.triangles.insert(out.triangles.end(), c.triangles.begin(), c.triangles.end());
    std::vector<std::array<std::uint32_t, 3>>().swap(c.triangles);
  }
  return out;
}

}  // namespace cutsim::stock
