// libFuzzer target: the machine loader.
#include "fuzz_inputs.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  cutsim::fuzz::machine_input(data, size);
  return 0;
}
