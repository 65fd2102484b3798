// cutsim: a cutting simulator for ultra-precision machining.
#include <atomic>
#include <csignal>
#include <ctime>
#include <cstdio>
#include <iostream>

#include "cutsim/core/huge_pages.h"
#include "cutsim/core/interrupt.h"

#include "commands.h"
#include "cutsim/core/error.h"

namespace {
// Records the first signal; one that comes later kills as usual. Within
// half a second of the first, a signal counts as the same one: `timeout`
// (and other supervisors) signal both the child and its process group, so
// one stop arrives twice, and on a busy machine the first may be handled
// before the second is sent. (Only async-signal-safe calls here.)
std::atomic<long long> g_first_signal_ns{0};
void on_signal(int sig) {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  const long long now = static_cast<long long>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
  if (cutsim::interrupt_signal().load() == 0) {
    g_first_signal_ns.store(now);
    cutsim::interrupt_signal().store(sig);
    return;
  }
  if (now - g_first_signal_ns.load() < 500'000'000) return;
  std::signal(sig, SIG_DFL);
  std::raise(sig);
}
void install_handlers() {
  struct sigaction sa {};
  sa.sa_handler = on_signal;
  sigemptyset(&sa.sa_mask);
  sa.sa_flags = 0;
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
}
}  // namespace

int main(int argc, char** argv) {
  // First, before any output: with huge pages asked for, this returns only
  // in the program started again (CUTSIM_HUGE_PAGES=0: not at all).
  cutsim::reexec_with_huge_pages(argv);
  cutsim::keep_freed_memory();
  install_handlers();
  CLI::App app{"cutsim: simulate an NC program's cuts in a voxel stock"};
  app.require_subcommand(1);
  app.set_version_flag("--version", "cutsim 0.1.0");
  cutsim::app::Action run = cutsim::app::add_run_command(app);
  cutsim::app::Action check = cutsim::app::add_check_command(app);
  cutsim::app::Action compare = cutsim::app::add_compare_command(app);
  cutsim::app::Action bench = cutsim::app::add_bench_command(app);
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForVersion& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    std::cerr << "cutsim: error: " << e.what() << "\n" << "run 'cutsim --help' for usage\n";
    return static_cast<int>(cutsim::ExitCode::usage);
  }
  try {
    if (app.got_subcommand("run")) return run();
    if (app.got_subcommand("check")) return check();
    if (app.got_subcommand("compare")) return compare();
    if (app.got_subcommand("bench")) return bench();
  } catch (const cutsim::InterruptedError& e) {
    std::cout.flush();
    std::cerr << e.format() << "\nno output written\n";
    return e.exit_status();
  } catch (const cutsim::Error& e) {
    std::cout.flush();
    std::cerr << e.format() << "\n";
    return static_cast<int>(e.code());
  } catch (const std::bad_alloc&) {
    std::cerr << "cutsim: error: out of memory (try a coarser --voxel)\n";
    return static_cast<int>(cutsim::ExitCode::software);
  } catch (const std::exception& e) {
    std::cerr << "cutsim: internal error: " << e.what() << "\n";
    return static_cast<int>(cutsim::ExitCode::software);
  }
  return static_cast<int>(cutsim::ExitCode::usage);
}
