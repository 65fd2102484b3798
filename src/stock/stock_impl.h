#pragma once
// Private: the OpenVDB state behind Stock.
#include <atomic>
#include <cstdint>

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

  Vec3 index_to_world(const openvdb::Coord& c) const {
    return origin + h * Vec3(c.x(), c.y(), c.z());
  }
  double grid_volume() const;
};

}  // namespace cutsim::stock
