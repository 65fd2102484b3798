// cutsim check PROG.nc: parse and interpret without simulating.
#include <filesystem>
#include <iostream>
#include <memory>

#include <nlohmann/json.hpp>

#include "commands.h"
#include "cutsim/core/error.h"
#include "cutsim/io/job.h"
#include "cutsim/sim/simulate.h"

namespace cutsim::app {

namespace {
struct CheckArgs {
  std::string program;
  bool dump = false;
  std::string dialect = "rs274ngc";
  bool block_delete = false;
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
                                         << " moves, no errors\n";
    return 0;
  };
}

}  // namespace cutsim::app
