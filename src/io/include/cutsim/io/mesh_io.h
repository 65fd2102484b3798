#pragma once
// Target meshes: STL (ASCII and binary), OBJ, PLY (ASCII and binary little
// endian), glTF and glb. Positions in the file's units; the caller places
// and scales them.
#include <string>

#include "cutsim/core/mesh.h"

namespace cutsim::io {

/// Loads a triangle mesh; polygons are fanned into triangles, glTF node
/// transforms are applied. Vertices at the same position are merged, so an
/// STL's triangle soup becomes an indexed mesh.
/// @throw InputError when the file cannot be read; ParseError (file:line
///        where there is one) for malformed content or an unknown format.
TriMesh load_mesh(const std::string& path);

struct MeshDefects {
  std::size_t open_edges = 0;         ///< edges with one triangle
  std::size_t nonmanifold_edges = 0;  ///< edges with more than two
  std::size_t flipped_edges = 0;      ///< edges whose two triangles run them the same way
  std::size_t degenerate_triangles = 0;
  bool closed() const { return !open_edges && !nonmanifold_edges && !flipped_edges; }
};

/// Counts what keeps `m` from being a closed, consistently oriented surface.
MeshDefects find_defects(const TriMesh& m);

/// @throw GeometryError naming `file`, `what` the mesh is and the defects
///        when `m` is not closed and consistently oriented, or encloses no volume.
void require_closed(const TriMesh& m, const std::string& file, const std::string& what = "the target mesh");

}  // namespace cutsim::io
