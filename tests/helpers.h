#pragma once
// Test helpers: programs written to temporary files, the pipeline run on them.
#include <gtest/gtest.h>

#include <cstdint>
#include <filesystem>
#include <map>
#include <fstream>
#include <string>
#include <vector>
#include <unistd.h>

#include <Eigen/Geometry>

#include "cutsim/sim/simulate.h"
#include "cutsim/io/job.h"
#include "cutsim/tool/tool.h"

namespace cutsim::test {

/// Every directed edge of `m`'s triangles (anything with `triangles` of
/// three indices) is matched by as many of its reverse: they close up,
/// consistently wound. (Edges four triangles share, where two sheets of a
/// level set's mesh touch, count as closed.)
template <class Mesh>
::testing::AssertionResult edges_matched(const Mesh& m) {
  std::map<std::pair<std::uint32_t, std::uint32_t>, int> count;
  for (const auto& t : m.triangles) {
    if (t[0] == t[1] || t[1] == t[2] || t[2] == t[0]) return ::testing::AssertionFailure() << "a degenerate triangle";
    for (std::size_t k = 0; k < 3; ++k) {
      const std::uint32_t a = t[k], b = t[(k + 1) % 3];
      if (a < b) ++count[{a, b}];
      else --count[{b, a}];
    }
  }
  for (const auto& [e, n] : count)
    if (n != 0) return ::testing::AssertionFailure() << "edge " << e.first << "-" << e.second << " is unmatched " << n << " times";
  return ::testing::AssertionSuccess();
}

/// A fresh directory under the system's temp folder, removed at scope end.
class TempDir {
public:
  TempDir() {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    std::string name = std::string("cutsim-") + (info ? std::string(info->test_suite_name()) + "-" + info->name() : "t");
    static int counter = 0;
    path_ = std::filesystem::temp_directory_path() / (name + "-" + std::to_string(::getpid()) + "-" + std::to_string(counter++));
    std::filesystem::remove_all(path_);
    std::filesystem::create_directories(path_);
  }
  ~TempDir() { std::error_code ec; std::filesystem::remove_all(path_, ec); }
  std::string file(const std::string& name) const { return (path_ / name).string(); }
  std::string write(const std::string& name, const std::string& text) const {
    std::ofstream(file(name), std::ios::binary) << text;
    return file(name);
  }
  const std::filesystem::path& path() const { return path_; }

private:
  std::filesystem::path path_;
};

inline sim::SimResult run_program(const TempDir& dir, const std::string& program, const std::string& tool_spec,
                                  const Aabb& stock, double voxel) {
  sim::SimOptions o;
  o.program = dir.write("prog.nc", program);
  o.tool = tool::parse_tool_spec(tool_spec);
  o.stock_box = stock;
  o.voxel_mm = voxel;
  return sim::simulate(o);
}

/// Runs the cutsim binary; returns the exit code, fills stdout and stderr.
int run_cli(const std::string& args, std::string* out = nullptr, std::string* err = nullptr);
/// Runs a whole command line (for wrappers such as timeout).
int run_cli_raw(const std::string& command, std::string* out = nullptr, std::string* err = nullptr);

inline std::string slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

/// Straight moves of V and nose tools for the profile prisms' tests, each
/// from the same start (prism_start): along the cutting direction, sheared
/// sideways, back along it, and on a tilted frame.
struct PrismMove {
  const char* spec;
  Vec3 move;
  Eigen::Matrix3d frame;
};
inline const Vec3 prism_start(0.01, -0.02, 0.03);
inline std::vector<PrismMove> prism_moves() {
  const Eigen::Matrix3d R = Eigen::AngleAxisd(0.5, Vec3(0.2, 1, 0.4).normalized()).toRotationMatrix();
  const Eigen::Matrix3d I = Eigen::Matrix3d::Identity();
  return {{"nose:r=0.5,angle=100", Vec3(0.3, 0.02, -0.01), I},
          {"nose:r=0.5,angle=100", Vec3(-0.2, -0.05, 0.04), I},
          {"nose:r=0.05,angle=60", Vec3(0.1, 0.03, 0.08), R},
          {"vtool:angle=90,h=0.05", Vec3(0.02, 0.005, -0.003), I},
          {"vtool:angle=60,h=0.05", Vec3(0.03, -0.01, 0.01), R}};
}

}  // namespace cutsim::test
