#pragma once
#include <CLI/CLI.hpp>
#include <cstdlib>
#include <functional>
#include <string>

namespace cutsim::app {

/// Number checks with a plain message (CLI11's own name the range up to
/// the largest double).
inline CLI::Validator number_check(bool zero_ok) {
  return CLI::Validator(
      [zero_ok](std::string& s) -> std::string {
        char* end = nullptr;
        const double v = std::strtod(s.c_str(), &end);
        if (end == s.c_str() || *end != '\0' || !(v == v)) return "'" + s + "' is not a number";
        if (zero_ok ? v < 0 : v <= 0) return "'" + s + "' must be " + (zero_ok ? "zero or more" : "more than zero");
        return {};
      },
      zero_ok ? "NONNEGATIVE" : "POSITIVE");
}
inline const CLI::Validator kPositive = number_check(false);
inline const CLI::Validator kNonNegative = number_check(true);

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
