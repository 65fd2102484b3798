// cutsim check PROG.nc: parse and interpret without simulating.
#include <filesystem>
#include <iostream>
#include <memory>

#include <nlohmann/json.hpp>

#include "commands.h"
#include "cutsim/core/error.h"
#include "cutsim/io/job.h"
#include "cutsim/sim/report.h"
#include "cutsim/sim/simulate.h"

namespace cutsim::app {

namespace {
struct CheckArgs {
  std::string program;
  bool dump = false;
  std::string dialect = "rs274ngc";
  bool block_delete = false;
  std::string machine;
};
}  // namespace

Action add_check_command(CLI::App& app) {
  auto args = std::make_shared<CheckArgs>();
  CLI::App* cmd = app.add_subcommand("check", "parse and interpret a program; print errors and warnings");
  cmd->add_option("program", args->program, "NC program (G-code)")->required();
  cmd->add_flag("--dump", args->dump, "print the resolved motion as JSON lines, one per move (mm, degrees)");
  cmd->add_option("--dialect", args->dialect, "G-code dialect: rs274ngc (default) or fanuc")
      ->check(CLI::IsMember({"rs274ngc", "fanuc"}));
  cmd->add_flag("--block-delete", args->block_delete, "skip lines that start with '/'");
  cmd->add_option("--machine", args->machine,
                  "also check axis velocity, acceleration and stroke on this machine (preset or .toml)");

  return [args]() -> int {
    if (!std::filesystem::exists(args->program)) throw InputError(args->program, "no such file");
    motion::InterpreterOptions iopt;
    sim::ProgramOptions popt;
    popt.dialect = io::parse_dialect(args->dialect, "--dialect");
    popt.block_delete = args->block_delete;
    auto on_move = [&](const motion::Move& m) {
      if (!args->dump) return;
      nlohmann::ordered_json j;
      j["line"] = m.line;
      j["motion"] = motion::motion_name(m.kind);
      j["end"] = {m.end.xyz.x(), m.end.xyz.y(), m.end.xyz.z(), rad_to_deg(m.end.abc.x()),
                  rad_to_deg(m.end.abc.y()), rad_to_deg(m.end.abc.z())};
      if (m.is_arc()) j["centre"] = {m.centre.x(), m.centre.y(), m.centre.z()};
      j["feed_mm_per_min"] = m.feed_mm_per_min;
      std::cout << j.dump() << "\n";
    };
    const sim::CheckResult r = sim::check_program(args->program, popt, iopt, on_move);
    for (const auto& w : r.warnings)
      std::cerr << args->program << ":" << w.line << ":" << w.column << ": warning: " << w.message << "\n";
    (args->dump ? std::cerr : std::cout) << args->program << ": " << r.blocks << " blocks, " << r.moves
                                         << " moves, no errors (peak RSS " << static_cast<int>(sim::peak_rss_mb())
                                         << " MB)\n";
    if (!args->machine.empty()) {
      const sim::AxisReport ax = sim::analyze_axes(args->program, popt, args->machine, iopt);
      std::ostream& os = args->dump ? std::cerr : std::cout;
      os << "machine " << ax.machine << ": program time " << ax.program_time_s << " s, "
         << ax.violations.size() << " axis-limit violations\n";
      // A line per axis and quantity, then every record (a lint's listing).
      for (const machine::ViolationKind& k : machine::summarize_violations(ax.violations))
        os << "  " << sim::format_violation_kind(k, ax.violations) << "\n";
      for (const auto& a : ax.violations)
        os << args->program << ":" << a.line << ": " << a.axis << " " << a.quantity << " " << a.value << " " << a.unit
           << " over the limit " << a.limit << ": " << (a.text ? *a.text : "") << "\n";
      for (const auto& a : ax.amplitude_limits)
        os << "amplitude limit " << a.axis << " at " << a.frequency_hz << " Hz: " << a.amplitude_mm << " mm ("
           << a.limited_by << ")\n";
      return ax.violations.empty() ? 0 : 1;
    }
    return 0;
  };
}

}  // namespace cutsim::app
