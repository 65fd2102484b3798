#include "cutsim/sim/simulate.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <fstream>
#include <optional>
#include <span>
#include <sstream>
#include <sys/resource.h>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include "cutsim/core/error.h"
#include "cutsim/core/huge_pages.h"
#include "cutsim/core/interrupt.h"
#include "cutsim/gcode/program_reader.h"
#include "cutsim/io/mesh_io.h"
#include "cutsim/io/tool_library.h"
#include "cutsim/sim/planner.h"
#include "cutsim/sweep/sweep.h"

namespace cutsim::sim {

namespace {

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

std::ifstream open_program(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path, "cannot open program: " + std::string(std::strerror(errno)));
  return in;
}

// Streams the program through the interpreter, calling `f` for every move.
template <class F>
CheckResult stream_moves(const std::string& path, const ProgramOptions& popt, const motion::InterpreterOptions& iopt_in, F&& f) {
  std::ifstream in = open_program(path);
  gcode::ReaderOptions ropt;
  ropt.dialect = popt.dialect;
  ropt.block_delete = popt.block_delete;
  gcode::ProgramReader reader(in, path, ropt);
  motion::InterpreterOptions iopt = iopt_in;
  iopt.dialect = popt.dialect;
  motion::Interpreter interp(path, iopt);
  gcode::Block block;
  std::vector<motion::Move> moves;
  CheckResult r;
  while (reader.next(block)) {
    if (interrupted())
      throw InterruptedError(SourceLocation{path, block.line, 0, block.text}, interrupt_signal().load(),
                             "interrupted while reading line " + std::to_string(block.line));
    ++r.blocks;
    moves.clear();
    interp.execute(block, moves);
    for (const motion::Move& m : moves) {
      ++r.moves;
      f(m, block);
    }
  }
  r.lines = reader.lines_read();
  r.warnings = interp.warnings();
  return r;
}

// A nice voxel size: 1, 2 or 5 times a power of ten, not below `h`.
double nice_ceil(double h) {
  const double e = std::pow(10.0, std::floor(std::log10(h)));
  for (double f : {1.0, 2.0, 5.0, 10.0})
    if (f * e >= h * (1 - 1e-9)) return f * e;
  return 10 * e;
}

std::string fmt_box(const Aabb& b) {
  std::ostringstream os;
  os << b.min.x() << "," << b.min.y() << "," << b.min.z() << "," << b.max.x() << "," << b.max.y() << "," << b.max.z();
  return os.str();
}

}  // namespace

double peak_rss_mb() {
  rusage ru{};
  getrusage(RUSAGE_SELF, &ru);
  return static_cast<double>(ru.ru_maxrss) / 1024.0;
}

CheckResult check_program(const std::string& program, const ProgramOptions& popt,
                          const motion::InterpreterOptions& iopt,
                          const std::function<void(const motion::Move&)>& on_move) {
  return stream_moves(program, popt, iopt, [&](const motion::Move& m, const gcode::Block&) {
    if (on_move) on_move(m);
  });
}

namespace {
machine::JointError parse_error_fields(const std::string& text, const std::string& origin) {
  machine::JointError e;
  std::stringstream ss(text);
  std::string item;
  while (std::getline(ss, item, ',')) {
    const auto eq = item.find('=');
    if (eq == std::string::npos) throw ConfigError(SourceLocation{origin, 0, 0, {}}, "expected key=value, got '" + item + "'");
    const std::string k = item.substr(0, eq), v = item.substr(eq + 1);
    char* end = nullptr;
    const double d = std::strtod(v.c_str(), &end);
    if (v.empty() || *end != '\0' || !std::isfinite(d))
      throw ConfigError(SourceLocation{origin, 0, 0, {}}, "'" + v + "' is not a number");
    if (k == "dx") e.dx = d; else if (k == "dy") e.dy = d; else if (k == "dz") e.dz = d;
    else if (k == "alpha") e.alpha = d; else if (k == "beta") e.beta = d; else if (k == "gamma") e.gamma = d;
    else throw ConfigError(SourceLocation{origin, 0, 0, {}}, "unknown key '" + k + "' (dx dy dz mm, alpha beta gamma rad)");
  }
  return e;
}
}  // namespace

