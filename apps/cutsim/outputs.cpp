#include "outputs.h"

#include <algorithm>
#include <cmath>

namespace cutsim::app {

std::vector<std::array<float, 4>> deviation_colors(const std::vector<float>& dev, double tol, double max_over,
                                                   double max_under) {
  std::vector<std::array<float, 4>> c(dev.size());
  for (std::size_t i = 0; i < dev.size(); ++i) {
    const double d = dev[i];
    if (std::fabs(d) <= tol) {
      c[i] = {0.55f, 0.55f, 0.55f, 1.0f};
    } else if (d < 0) {
      const float t = static_cast<float>(std::min(1.0, (-d - tol) / std::max(max_over - tol, 1e-12)));
      c[i] = {0.9f, 0.45f * (1 - t), 0.45f * (1 - t), 1.0f};
    } else {
      const float t = static_cast<float>(std::min(1.0, (d - tol) / std::max(max_under - tol, 1e-12)));
      c[i] = {0.45f * (1 - t), 0.45f * (1 - t), 0.9f, 1.0f};
    }
  }
  return c;
}

std::vector<io::GltfPart> comparison_parts(const compare::CompareResult& c, io::GltfPart surface,
                                           io::GltfOptions& gopt, std::vector<std::array<float, 4>>& colors) {
  const double tol = c.tolerance_mm;
  colors = deviation_colors(c.vertex_deviation_mm, tol, c.max_overcut_mm, c.max_undercut_mm);
  surface.colors = &colors;
  surface.deviation_mm = &c.vertex_deviation_mm;
  gopt.extras_text = {{"colour_scale", "COLOR_0: red overcut, blue undercut, grey within +-tolerance; "
                                       "_DEVIATION: signed distance to the target in mm, + undercut, - overcut"}};
  gopt.extras_number = {{"tolerance_mm", tol}, {"max_overcut_mm", c.max_overcut_mm},
                        {"max_undercut_mm", c.max_undercut_mm}};
  io::GltfPart over{"overcut", &c.overcut_mesh, {0.85f, 0.05f, 0.05f, 1.0f}};
  io::GltfPart under{"undercut", &c.undercut_mesh, {0.05f, 0.1f, 0.85f, 1.0f}};
  // Drawn on a coarser grid than the stock's when the regions are large.
  over.extras_number = under.extras_number = {{"mesh_voxel_mm", c.region_mesh_voxel_mm}};
  return {surface, over, under};
}

}  // namespace cutsim::app
