// Replays every input the fuzzers found (tests/fuzz_regressions/<target>/)
// through the same code as the fuzz targets: each must end in a result or a
// cutsim::Error, never a crash or another exception.
#include <filesystem>

#include "../fuzz/fuzz_inputs.h"
#include "helpers.h"

namespace cutsim::test {
namespace {

namespace fs = std::filesystem;

std::size_t replay(const std::string& target, void (*run)(const std::uint8_t*, std::size_t)) {
  std::size_t n = 0;
  for (const auto& e : fs::directory_iterator(std::string(CUTSIM_SOURCE_DIR) + "/tests/fuzz_regressions/" + target)) {
    const std::string data = slurp(e.path().string());
    SCOPED_TRACE(e.path().string());
    EXPECT_NO_THROW(run(reinterpret_cast<const std::uint8_t*>(data.data()), data.size()));
    ++n;
  }
  return n;
}

TEST(FuzzRegressions, GcodeInputsEndInAnAnswer) { EXPECT_GE(replay("gcode", &fuzz::gcode_input), 4u); }
TEST(FuzzRegressions, JobInputsEndInAnAnswer) { EXPECT_GE(replay("job", &fuzz::job_input), 1u); }
TEST(FuzzRegressions, MachineInputsEndInAnAnswer) { EXPECT_GE(replay("machine", &fuzz::machine_input), 1u); }
TEST(FuzzRegressions, MeshInputsEndInAnAnswer) { EXPECT_GE(replay("mesh", &fuzz::mesh_input), 1u); }
TEST(FuzzRegressions, ToolLibraryInputsEndInAnAnswer) { EXPECT_GE(replay("tools", &fuzz::tools_input), 3u); }
TEST(FuzzRegressions, EnvironmentInputsEndInAnAnswer) { EXPECT_GE(replay("environment", &fuzz::environment_input), 1u); }

}  // namespace
}  // namespace cutsim::test