void apply_joint_error(machine::Machine& m, const std::string& spec, const std::string& origin) {
  const auto colon = spec.find(':');
  if (colon != 1) throw ConfigError(SourceLocation{origin, 0, 0, {}}, "joint error '" + spec + "': expected AXIS:key=value,...");
  const int j = m.joint_of(spec[0]);
  if (j < 0) throw ConfigError(SourceLocation{origin, 0, 0, {}}, std::string("machine ") + m.name + " has no axis " + spec[0]);
  m.chain[static_cast<std::size_t>(j)].error = parse_error_fields(spec.substr(2), origin);
}

Pose parse_setting(const std::string& spec, const std::string& origin) {
  return parse_error_fields(spec, origin).transform();
}

namespace {
void amplitude_limits_of(const machine::Machine& mach, const machine::AxisMonitor& mon,
                         std::vector<machine::AmplitudeLimit>& out) {
  // At the frequency of a turning rotary joint (a lathe spindle under slow
  // tool servo): one undulation per revolution.
  for (std::size_t j = 0; j < mach.chain.size(); ++j) {
    if (mach.chain[j].type != machine::JointType::rotary || mon.revolutions(static_cast<int>(j)) < 1) continue;
    const double f = mon.revolutions(static_cast<int>(j)) / mon.turning_time(static_cast<int>(j));
    for (const auto& lj : mach.chain)
      if (lj.type == machine::JointType::linear) out.push_back(machine::amplitude_limit(lj, f));
  }
}
}  // namespace

TriMesh load_target(const std::string& file, double scale, const Vec3& rotate_deg, const Vec3& offset_mm) {
  TriMesh m = io::load_mesh(file);
  const Eigen::Matrix3d R = (Eigen::AngleAxisd(deg_to_rad(rotate_deg.z()), Vec3::UnitZ()) *
                             Eigen::AngleAxisd(deg_to_rad(rotate_deg.y()), Vec3::UnitY()) *
                             Eigen::AngleAxisd(deg_to_rad(rotate_deg.x()), Vec3::UnitX())).toRotationMatrix();
  for (Vec3& p : m.positions) p = R * (scale * p) + offset_mm;
  io::require_closed(m, file);
  return m;
}

AxisReport analyze_axes(const std::string& program, const ProgramOptions& popt, const std::string& machine_name,
                        const motion::InterpreterOptions& iopt) {
  const machine::Machine mach = machine::load_machine(machine_name);
  const machine::Kinematics kin(mach);
  Planner planner(kin, iopt.initial, {});
  planner.set_file(program);
  machine::AxisMonitor mon(mach, machine::joints_of(iopt.initial));
  AxisReport r;
  r.machine = mach.name;
  stream_moves(program, popt, iopt, [&](const motion::Move& m, const gcode::Block&) {
    ++r.moves;
    planner.monitor(m, planner.plan(m), mon);
  });
  r.program_time_s = planner.time_s();
  r.violations = mon.violations();
  amplitude_limits_of(mach, mon, r.amplitude_limits);
  return r;
}

namespace {

// A move planned, with its tool (and, once the cutting pass builds it,
// its sweep), waiting for its group: both passes plan moves in order and
// work on them side by side.
struct QueuedMove {
  motion::Move m;
  PlannedMove pm;
  const tool::Tool* tool;
  sweep::Sweep sw;
};

}  // namespace

