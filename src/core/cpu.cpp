#include "cutsim/core/cpu.h"

#include <cstdlib>
#include <cstring>

namespace cutsim {

bool cpu_has_avx2() {
#if defined(__x86_64__)
  static const bool has = __builtin_cpu_supports("avx2");
  return has;
#else
  return false;
#endif
}

bool use_avx2() {
  static const bool on = cpu_has_avx2() && !(std::getenv("CUTSIM_AVX2") && std::strcmp(std::getenv("CUTSIM_AVX2"), "0") == 0);
  return on;
}

}  // namespace cutsim
