// libFuzzer target: tool libraries (TOML and LinuxCNC .tbl).
#include "fuzz_inputs.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  cutsim::fuzz::tools_input(data, size);
  return 0;
}