SimResult simulate(const SimOptions& opt) {
  const auto t_start = Clock::now();
  SimResult res;
  res.program = opt.program;

  // Settings: command line over job file over defaults.
  ProgramOptions popt;
  popt.dialect = opt.dialect ? *opt.dialect : opt.job.dialect ? *opt.job.dialect : gcode::Dialect::rs274ngc;
  popt.block_delete = opt.block_delete || opt.job.block_delete.value_or(false);
  // Tools: a library resolves T numbers; a spec is the tool without a
  // library, or before the first tool change with one.
  std::optional<io::ToolLibrary> library;
  if (opt.tools_file) library = io::load_tool_library(*opt.tools_file);
  else if (opt.job.tool_library) library = io::load_tool_library(*opt.job.tool_library);
  std::optional<tool::Tool> spec_tool = opt.tool ? opt.tool : opt.job.tool;
  if (!spec_tool && !library) {
    spec_tool = tool::parse_tool_spec("ball:d=1", "default");
    res.defaults.notes.push_back("tool: ball:d=1 (default; set --tool, --tools or [tool] spec)");
  }
  if (library) res.tool_library = library->source;
  bool noted_t0 = false;
  auto tool_for = [&](const motion::Move& m) -> const tool::Tool& {
    if (!library) return *spec_tool;
    if (m.tool == 0) {
      if (spec_tool) return *spec_tool;
      const tool::Tool& first = library->tools.begin()->second;
      if (!noted_t0) {
        res.defaults.notes.push_back("tool: moves before the first tool change use T" + std::to_string(first.number) +
                                     " (the library's first; set --tool for them)");
        noted_t0 = true;
      }
      return first;
    }
    if (const tool::Tool* t = library->find(m.tool)) return *t;
    std::string have;
    for (const auto& [n, t] : library->tools) have += (have.empty() ? "T" : ", T") + std::to_string(n);
    throw ConfigError(SourceLocation{opt.program, m.line, 1, m.text ? *m.text : std::string()},
                      "tool T" + std::to_string(m.tool) + " is not in the tool library " + library->source +
                          " (it holds " + have + ")");
  };
  auto note_use = [&](const tool::Tool& t) {
    for (const auto& u : res.tools_used)
      if (u.number == t.number && u.name == t.name) return;
    res.tools_used.push_back(t);
  };

  // The machine, its errors and the air.
  machine::Machine mach = machine::load_machine(opt.machine ? *opt.machine : opt.job.machine.value_or("xyz"));
  for (const auto& [axis, spec] : opt.job.joint_errors) apply_joint_error(mach, axis + ":" + spec, opt.job.source);
  for (const auto& spec : opt.joint_errors) apply_joint_error(mach, spec, "--joint-error");
  if (opt.job.tool_setting) mach.tool_setting = parse_setting(*opt.job.tool_setting, opt.job.source);
  if (opt.job.workpiece_setting) mach.workpiece_setting = parse_setting(*opt.job.workpiece_setting, opt.job.source);
  if (opt.tool_setting) mach.tool_setting = parse_setting(*opt.tool_setting, "--tool-setting");
  if (opt.workpiece_setting) mach.workpiece_setting = parse_setting(*opt.workpiece_setting, "--workpiece-setting");
  res.machine = mach.name;
  const machine::Kinematics kin(mach);
  machine::EnvironmentLog env;
  const std::optional<std::string> env_path = opt.environment ? opt.environment : opt.job.environment;
  if (env_path) env = machine::EnvironmentLog::load_csv(*env_path);
  bool laser_axes = false;
  for (const auto& j : mach.chain) laser_axes |= j.laser.has_value();
  res.laser_error_applied = laser_axes && !env.empty();

  // Pass 1: check the whole program, time it against the machine, find
  // where the cutting moves go, before any grid is built or output written.
  motion::InterpreterOptions iopt;
  // (Assigned, not copied from the ternary: GCC 12 then warns the payload
  // may be read uninitialized.)
  std::optional<Aabb> stock_box;
  if (opt.stock_box) stock_box.emplace(*opt.stock_box);
  else if (opt.job.stock_box) stock_box.emplace(*opt.job.stock_box);
  Aabb cut_path;  // tool tip path of feed moves, workpiece frame
  Planner::Options plopt;
  plopt.environment = env.empty() ? nullptr : &env;
  {
    iopt.initial.xyz = opt.job.start_mm ? *opt.job.start_mm : Vec3(0, 0, 0);
    Planner planner(kin, iopt.initial, plopt);
    planner.set_file(opt.program);
    const CheckResult cr = stream_moves(opt.program, popt, iopt, [&](const motion::Move& m, const gcode::Block&) {
      const PlannedMove pm = planner.plan(m);
      const tool::Tool& t = tool_for(m);
      if (m.is_cutting_feed()) {
        note_use(t);
        ++res.cutting_moves;
        if (kin.is_identity()) cut_path.extend(m.path_bounds());
        else
          for (double s : {0.0, 0.5, 1.0}) cut_path.extend(Vec3(planner.pose_at(m, pm, s).translation()));
      }
    });
    res.blocks = cr.blocks;
    res.lines = cr.lines;
    res.moves = cr.moves;
    res.warnings = cr.warnings;
  }
  res.tool = !res.tools_used.empty() ? res.tools_used.front() : spec_tool ? *spec_tool : library->tools.begin()->second;
  const double tool_r = res.tool.radius();
  if (!stock_box) {
    if (cut_path.empty())
      throw ConfigError(SourceLocation{opt.program, 0, 0, {}},
                        "the program has no cutting moves to place a default stock under; give --stock-box or a job file");
    // Default: the box under the cutting moves: their XY extent grown by the
    // tool radius, top at Z0 when the cuts straddle it (else at the highest
    // cut), 1 mm of material below the deepest cut.
    Aabb b;
    const double top = std::clamp(0.0, cut_path.min.z(), cut_path.max.z());
    const double bottom = cut_path.min.z() - 1.0;
    b.min = Vec3(cut_path.min.x() - tool_r, cut_path.min.y() - tool_r, bottom);
    b.max = Vec3(cut_path.max.x() + tool_r, cut_path.max.y() + tool_r, top > bottom ? top : bottom + 1.0);
    if (b.max.z() - b.min.z() <= 0) b.max.z() = b.min.z() + 1.0;
    stock_box = b;
    res.defaults.notes.push_back("stock: box " + fmt_box(b) + " mm (default: under the cutting moves; set --stock-box)");
  }
  res.stock_box = *stock_box;
  const Vec3 start = opt.job.start_mm ? *opt.job.start_mm : Vec3(0, 0, res.stock_box.max.z() + 10.0);
  if (!opt.job.start_mm) {
    std::ostringstream os;
    os << "start: tool tip at X0 Y0 Z" << start.z() << " (default: 10 mm above the stock; set [simulation] start)";
    res.defaults.notes.push_back(os.str());
  }
  iopt.initial.xyz = start;

  // Voxel size: command line, job, else from the tool and the cut area.
  const double area = cut_path.empty() ? 1.0 : (cut_path.size().x() + 2 * tool_r) * (cut_path.size().y() + 2 * tool_r);
  if (opt.voxel_mm) res.voxel_mm = *opt.voxel_mm;
  else if (opt.job.voxel_mm) res.voxel_mm = *opt.job.voxel_mm;
  else {
    // The size that shapes the surface: the radius of an end mill, the nose
    // radius of a fly-cutter or nose tool, a fifth of a V tool's edge.
    const tool::Tool& t = res.tool;
    const double feature = t.kind == tool::ToolKind::flycutter || t.kind == tool::ToolKind::nose ? t.corner_radius_mm
                           : t.kind == tool::ToolKind::vtool ? t.edge_height_mm / 5 : tool_r;
    res.voxel_mm = nice_ceil(std::max(feature / 25.0, std::sqrt(area / 2e7)));
    std::ostringstream os;
    os << "voxel: " << res.voxel_mm << " mm (default: tool size / 25, at most ~2e7 voxels per layer of cut area; set --voxel)";
    res.defaults.notes.push_back(os.str());
  }
  // Sampled sweeps stay within a quarter voxel of the true ones.
  plopt.sweep_tolerance_mm = res.voxel_mm / 4;
  plopt.chord_tolerance_mm = std::min(1e-4, res.voxel_mm / 20);

  // Region of interest: what the sweeps reach inside the stock; axis limits.
  stock::StockOptions sopt;
  sopt.voxel_mm = res.voxel_mm;
  sopt.measure_band_every = opt.measure_band_every;
  if (opt.job.memory_limit_mb) sopt.memory_limit_bytes = static_cast<std::size_t>(*opt.job.memory_limit_mb * 1048576.0);
  const double margin = (sopt.half_band_voxels + 2) * res.voxel_mm;
  const Aabb stock_reach = res.stock_box.expanded(margin);
  plopt.interest = stock_reach;
  Aabb roi;
  int total_moves = 0;
  {
    Planner planner(kin, iopt.initial, plopt);
    planner.set_file(opt.program);
    machine::AxisMonitor mon(mach, machine::joints_of(iopt.initial));
    // What a move reaches of the stock (the union of boxes does not depend
    // on the order: moves are planned in order, then measured side by side
    // in groups).
    auto reach_of = [&](const motion::Move& m, const PlannedMove& pm, const tool::Tool& t) {
      Aabb out;
      // Piece by piece: a sampled rotary move's overall box can span the
      // whole stock while its pieces pass outside it.
      const sweep::Sweep sw = planner.sweep(m, pm, t);
      if (sw.bounds.overlaps(stock_reach))
        for (const auto& prim : sw.prims) {
          const Aabb& b = sweep::bounds(prim);
          if (b.overlaps(stock_reach)) out.extend(b.intersected(stock_reach));
        }
      // The regions that must not touch: where they reach into the stock,
      // the grid must hold the material they might meet.
      const int n = m.is_straight() ? 1 : 16;
      for (const auto& r : tool::contact_regions(t)) {
        const Aabb lb = tool::shape_bounds(r.shape);
        for (int i = 0; i <= n; ++i) {
          const Pose q = planner.pose_at(m, pm, static_cast<double>(i) / n) * r.frame;
          const Aabb b = sweep::world_box(lb, q.linear(), q.translation()).expanded(n > 1 ? 0.1 * lb.size().norm() : 0.0);
          if (b.overlaps(stock_reach)) out.extend(b.intersected(stock_reach));
        }
      }
      return out;
    };
    std::vector<QueuedMove> planned;
    auto measure = [&] {
      const Aabb got = tbb::parallel_reduce(
          tbb::blocked_range<std::size_t>(0, planned.size(), 16), Aabb(),
          [&](const auto& r, Aabb acc) {
            for (std::size_t j = r.begin(); j != r.end(); ++j) acc.extend(reach_of(planned[j].m, planned[j].pm, *planned[j].tool));
            return acc;
          },
          [](Aabb a, const Aabb& b) {
            a.extend(b);
            return a;
          });
      roi.extend(got);
      planned.clear();
    };
    stream_moves(opt.program, popt, iopt, [&](const motion::Move& m, const gcode::Block&) {
      ++total_moves;
      const PlannedMove pm = planner.plan(m);
      planner.monitor(m, pm, mon);
      planned.push_back({m, pm, &tool_for(m), {}});
      if (planned.size() >= 256) measure();
    });
    measure();
    res.axis_limit_violations = mon.violations();
    res.program_time_s = planner.time_s();
    amplitude_limits_of(mach, mon, res.amplitude_limits);
  }
  res.timing.parse_s = seconds_since(t_start);
  // The target (read beside the program's passes), before any grid.
  if (opt.target_bounds)
    if (const Aabb tb = opt.target_bounds(); !tb.overlaps(res.stock_box))
      throw GeometryError(SourceLocation{opt.target_file, 0, 0, {}},
                          "the target (" + fmt_box(tb) + " mm) does not overlap the stock (" + fmt_box(res.stock_box) +
                              " mm): nothing to compare; check its placement ([target] offset)");

  const auto t_sim = Clock::now();
  if (roi.empty()) {
    // Nothing reaches the stock: a minimal grid keeps the outputs uniform.
    roi = Aabb{res.stock_box.max - Vec3::Constant(margin), res.stock_box.max};
  }
  // A grid under 2 GiB takes its new memory in small pages, until the
  // simulation ends (stock_wants_small_pages: on this machine they cost
  // less to touch first, and a grid that size gains little from huge ones).
  std::optional<SmallPagesForNewMemory> small_pages;
  if (stock_wants_small_pages(stock::estimate_memory_bytes(res.stock_box, roi.expanded(margin), sopt)))
    small_pages.emplace();
  res.stock_page_kb = huge_pages_for_new_memory() ? 2048 : 4;
  try {
    res.stock = std::make_unique<stock::Stock>(res.stock_box, roi.expanded(margin), sopt);
  } catch (const InterruptedError& e) {
    throw InterruptedError(SourceLocation{opt.program, 0, 0, {}}, e.exit_status() - 128,
                           e.message() + ", before the first cut");
  }
  res.timing.stock_build_s = seconds_since(t_sim);

  // Pass 2: check the non-cutting regions, then cut.
  int done = 0;
  Planner planner(kin, iopt.initial, plopt);
  planner.set_file(opt.program);
  res.contact_tolerance_mm = opt.contact_tolerance_mm ? *opt.contact_tolerance_mm
                             : opt.job.contact_tolerance_mm ? *opt.job.contact_tolerance_mm
                                                            : res.voxel_mm / 4;
  const bool stop_at_contact = opt.stop_at_first_contact || opt.job.stop_at_first_contact.value_or(false);
  InterferenceChecker checker(*res.stock, planner, res.contact_tolerance_mm, plopt.sweep_tolerance_mm);
  struct StopAtContact {};
  // Consecutive moves are subtracted in batches: a leaf many short moves
  // reach is then visited once per batch, not once per move. Where the
  // contact check finds a touch the batch would change, it tests the pose
  // again on the stock less the batch's latest cuts, held back, and only
  // where the older ones would change what it then finds does it subtract
  // the batch first (InterferenceChecker::PendingCuts). The union
  // removed does not depend on where batches end; they start small (an
  // interrupt or --partial soon has a result) and double up to a number
  // of moves and pieces. Sizes follow the program only, so runs repeat
  // exactly. (The stock bounds the memory of binning a batch itself, by
  // the leaves its pieces really reach.)
  constexpr std::size_t kMaxBatchMoves = 4096, kBatchPrims = 16384;
  std::size_t batch_moves = 8;
  std::vector<sweep::Sweep> pending;
  std::size_t pending_prims = 0;
  int pending_last_line = 0;
  double flush_s = 0;  // stock update time spent inside the contact check
  std::size_t stock_changes = 0;  // subtractions so far
  auto flush = [&] {
    if (pending.empty()) return;
    const auto t = Clock::now();
    res.stock->subtract(pending);
    ++stock_changes;
    const double s = seconds_since(t);
    res.timing.stock_update_s += s;
    flush_s += s;
    if (!interrupted()) res.last_line_cut = pending_last_line;
    batch_moves = std::min(2 * batch_moves, kMaxBatchMoves);
    pending.clear();
    pending_prims = 0;
  };
  // A V or nose tool's consecutive moves at one orientation: each prism's
  // piece that closes its joints with its neighbours (sweep::JointPrim)
  // rides with the move after it; its slab reaches the band past the
  // prism's ends (deeper is clamped alike).
  sweep::Joiner join(res.stock->band_mm(), stock_reach);
  auto cut_tail = [&] {  // the last prism's piece, once no move follows
    if (sweep::Sweep tail = join.finish(); !tail.prims.empty()) pending.push_back(std::move(tail));
    flush();
  };
  InterferenceChecker::PendingCuts held =
      InterferenceChecker::pending_cuts([&] { return HeldCuts(pending); }, *res.stock, opt.latest_cuts);
  held.flush = [&] {
    const bool any = !pending.empty();
    flush();
    return any;
  };
  // A move's cut is held back where it reaches the stock's grid.
  auto reaches_grid = [&](const sweep::Sweep& sw) {
    return !sw.prims.empty() && sw.bounds.overlaps(res.stock->roi().expanded(res.stock->band_mm() + res.voxel_mm));
  };
  try {
  // Moves are checked in groups: their first scans side by side on the
  // stock as it is (they only read it), then each move in order, where a
  // scan stands unless a subtraction since makes it stale (and it found a
  // touch): the same contacts and cuts as move by move, with the second
  // thread busy where most scans are too small to share. (One at a time
  // when stopping at the first contact: the moves after it must not be
  // joined to it.)
  const std::size_t group_size = stop_at_contact ? 1 : std::max<std::size_t>(1, opt.check_group);
  std::vector<QueuedMove> group;
  std::vector<InterferenceChecker::FirstScans> firsts;
  PlaningRun runs;
  std::vector<PlaningRun::View> run_views;
  auto check_group = [&] {
    if (group.empty()) return;
    // Each move's planing run as it starts, in order (before the scans
    // side by side, which only read them).
    run_views.assign(group.size(), {});
    if (opt.planing_runs)
      for (std::size_t j = 0; j < group.size(); ++j)
        run_views[j] = runs.next(group[j].m, group[j].pm, *group[j].tool, planner);
    // The moves' sweeps side by side too (joined in order below).
    const auto t0 = Clock::now();
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, group.size(), 1), [&](const auto& r) {
      for (std::size_t j = r.begin(); j != r.end(); ++j) group[j].sw = planner.sweep(group[j].m, group[j].pm, *group[j].tool);
    });
    res.timing.plan_sweep_s += seconds_since(t0);
    // Joined in order, then held as they will be when each move is checked:
    // the batch, then the group's moves before it.
    std::vector<sweep::Sweep> cuts;
    std::vector<std::size_t> cuts_before(group.size() + 1, 0);
    for (std::size_t j = 0; j < group.size(); ++j) {
      join(group[j].sw);
      cuts_before[j] = cuts.size();
      if (reaches_grid(group[j].sw)) cuts.push_back(std::move(group[j].sw));
    }
    cuts_before[group.size()] = cuts.size();
    firsts.assign(group.size(), {});
    const auto t1 = Clock::now();
    if (group.size() > 1) {
      tbb::parallel_for(tbb::blocked_range<std::size_t>(0, group.size(), 1), [&](const auto& r) {
        for (std::size_t j = r.begin(); j != r.end(); ++j) {
          const HeldCuts before(pending, std::span<const sweep::Sweep>(cuts).first(cuts_before[j]));
          const InterferenceChecker::PendingCuts view =
              InterferenceChecker::pending_cuts([before] { return before; }, *res.stock, opt.latest_cuts);
          firsts[j] = checker.first_scans(group[j].m, group[j].pm, *group[j].tool, &view, &run_views[j]);
        }
      });
    }
    res.timing.contact_check_s += seconds_since(t1);
    const std::size_t subtractions = stock_changes;
    for (std::size_t j = 0; j < group.size(); ++j) {
      const motion::Move& m = group[j].m;
      const auto t2 = Clock::now();
      flush_s = 0;
      firsts[j].current = stock_changes == subtractions;
      const bool touched =
          checker.check(m, group[j].pm, *group[j].tool, &held, group.size() > 1 ? &firsts[j] : nullptr, &run_views[j]);
      res.timing.contact_check_s += seconds_since(t2) - flush_s;
      if (cuts_before[j + 1] > cuts_before[j]) {
        pending_prims += cuts[cuts_before[j]].prims.size();
        pending.push_back(std::move(cuts[cuts_before[j]]));
      }
      pending_last_line = m.line;
      if (pending.empty() && !interrupted()) res.last_line_cut = m.line;  // nothing of it waits to be cut
      if (pending.size() >= batch_moves || pending_prims >= kBatchPrims || !opt.hold_cuts ||
          (touched && stop_at_contact))
        flush();
      if (interrupted())
        throw InterruptedError(SourceLocation{opt.program, m.line, 0, m.text ? *m.text : std::string()},
                               interrupt_signal().load(), "interrupted while cutting line " + std::to_string(m.line));
      ++done;
      if (opt.progress && (done % 64 == 0 || done == total_moves))
        opt.progress(static_cast<double>(done) / std::max(total_moves, 1), m.line);
      if (touched && stop_at_contact) {
        cut_tail();
        throw StopAtContact{};
      }
    }
    group.clear();
  };
  stream_moves(opt.program, popt, iopt, [&](const motion::Move& m, const gcode::Block&) {
    const auto t0 = Clock::now();
    const tool::Tool& t = tool_for(m);
    const PlannedMove pm = planner.plan(m);
    res.timing.plan_sweep_s += seconds_since(t0);
    group.push_back({m, pm, &t, {}});
    if (group.size() >= group_size) check_group();
  });
  check_group();
  cut_tail();
  } catch (const InterruptedError& e) {
    if (!opt.keep_partial) throw;
    res.interrupted = true;
    res.interrupt_message = e.what();
    res.interrupt_status = e.exit_status();
  } catch (const StopAtContact&) {
    res.stopped_at_contact = true;
  }
  if (res.stock) res.stock->release_scratch();
  res.contacts = checker.contacts();
  res.contact_poses = checker.poses();
  res.poses_cleared_by_runs = checker.poses_cleared();
  res.max_laser_error_mm = planner.max_laser_error_mm();
  if (opt.job.profile) res.profile = measure_profile(*res.stock, res.stock_box, *opt.job.profile);
  res.timing.simulate_s = seconds_since(t_sim);
  return res;
}

