// Conformance corpus: tests/conformance/*.nc against motion worked out by
// hand in the matching .expected file (JSON lines as `cutsim check --dump`
// prints them; '#' lines are the working). End points and arc centres must
// agree to 1e-9 mm, feeds to 1e-9 mm/min.
#include <filesystem>
#include <fstream>

#include <nlohmann/json.hpp>

#include "cutsim/sim/simulate.h"
#include "helpers.h"

namespace cutsim::test {
namespace {

namespace fs = std::filesystem;

std::vector<nlohmann::json> actual_motion(const std::string& program, gcode::Dialect d) {
  std::vector<nlohmann::json> out;
  sim::ProgramOptions popt;
  popt.dialect = d;
  sim::check_program(program, popt, motion::InterpreterOptions{}, [&](const motion::Move& m) {
    nlohmann::json j;
    j["line"] = m.line;
    j["motion"] = motion::motion_name(m.kind);
    j["end"] = {m.end.xyz.x(), m.end.xyz.y(), m.end.xyz.z(), rad_to_deg(m.end.abc.x()), rad_to_deg(m.end.abc.y()),
                rad_to_deg(m.end.abc.z())};
    if (m.is_arc()) j["centre"] = {m.centre.x(), m.centre.y(), m.centre.z()};
    j["feed_mm_per_min"] = m.feed_mm_per_min;
    out.push_back(j);
  });
  return out;
}

class Conformance : public ::testing::TestWithParam<std::string> {};

TEST_P(Conformance, MotionMatchesHandCalculation) {
  const std::string base = std::string(CUTSIM_SOURCE_DIR) + "/tests/conformance/" + GetParam();
  std::ifstream in(base + ".expected");
  ASSERT_TRUE(in) << base;
  std::vector<nlohmann::json> expected;
  gcode::Dialect dialect = gcode::Dialect::rs274ngc;
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("# dialect: fanuc", 0) == 0) dialect = gcode::Dialect::fanuc;
    if (line.empty() || line[0] == '#') continue;
    expected.push_back(nlohmann::json::parse(line));
  }
  const auto actual = actual_motion(base + ".nc", dialect);
  ASSERT_EQ(actual.size(), expected.size());
  for (std::size_t i = 0; i < actual.size(); ++i) {
    const auto& a = actual[i];
    const auto& e = expected[i];
    SCOPED_TRACE("move " + std::to_string(i) + " expected " + e.dump() + " got " + a.dump());
    EXPECT_EQ(a["line"], e["line"]);
    EXPECT_EQ(a["motion"], e["motion"]);
    for (int k = 0; k < 6; ++k) EXPECT_NEAR(a["end"][k].get<double>(), e["end"][k].get<double>(), 1e-9);
    EXPECT_EQ(a.contains("centre"), e.contains("centre"));
    if (a.contains("centre") && e.contains("centre")) {
      for (int k = 0; k < 3; ++k) EXPECT_NEAR(a["centre"][k].get<double>(), e["centre"][k].get<double>(), 1e-9);
    }
    EXPECT_NEAR(a["feed_mm_per_min"].get<double>(), e["feed_mm_per_min"].get<double>(), 1e-9);
  }
}

INSTANTIATE_TEST_SUITE_P(Corpus, Conformance,
                         ::testing::Values("arcs_g17", "arcs_g18_g19", "incremental_units", "offsets", "parameters",
                                           "control_flow", "sub_forward", "feed_modes", "fanuc_basic", "fanuc_tilt"));

}  // namespace
}  // namespace cutsim::test
