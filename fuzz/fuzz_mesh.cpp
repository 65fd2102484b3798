// libFuzzer target: the target-mesh loaders (STL, OBJ, PLY, glb).
#include "fuzz_inputs.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  cutsim::fuzz::mesh_input(data, size);
  return 0;
}