Profile measure_profile(const stock::Stock& stock, const Aabb& stock_box, const io::ProfileSpec& spec) {
  Profile p;
  p.spec = spec;
  const auto n = static_cast<std::size_t>(std::floor((spec.to - spec.from) / spec.step + 1e-9)) + 1;
  std::vector<double> s, z;
  for (std::size_t i = 0; i < n; ++i) {
    const double u = spec.from + static_cast<double>(i) * spec.step;
    const double h = spec.along == 'x' ? stock.surface_height(u, spec.at, stock_box.max.z() + stock.voxel_mm())
                                       : stock.surface_height(spec.at, u, stock_box.max.z() + stock.voxel_mm());
    p.position_mm.push_back(u);
    p.height_mm.push_back(h);
    if (std::isfinite(h)) {
      s.push_back(u);
      z.push_back(h);
    }
  }
  if (z.empty()) return p;
  const auto [lo, hi] = std::minmax_element(z.begin(), z.end());
  p.pv_mm = *hi - *lo;
  // Least-squares line through the heights.
  double ms = 0, mz = 0;
  for (std::size_t i = 0; i < s.size(); ++i) ms += s[i], mz += z[i];
  ms /= static_cast<double>(s.size());
  mz /= static_cast<double>(s.size());
  double sxx = 0, sxz = 0;
  for (std::size_t i = 0; i < s.size(); ++i) sxx += (s[i] - ms) * (s[i] - ms), sxz += (s[i] - ms) * (z[i] - mz);
  const double slope = sxx > 0 ? sxz / sxx : 0;
  double rlo = 1e300, rhi = -1e300;
  for (std::size_t i = 0; i < s.size(); ++i) {
    const double r = z[i] - mz - slope * (s[i] - ms);
    rlo = std::min(rlo, r);
    rhi = std::max(rhi, r);
  }
  p.pv_detrended_mm = rhi - rlo;
  return p;
}

}  // namespace cutsim::sim
