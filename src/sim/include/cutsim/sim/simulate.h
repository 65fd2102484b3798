#pragma once
// The pipeline: program -> blocks -> moves -> sweeps -> stock, in two
// streaming passes (plan the region of interest, then cut).
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "cutsim/compare/compare.h"
#include "cutsim/core/geometry.h"
#include "cutsim/core/mesh.h"
#include "cutsim/gcode/block.h"
#include "cutsim/io/job.h"
#include "cutsim/machine/axis_monitor.h"
#include "cutsim/machine/machine.h"
#include "cutsim/motion/interpreter.h"
#include "cutsim/sim/interference.h"
#include "cutsim/stock/stock.h"
#include "cutsim/tool/tool.h"

namespace cutsim::sim {

/// How the program text is read.
struct ProgramOptions {
  gcode::Dialect dialect = gcode::Dialect::rs274ngc;
  bool block_delete = false;  ///< skip lines starting with '/'
};

struct SimOptions {
  std::string program;          ///< NC program path
  io::Job job;                  ///< settings from the job file, overridden below
  std::optional<Aabb> stock_box;     ///< --stock-box
  std::optional<tool::Tool> tool;    ///< --tool (with a library: the tool before the first tool change)
  std::optional<std::string> tools_file;        ///< --tools FILE (.toml or LinuxCNC .tbl)
  std::optional<double> contact_tolerance_mm;   ///< --contact-tolerance
  bool stop_at_first_contact = false;           ///< --stop-at-contact
  std::optional<double> voxel_mm;    ///< --voxel
  std::optional<gcode::Dialect> dialect;  ///< --dialect
  bool block_delete = false;         ///< --block-delete
  std::optional<std::string> machine;          ///< --machine NAME|FILE
  std::vector<std::string> joint_errors;       ///< --joint-error A:dy=-0.5,gamma=1e-5
  std::optional<std::string> tool_setting;     ///< --tool-setting dx=..,dy=..,dz=..,alpha=..,beta=..,gamma=..
  std::optional<std::string> workpiece_setting;  ///< --workpiece-setting (same keys)
  std::optional<std::string> environment;      ///< --environment log.csv (laser-scale error)
  /// On interruption while cutting, return what was cut so far (marked
  /// `interrupted`) instead of throwing InterruptedError.
  bool keep_partial = false;
  /// --measure-band N: stock::StockOptions::measure_band_every (a bench figure).
  std::size_t measure_band_every = 0;
  /// Moves whose contact scans run side by side before they are checked
  /// in order (the results do not depend on it; 1: one move at a time).
  /// Each group is two parallel loops (its sweeps, its first scans) that
  /// wake the other thread: raster40k's 40,000 short moves in groups of 8
  /// took 0.016 s in the contact check and 0.012 in planning, 0.030 and
  /// 0.020 where the host was slow to run the woken thread; in groups of
  /// 64, 0.011 and 0.007 (simulate 0.352-0.368 -> 0.340-0.346 s). The
  /// snowflake and the lens read the same either way.
  std::size_t check_group = 64;
  /// Poses of a pointed V tool's planing runs whose clearance body the
  /// run's groove clears are not scanned (sim::PlaningRun; the results do
  /// not depend on it: false scans them, for the tests that compare).
  bool planing_runs = true;
  /// Cuts held back and subtracted in batches (false: each move's cut is
  /// subtracted before the next move is checked; the results are the
  /// same, the reference for tests).
  bool hold_cuts = true;
  /// How many of the latest held cuts a contact test weighs voxel by voxel
  /// (the results do not depend on it).
  std::size_t latest_cuts = InterferenceChecker::kLatestCuts;
  /// Bounds of the target, when there is one: called once, after the
  /// program's passes and before any grid is built (the target may be
  /// read beside them; what it throws stops the run there). A target
  /// that misses the stock is refused then.
  std::function<Aabb()> target_bounds;
  std::string target_file;
  /// Called with the fraction done (0..1) and the NC line being cut.
  std::function<void(double, int)> progress;
};

/// What was chosen because nothing said otherwise (printed for the user).
struct Defaults {
  std::vector<std::string> notes;
};

struct Timing {
  double parse_s = 0, simulate_s = 0, export_s = 0, total_s = 0;
  double stock_build_s = 0;   ///< part of simulate_s: filling the grid
  double plan_sweep_s = 0;    ///< part of simulate_s: kinematics, planning and sweep construction
  double stock_update_s = 0;  ///< part of simulate_s: subtracting sweeps from the grid
  double contact_check_s = 0; ///< part of simulate_s: testing the non-cutting regions
  double mesh_s = 0;          ///< part of export_s: the machined surface's mesh
  double compare_s = 0;       ///< part of export_s: overcut/undercut volumes, regions and deviations
  double write_s = 0;         ///< part of export_s: writing the glb (and the .vdb)
  double peak_rss_simulate_mb = 0;  ///< peak RSS when the simulation ended (before the export)
};

/// Surface heights of the machined top along a line ([report] profile).
struct Profile {
  io::ProfileSpec spec;
  std::vector<double> position_mm, height_mm;  ///< NaN where the line finds no surface
  double pv_mm = 0;            ///< peak to valley of the heights found
  double pv_detrended_mm = 0;  ///< after taking out the least-squares line (the tilt)
};

/// Samples `stock` along `spec` from above the stock's top.
Profile measure_profile(const stock::Stock& stock, const Aabb& stock_box, const io::ProfileSpec& spec);

struct SimResult {
  std::string program;
  int blocks = 0;        ///< blocks with words
  int lines = 0;         ///< physical lines read
  int moves = 0;         ///< all moves
  int cutting_moves = 0; ///< G1/G2/G3 moves
  tool::Tool tool;
  Aabb stock_box;
  double voxel_mm = 0;
  Defaults defaults;
  std::vector<motion::Warning> warnings;
  std::unique_ptr<stock::Stock> stock;
  Timing timing;
  /// The page size the stock's new memory came in: 4 (KB) or 2048, the
  /// transparent huge pages malloc asks for (core/huge_pages.h).
  int stock_page_kb = 4;
  std::string machine;                          ///< name of the machine used
  std::vector<machine::AxisViolation> axis_limit_violations;
  std::vector<machine::AmplitudeLimit> amplitude_limits;
  double program_time_s = 0;                    ///< from the feeds and the machine's rapids
  bool laser_error_applied = false;
  double max_laser_error_mm = 0;
  int last_line_cut = 0;                        ///< NC line of the last move subtracted
  bool interrupted = false;                     ///< stopped early (keep_partial)
  std::string interrupt_message;
  int interrupt_status = 0;                     ///< exit status the CLI returns
  std::optional<compare::CompareResult> comparison;  ///< with a target
  std::string tool_library;                     ///< library file, if any
  std::vector<tool::Tool> tools_used;           ///< in order of first use
  std::vector<Contact> contacts;                ///< non-cutting regions in the material
  double contact_tolerance_mm = 0;              ///< contacts shallower than this are not recorded
  long contact_poses = 0;                       ///< poses the contact check walked
  long poses_cleared_by_runs = 0;               ///< of them, those a planing run cleared (not scanned)
  bool stopped_at_contact = false;              ///< stop_at_first_contact ended the run
  std::optional<Profile> profile;               ///< [report] profile
};

/// The target mesh from a file, placed in the workpiece frame (scale, then
/// rotation about X, Y, Z, then offset) and checked to be closed.
/// @throw InputError, ParseError, GeometryError (open edges and the like).
TriMesh load_target(const std::string& file, double scale, const Vec3& rotate_deg, const Vec3& offset_mm);

/// Applies `AXIS:key=value,...` to the machine's joint errors and
/// `key=value,...` setting specs (keys dx dy dz in mm, alpha beta gamma in rad).
/// @throw ConfigError naming `origin`.
void apply_joint_error(machine::Machine& m, const std::string& spec, const std::string& origin);
Pose parse_setting(const std::string& spec, const std::string& origin);

/// Runs the whole simulation.
/// @throw cutsim::Error subclasses (parse, config, input, geometry).
SimResult simulate(const SimOptions& opt);

/// The program checked and interpreted, without simulating.
struct CheckResult {
  int blocks = 0;
  int lines = 0;
  int moves = 0;
  std::vector<motion::Warning> warnings;
};

/// Interprets the program; calls `on_move` for each move if given.
/// @throw cutsim::Error subclasses.
CheckResult check_program(const std::string& program, const ProgramOptions& popt,
                          const motion::InterpreterOptions& iopt,
                          const std::function<void(const motion::Move&)>& on_move = {});

/// The program on a machine without cutting: time line and axis limits.
struct AxisReport {
  std::string machine;
  int moves = 0;
  double program_time_s = 0;
  std::vector<machine::AxisViolation> violations;
  std::vector<machine::AmplitudeLimit> amplitude_limits;
};

/// Plans every move on `machine` (preset or file) and checks its axes.
/// @throw cutsim::Error subclasses.
AxisReport analyze_axes(const std::string& program, const ProgramOptions& popt, const std::string& machine,
                        const motion::InterpreterOptions& iopt = {});

/// Peak resident set size of this process, MiB.
double peak_rss_mb();

}  // namespace cutsim::sim
