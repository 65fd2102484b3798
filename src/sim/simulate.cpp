#include "cutsim/sim/simulate.h"

#include <chrono>
#include <cmath>
#include <fstream>
#include <sstream>
#include <sys/resource.h>

#include "cutsim/core/error.h"
#include "cutsim/gcode/program_reader.h"
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

SimResult simulate(const SimOptions& opt) {
  const auto t_start = Clock::now();
  SimResult res;
  res.program = opt.program;

  // Settings: command line over job file over defaults.
  ProgramOptions popt;
  popt.dialect = opt.dialect ? *opt.dialect : opt.job.dialect ? *opt.job.dialect : gcode::Dialect::rs274ngc;
  popt.block_delete = opt.block_delete || opt.job.block_delete.value_or(false);
  res.tool = opt.tool ? *opt.tool : opt.job.tool ? *opt.job.tool : tool::parse_tool_spec("ball:d=1", "default");
  if (!opt.tool && !opt.job.tool) res.defaults.notes.push_back("tool: ball:d=1 (default; set --tool or [tool] spec)");
  const double tool_r = res.tool.radius();

  // Pass 1: check the whole program and find where the cutting moves go,
  // before any grid is built or any output written. The start position is
  // not known yet: X0 Y0 and far above, refined after the stock is known.
  motion::InterpreterOptions iopt;
  std::optional<Aabb> stock_box = opt.stock_box ? opt.stock_box : opt.job.stock_box;
  Aabb cut_path;  // tool tip path of feed moves
  auto check_axes = [&](const motion::Move& m, const gcode::Block& b) {
    if ((m.end.abc - m.start.abc).cwiseAbs().maxCoeff() > 0) {
      int col = 1;
      for (const auto& w : b.words)
        if (w.letter >= 'A' && w.letter <= 'C') { col = w.column; break; }
      throw ParseError(SourceLocation{opt.program, m.line, col, b.text},
                       "rotary axis moves need a multi-axis machine; this run uses the 3-axis xyz machine");
    }
    if ((m.tool_axis - Vec3::UnitZ()).norm() > 1e-12)
      throw ParseError(SourceLocation{opt.program, m.line, 1, b.text},
                       "the tool axis is tilted (G53.1); this run uses the 3-axis xyz machine");
  };
  {
    iopt.initial.xyz = opt.job.start_mm ? *opt.job.start_mm : Vec3(0, 0, 0);
    const CheckResult cr = stream_moves(opt.program, popt, iopt, [&](const motion::Move& m, const gcode::Block& b) {
      check_axes(m, b);
      if (m.is_cutting_feed()) {
        ++res.cutting_moves;
        cut_path.extend(m.path_bounds());
      }
    });
    res.blocks = cr.blocks;
    res.lines = cr.lines;
    res.moves = cr.moves;
    res.warnings = cr.warnings;
  }
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
    res.voxel_mm = nice_ceil(std::max(tool_r / 25.0, std::sqrt(area / 2e7)));
    std::ostringstream os;
    os << "voxel: " << res.voxel_mm << " mm (default: tool radius / 25, at most ~2e7 voxels per layer of cut area; set --voxel)";
    res.defaults.notes.push_back(os.str());
  }

  // Region of interest: what the sweeps reach inside the stock.
  stock::StockOptions sopt;
  sopt.voxel_mm = res.voxel_mm;
  if (opt.job.memory_limit_mb) sopt.memory_limit_bytes = static_cast<std::size_t>(*opt.job.memory_limit_mb * 1048576.0);
  const double margin = (sopt.half_band_voxels + 2) * res.voxel_mm;
  const Aabb stock_reach = res.stock_box.expanded(margin);
  Aabb roi;
  int total_moves = 0;
  stream_moves(opt.program, popt, iopt, [&](const motion::Move& m, const gcode::Block&) {
    ++total_moves;
    const Aabb b = sweep::sweep_move(m, res.tool).bounds;
    if (b.overlaps(stock_reach)) roi.extend(b.intersected(stock_reach));
  });
  res.timing.parse_s = seconds_since(t_start);

  const auto t_sim = Clock::now();
  if (roi.empty()) {
    // Nothing reaches the stock: a minimal grid keeps the outputs uniform.
    roi = Aabb{res.stock_box.max - Vec3::Constant(margin), res.stock_box.max};
  }
  res.stock = std::make_unique<stock::Stock>(res.stock_box, roi.expanded(margin), sopt);

  // Pass 2: cut.
  int done = 0;
  stream_moves(opt.program, popt, iopt, [&](const motion::Move& m, const gcode::Block&) {
    const sweep::Sweep s = sweep::sweep_move(m, res.tool, sweep::SweepOptions{std::min(1e-4, res.voxel_mm / 20)});
    res.stock->subtract(s);
    ++done;
    if (opt.progress && (done % 64 == 0 || done == total_moves))
      opt.progress(static_cast<double>(done) / std::max(total_moves, 1), m.line);
  });
  res.timing.simulate_s = seconds_since(t_sim);
  return res;
}

}  // namespace cutsim::sim
