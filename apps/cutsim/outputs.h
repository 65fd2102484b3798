#pragma once
// What `run` and `compare` both write: the machined surface coloured by its
// deviation from the target, with the overcut and undercut regions as nodes.
#include <array>
#include <vector>

#include "cutsim/compare/compare.h"
#include "cutsim/io/gltf_writer.h"

namespace cutsim::app {

/// Deviation colours, linear RGB: overcut red, undercut blue, within the
/// tolerance neutral; the saturation grows with the deviation.
std::vector<std::array<float, 4>> deviation_colors(const std::vector<float>& dev, double tol, double max_over,
                                                   double max_under);

/// The machined surface `surface` coloured by `c` (colours stored in
/// `colors`, which must outlive the parts), then the overcut and undercut
/// nodes; `gopt` gets the colour scale and figures in its extras.
std::vector<io::GltfPart> comparison_parts(const compare::CompareResult& c, io::GltfPart surface,
                                           io::GltfOptions& gopt, std::vector<std::array<float, 4>>& colors);

}  // namespace cutsim::app
