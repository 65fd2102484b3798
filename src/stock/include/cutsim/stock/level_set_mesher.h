#pragma once
// A level set's surface as triangles (the stock's, the comparison's
// regions), read from the leaves' buffers directly: one point per cell,
// cells merged within a leaf where the surface is flat and simple.
#include <array>
#include <cstdint>
#include <vector>

#include <openvdb/openvdb.h>

#include "cutsim/core/geometry.h"

namespace cutsim::stock {

struct LevelSetMesh {
  std::vector<Vec3> points;  ///< index space (voxel units)
  /// Unit, one per point, outwards: the gradient at its cells' centres
  /// (their corners' differences), the mean of its cells' where merged.
  std::vector<Eigen::Vector3f> normals;
  /// Counter-clockwise seen from outside (the side where values are >= the isovalue).
  std::vector<std::array<std::uint32_t, 3>> triangles;
  std::size_t merged_cells = 0;  ///< cells whose point is shared with others
};

/// The level set of `tree` at `isovalue` (inside where a value is below it).
///
/// A cell is the cube between eight neighbouring voxels; one whose corners
/// differ in sign gets one point, the mean of its edges' zero crossings
/// (linear along each edge). Each edge between two voxels of different
/// sign gives a quad between the points of the four cells around it.
///
/// With `adaptivity` > 0, aligned blocks of 2^3, 4^3 and 8^3 cells within
/// a leaf share one point (the mean of their cells' points) where every
/// cell's gradient lies within the adaptivity of their mean (1 - n.m <=
/// adaptivity / 2) and the block holds one sheet: its corners' signs are
/// not ambiguous, and each of its edge midpoints, face centres and centre
/// takes the sign of one of the corners it lies between. Quads then
/// collapse to triangles or nothing where their cells share points, so
/// the mesh stays closed wherever the unmerged one is.
///
/// Sign changes are found wherever a leaf is at one end of an edge; an
/// edge between two tiles is not meshed. The output is the same for any
/// number of threads.
LevelSetMesh mesh_level_set(const openvdb::FloatTree& tree, double adaptivity, float isovalue = 0.0f);

}  // namespace cutsim::stock
