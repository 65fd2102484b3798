#include "cutsim/cases/cases.h"

#include "cases_impl.h"
#include "cutsim/core/error.h"

namespace cutsim::cases {

const std::vector<Case>& all_cases() {
  static const std::vector<Case> cases{
      {"snowflake", "1: snow crystal planed by a 90 deg V tool (seeds/001)", snowflake_files},
      {"blade", "2: turbine blade, 3-axis roughing and 5-axis finishing on xyzbc (seeds/001)", blade_files},
      {"lens", "3: slow-tool-servo 1 x 2 lens array on xzc, both compensations (seeds/002)", lens_files},
      {"flycut", "4: raster fly-cutting with a pressure drift on Z's laser scale (seeds/000)", flycut_files},
      {"fouraxis", "5: 4-axis faces with dy_AY = -0.5 mm (seeds/003)", fouraxis_files},
      {"raster40k", "speed goal: 40,000-move ball-end raster, 100 x 100 mm at 0.1 mm voxels", raster_files},
  };
  return cases;
}

const Case& find_case(const std::string& name) {
  for (const Case& c : all_cases())
    if (c.name == name) return c;
  std::string known;
  for (const Case& c : all_cases()) known += (known.empty() ? "" : ", ") + c.name;
  throw UsageError("unknown case '" + name + "' (cases: " + known + ")");
}

}  // namespace cutsim::cases
