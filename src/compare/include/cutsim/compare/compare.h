#pragma once
// Machined stock against the target: signed deviation of the machined
// surface (exact to the target's triangles) and overcut / undercut volumes.
#include <vector>

#include "cutsim/compare/target.h"
#include "cutsim/core/mesh.h"
#include "cutsim/stock/stock.h"

namespace cutsim::compare {

struct CompareOptions {
  double tolerance_mm = 0.001;  ///< deviations within +-tolerance count as in tolerance
  /// The volumes always come from the stock's voxels. The region meshes are
  /// drawn on a grid 1, 2, 4 or 8 voxels wide, the finest that keeps them
  /// within about this many blocks of its own (16384: some 2M vertices); a
  /// coarse cell is in a region if any of its voxels is (nothing vanishes).
  std::size_t region_block_budget = 16384;
  /// The region meshes' merging, as the machined surface's (Stock::surface_mesh):
  /// 0 keeps a quad per cell face; more merges flat stretches of a region's
  /// surface into larger polygons (a thin region's two faces stay apart).
  double region_mesh_adaptivity = 0.01;
};

struct CompareResult {
  /// Material removed that the target keeps / left that the target removes,
  /// mm^3, integrated over the region of interest by voxel coverage:
  /// per voxel max(0, f_target - f_stock) and max(0, f_stock - f_target),
  /// f = clamp(1/2 - d/h, 0, 1).
  double overcut_volume_mm3 = 0;
  double undercut_volume_mm3 = 0;
  double max_overcut_mm = 0;     ///< deepest machined-surface point inside the target
  double max_undercut_mm = 0;    ///< farthest machined-surface point outside it
  double tolerance_mm = 0;
  double fraction_in_tolerance = 0;  ///< of the machined surface's area
  /// Signed deviation at each vertex of the machined mesh: + outside the
  /// target (undercut), - inside (overcut).
  std::vector<float> vertex_deviation_mm;
  /// The overcut and undercut regions as closed meshes (zero sets of
  /// max(d_target, -d_stock) and max(d_stock, -d_target) on the voxels).
  TriMesh overcut_mesh, undercut_mesh;
  /// Voxel size the region meshes were drawn at, mm: the stock's, or a
  /// multiple of it when the regions are large (see compare()).
  double region_mesh_voxel_mm = 0;
};

CompareResult compare(const stock::Stock& stock, const Target& target, const TriMesh& machined,
                      const CompareOptions& opt = {});

}  // namespace cutsim::compare
