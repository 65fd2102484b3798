#pragma once
// Private: the OpenVDB state behind Stock.
#include <atomic>
#include <cstdint>
#include <optional>
#include <vector>

#include <openvdb/openvdb.h>

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
  std::size_t blocks_aired = 0;                      // 32^3 blocks with material set to air whole (bench figure)
  std::size_t max_pairs = std::size_t(1) << 20;  // StockOptions::max_update_pairs
  // Scratch of the stock update, kept between calls: fresh arrays of this
  // size cost a page fault per 4 KB every time.
  std::vector<std::uint64_t> scratch_pairs;
  std::vector<std::uint64_t> scratch_sort;  // radix sort's other buffer
  std::vector<double> scratch_d;
  std::vector<Vec3> scratch_g;
  std::size_t grid_updates = 0;                      // (bench figures, written on the calling thread)
  double bin_s = 0, classify_s = 0, topology_s = 0, voxels_s = 0;

  Vec3 index_to_world(const openvdb::Coord& c) const {
    return origin + h * Vec3(c.x(), c.y(), c.z());
  }
  double grid_volume() const;
  // grid_volume() as of the last change to the tree (a pass over every
  // leaf; the report asks for it several times). Cleared by every cut.
  std::optional<double> grid_volume_now;

  // Which 32^3 blocks of grid_index may hold material (a leaf, or a tile
  // at or below 0). A clear bit means all air: cuts and contact checks
  // pass over the block without probing its 64 leaves. Bits are only
  // cleared where the tree shows air, so the map errs towards material.
  static constexpr int kBlockLog2 = 5;
  openvdb::Coord occ_lo;  // first block, in block units
  int occ_nx = 0, occ_ny = 0, occ_nz = 0;
  std::vector<std::uint64_t> occ;
  /// The bit of the block holding voxel `o`, or -1 outside the map.
  std::int64_t occ_bit(const openvdb::Coord& o) const {
    const int x = (o.x() >> kBlockLog2) - occ_lo.x(), y = (o.y() >> kBlockLog2) - occ_lo.y(),
              z = (o.z() >> kBlockLog2) - occ_lo.z();
    if (x < 0 || y < 0 || z < 0 || x >= occ_nx || y >= occ_ny || z >= occ_nz) return -1;
    return (static_cast<std::int64_t>(x) * occ_ny + y) * occ_nz + z;
  }
  bool occ_test(std::int64_t i) const { return (occ[static_cast<std::size_t>(i) >> 6] >> (i & 63)) & 1; }
  /// `o`: a voxel index (of a 32-aligned block). True outside the map.
  bool may_hold_material(const openvdb::Coord& o) const {
    const std::int64_t i = occ_bit(o);
    return i < 0 || occ_test(i);
  }
  // The same per 128^3 node (4^3 blocks): a set bit where any of its
  // blocks' is, so a piece's box over air (above a roughed part) is passed
  // over a node at a time: the blade at 1 um asked 45 M all-air nodes, 64
  // bits each. Nodes outside the map (whose blocks are) count as material.
  static constexpr int kNodeLog2 = 7;
  openvdb::Coord node_lo;  // first node, in node units
  int node_nx = 0, node_ny = 0, node_nz = 0;
  std::vector<std::uint64_t> node_occ;
  std::int64_t node_bit(const openvdb::Coord& o) const {
    const int x = (o.x() >> kNodeLog2) - node_lo.x(), y = (o.y() >> kNodeLog2) - node_lo.y(),
              z = (o.z() >> kNodeLog2) - node_lo.z();
    if (x < 0 || y < 0 || z < 0 || x >= node_nx || y >= node_ny || z >= node_nz) return -1;
    return (static_cast<std::int64_t>(x) * node_ny + y) * node_nz + z;
  }
  /// `o`: a voxel index (of a 128-aligned node). True outside the map, and
  /// where may_hold_material is for one of the node's 32^3 blocks.
  bool node_may_hold_material(const openvdb::Coord& o) const {
    const std::int64_t i = node_bit(o);
    return i < 0 || ((node_occ[static_cast<std::size_t>(i) >> 6] >> (i & 63)) & 1);
  }
  /// Sets node `o`'s bit from its blocks' (`o`: 128-aligned).
  void update_node_bit(const openvdb::Coord& o);
  /// From the whole tree (after a build or a load).
  void rebuild_occupancy();
  /// Clears the bits of the given blocks (32-aligned voxel indices) that
  /// now hold only air.
  void refresh_occupancy(std::vector<openvdb::Coord> blocks);
};

}  // namespace cutsim::stock
