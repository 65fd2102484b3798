#pragma once
// Binary glTF (.glb) export. glTF is metres and Y-up: a root node turns the
// Z-up machine frame into it; each mesh stores float positions relative to a
// local origin held by its node in double precision.
#include <array>
#include <string>
#include <utility>
#include <vector>

#include "cutsim/core/mesh.h"

namespace cutsim::io {

struct GltfPart {
  std::string name;
  const TriMesh* mesh = nullptr;
  std::array<float, 4> base_color{0.75f, 0.75f, 0.78f, 1.0f};  ///< linear RGBA
  const std::vector<std::array<float, 4>>* colors = nullptr;   ///< COLOR_0 per vertex, linear RGBA
  const std::vector<float>* deviation_mm = nullptr;              ///< _DEVIATION per vertex (custom attribute)
  /// The node's extras (contact markers: NC line, text, region, depth).
  std::vector<std::pair<std::string, std::string>> extras_text = {};
  std::vector<std::pair<std::string, double>> extras_number = {};
};

struct GltfOptions {
  std::string generator = "cutsim";
  /// Scale of the root node: 1 keeps metres; 1000 shows a 1 mm part as 1 m
  /// for viewers with a fixed near plane.
  double scale = 1.0;
  /// Added to the asset's extras (units, colour scale...).
  std::vector<std::pair<std::string, std::string>> extras_text;
  std::vector<std::pair<std::string, double>> extras_number;
};

/// Serialises the parts to .glb bytes. Parts with no triangles are skipped.
std::string glb_bytes(const std::vector<GltfPart>& parts, const GltfOptions& opt = {});

/// Writes the parts to `path` atomically.
/// @throw OutputError when the file cannot be written.
void write_glb(const std::string& path, const std::vector<GltfPart>& parts, const GltfOptions& opt = {});

}  // namespace cutsim::io
