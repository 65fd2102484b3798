// libFuzzer target: the G-code reader (expressions, control flow) and the
// interpreter, in both dialects.
#include "fuzz_inputs.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  cutsim::fuzz::gcode_input(data, size);
  return 0;
}
