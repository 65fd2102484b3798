#pragma once
// Test helpers: programs written to temporary files, the pipeline run on them.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>
#include <unistd.h>

#include "cutsim/sim/simulate.h"
#include "cutsim/io/job.h"
#include "cutsim/tool/tool.h"

namespace cutsim::test {

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

}  // namespace cutsim::test
