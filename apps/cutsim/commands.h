#pragma once
#include <CLI/CLI.hpp>
#include <functional>

namespace cutsim::app {

/// Each subcommand registers itself and returns the action to run when chosen.
using Action = std::function<int()>;
Action add_run_command(CLI::App& app);
Action add_check_command(CLI::App& app);
Action add_compare_command(CLI::App& app);
Action add_bench_command(CLI::App& app);

/// A one-line progress bar on stderr, only when stderr is a terminal.
class ProgressBar {
public:
  ProgressBar();
  ~ProgressBar();
  void update(double fraction, int line);
  void finish();

private:
  bool tty_;
  int last_percent_ = -1;
};

}  // namespace cutsim::app
