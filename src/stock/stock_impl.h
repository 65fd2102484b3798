#pragma once
// Private: the OpenVDB state behind Stock.
#include <atomic>
#include <cstdint>
#include <optional>
#include <unordered_map>
#include <vector>

#include <openvdb/openvdb.h>
#include <tbb/enumerable_thread_specific.h>

#include "cutsim/stock/stock.h"

namespace cutsim::stock {

struct Stock::Impl {
  Aabb box;        // world mm
  Aabb roi;        // world mm, snapped to voxel cells
  double h = 0;    // voxel size mm
  float gamma = 0; // half band, mm (background value)
  Vec3 origin;     // world position of index (0,0,0) (grid local frame)
  openvdb::CoordBBox roi_index;   // voxels inside the ROI
  openvdb::CoordBBox grid_index;  // ROI plus padding: voxels the grid may hold
  openvdb::FloatGrid::Ptr grid;
  double initial_grid_volume = 0;  // coverage volume inside roi_index at build
  std::atomic<std::uint64_t> voxel_evaluations{0};  // voxels the cuts evaluated (bench figure)
  std::atomic<std::uint64_t> voxels_aired{0};       // voxels set to air by a whole quarter's bound
  std::atomic<std::uint64_t> band_voxels{0};        // StockStats::band_voxels
  std::size_t measure_band_every = 0;                // StockOptions::measure_band_every
  std::size_t blocks_aired = 0;                      // 32^3 blocks with material set to air whole (bench figure)
  std::size_t max_pairs = std::size_t(1) << 20;  // StockOptions::max_update_pairs
  // Scratch of the stock update, kept between calls: fresh arrays of this
  // size cost a page fault per 4 KB every time.
  std::vector<std::uint64_t> scratch_pairs;
  std::vector<std::uint64_t> scratch_sort;  // radix sort's other buffer
  std::vector<double> scratch_d;
  std::vector<Vec3> scratch_g;
  // The binning's (leaf, piece) keys, per thread (sorted after, so their
  // order here does not matter): one growing array each, kept, instead of
  // one per piece grown from nothing (raster40k: 40,000 of them, ~7
  // reallocations each, per run).
  tbb::enumerable_thread_specific<std::vector<std::uint64_t>> scratch_bins;
  std::size_t grid_updates = 0;                      // (bench figures, written on the calling thread)
  double bin_s = 0, classify_s = 0, topology_s = 0, voxels_s = 0;

  // A leaf's material against planes: for a piece whose tangent plane at
  // the leaf's centre c bounds it below (d(p) >= d + g . (p - c)), a voxel
  // changes only where d(p) + v(p) < 0, and min over the voxels of
  // v(p) + g . (p - c) is bounded by these (LeafPlanes::least). Values only
  // rise as the stock is cut, so kept figures stay lower bounds however
  // stale: they are refreshed where the update leaves a leaf, for speed.
  struct LeafPlanes {
    float low;     // least value
    float up[3];   // least of v(p) + (p_k - c_k), mm
    float down[3]; // least of v(p) - (p_k - c_k)
    static LeafPlanes of_leaf(const float* data, double h, float gamma);
    static LeafPlanes of_tile(float value, double h, float gamma);
    /// A lower bound for min over the leaf's voxels of v(p) + g . (p - c).
    double least(const Vec3& g, double h) const;
  };
  // Kept only once a cut brings a piece that uses them (a fly-cutter's
  // torus): every leaf then, refreshed by each update.
  bool planes_on = false;
  std::unordered_map<openvdb::Coord, LeafPlanes> leaf_planes;  // (OpenVDB's std::hash<Coord>)
  /// Starts keeping leaf_planes, from every leaf of the tree.
  void start_leaf_planes();

  Vec3 index_to_world(const openvdb::Coord& c) const {
    return origin + h * Vec3(c.x(), c.y(), c.z());
  }
  double grid_volume() const;
  // grid_volume() as of the last change to the tree (a pass over every
  // leaf; the report asks for it several times). Cleared by every cut.
  std::optional<double> grid_volume_now;

  // One bit per cube of 2^log2 voxels over a box of voxel indices, x-major.
  struct CubeBits {
    int log2 = 0;
    openvdb::Coord lo;  // first cube, in cube units
    int nx = 0, ny = 0, nz = 0;
    std::vector<std::uint64_t> words;
    /// Covers the cubes that meet `box` (voxel indices), all bits clear.
    void reset(int cube_log2, const openvdb::CoordBBox& box) {
      log2 = cube_log2;
      lo = openvdb::Coord(box.min().x() >> log2, box.min().y() >> log2, box.min().z() >> log2);
      nx = (box.max().x() >> log2) - lo.x() + 1;
      ny = (box.max().y() >> log2) - lo.y() + 1;
      nz = (box.max().z() >> log2) - lo.z() + 1;
      words.assign((size() + 63) / 64, 0);
    }
    std::size_t size() const { return static_cast<std::size_t>(nx) * ny * nz; }
    /// The bit of the cube holding voxel `o`, or -1 outside.
    std::int64_t index(const openvdb::Coord& o) const {
      const int x = (o.x() >> log2) - lo.x(), y = (o.y() >> log2) - lo.y(), z = (o.z() >> log2) - lo.z();
      if (x < 0 || y < 0 || z < 0 || x >= nx || y >= ny || z >= nz) return -1;
      return (static_cast<std::int64_t>(x) * ny + y) * nz + z;
    }
    bool test(std::int64_t i) const { return (words[static_cast<std::size_t>(i) >> 6] >> (i & 63)) & 1; }
    void set(std::int64_t i, bool on) {
      const std::uint64_t bit = std::uint64_t(1) << (i & 63);
      std::uint64_t& w = words[static_cast<std::size_t>(i) >> 6];
      w = on ? (w | bit) : (w & ~bit);
    }
    /// True outside the map, or where the bit is set.
    bool maybe(const openvdb::Coord& o) const {
      const std::int64_t i = index(o);
      return i < 0 || test(i);
    }
  };

  // Which 32^3 blocks of grid_index may hold material (a leaf, or a tile
  // at or below 0). A clear bit means all air: cuts and contact checks
  // pass over the block without probing its 64 leaves. Bits are only
  // cleared where the tree shows air, so the map errs towards material.
  static constexpr int kBlockLog2 = 5;
  CubeBits occ;
  /// `o`: a voxel index (of a 32-aligned block). True outside the map.
  bool may_hold_material(const openvdb::Coord& o) const { return occ.maybe(o); }
  // The same per 128^3 node (4^3 blocks): a set bit where any of its
  // blocks' is, so a piece's box over air (above a roughed part) is passed
  // over a node at a time: the blade at 1 um asked 45 M all-air nodes, 64
  // bits each. Nodes outside the map (whose blocks are) count as material.
  static constexpr int kNodeLog2 = 7;
  CubeBits nodes;
  /// `o`: a voxel index (of a 128-aligned node). True outside the map, and
  /// where may_hold_material is for one of the node's 32^3 blocks.
  bool node_may_hold_material(const openvdb::Coord& o) const { return nodes.maybe(o); }
  /// Sets node `o`'s bit from its blocks' (`o`: 128-aligned).
  void update_node_bit(const openvdb::Coord& o);
  /// From the whole tree (after a build or a load).
  void rebuild_occupancy();
  /// Clears the bits of the given blocks (32-aligned voxel indices) that
  /// now hold only air.
  void refresh_occupancy(std::vector<openvdb::Coord> blocks);
};

}  // namespace cutsim::stock
