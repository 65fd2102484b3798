// libFuzzer target: the job file (TOML) loader and tool specs.
#include "fuzz_inputs.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  cutsim::fuzz::job_input(data, size);
  return 0;
}
