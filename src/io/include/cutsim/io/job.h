#pragma once
// The job file (TOML): stock, tool and simulation settings for a program.
// Every field is optional; the command line overrides the file.
#include <optional>
#include <utility>
#include <vector>
#include <string>

#include "cutsim/core/geometry.h"
#include "cutsim/gcode/block.h"
#include "cutsim/tool/tool.h"

namespace cutsim::io {

/// A line of surface heights for the report ([report] profile): the machined
/// top sampled along X or Y at a fixed value of the other axis.
struct ProfileSpec {
  char along = 'y';        ///< 'x' or 'y'
  double at = 0;           ///< the other coordinate, mm
  double from = 0, to = 0, step = 0;  ///< mm along `along`
};

/// What a reference case is held to ([bench]): `cutsim bench` prints each
/// figure against its goal; `cutsim run` does not read it.
struct BenchGoals {
  std::optional<double> max_wall_s;       ///< end-to-end wall seconds (the bench's wall_s)
  std::optional<double> max_rss_mb;       ///< peak resident memory, MB (the bench's rss_MB)
  std::optional<double> min_moves_per_s;  ///< moves over the simulation's seconds (the bench's moves/s)
};

struct Job {
  std::string source;                ///< job file path, empty if none
  std::optional<Aabb> stock_box;     ///< [stock] box = [xmin,ymin,zmin,xmax,ymax,zmax], mm
  std::optional<tool::Tool> tool;    ///< [tool] spec = "ball:d=1"
  std::optional<std::string> tool_library;  ///< [tool] library = "tools.toml" or "tools.tbl" (beside the job)
  std::optional<double> contact_tolerance_mm;  ///< [simulation] contact_tolerance_mm
  std::optional<bool> stop_at_first_contact;   ///< [simulation] stop_at_first_contact
  std::optional<double> voxel_mm;    ///< [simulation] voxel_mm
  std::optional<Vec3> start_mm;      ///< [simulation] start = [x,y,z], tool tip at program start
  std::optional<double> memory_limit_mb;  ///< [simulation] memory_limit_mb
  std::optional<gcode::Dialect> dialect;  ///< [program] dialect = "rs274ngc" | "fanuc"
  std::optional<bool> block_delete;       ///< [program] block_delete
  std::optional<std::string> machine;     ///< [machine] name = preset or file
  std::vector<std::pair<std::string, std::string>> joint_errors;  ///< [machine.errors] A = "dy=-0.5"
  std::optional<std::string> tool_setting;       ///< [machine] tool_setting = "dz=0.01"
  std::optional<std::string> workpiece_setting;  ///< [machine] workpiece_setting = "..."
  std::optional<std::string> environment;        ///< [machine] environment = "env.csv" (beside the job)
  std::optional<std::string> target;             ///< [target] file (beside the job)
  Vec3 target_offset_mm = Vec3::Zero();          ///< [target] offset: added after rotation and scale
  Vec3 target_rotate_deg = Vec3::Zero();         ///< [target] rotate_deg: about X, then Y, then Z
  double target_scale = 1.0;                     ///< [target] scale: file units to mm (0.001 for um)
  std::optional<double> tolerance_mm;            ///< [target] tolerance_mm
  std::optional<ProfileSpec> profile;            ///< [report] profile = { along, at, from, to, step }
  std::optional<BenchGoals> bench;               ///< [bench] max_wall_s, max_rss_mb, min_moves_per_s
};

/// Reads a job file.
/// @throw InputError if it cannot be read; ConfigError with file:line:col for
///        a TOML syntax error, an unknown key, or a value of the wrong type.
Job load_job(const std::string& path);

/// "rs274ngc" or "fanuc".
/// @throw ConfigError naming `origin` for anything else.
gcode::Dialect parse_dialect(const std::string& name, const std::string& origin);

/// Parses `XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX` (mm).
/// @throw ConfigError naming `origin` when malformed or empty.
Aabb parse_box(const std::string& text, const std::string& origin);

}  // namespace cutsim::io
