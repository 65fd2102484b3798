#pragma once
// Interruption (SIGINT, SIGTERM): the signal handler only records the
// signal; long loops poll it and stop at the next move or leaf block.
#include <atomic>

namespace cutsim {

/// The signal number that asked us to stop, 0 while running.
std::atomic<int>& interrupt_signal();
inline bool interrupted() { return interrupt_signal().load(std::memory_order_relaxed) != 0; }

}  // namespace cutsim
