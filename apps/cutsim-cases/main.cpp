// cutsim-cases: writes the reference cases of CASES.md (target models, NC
// programs, jobs, logs) under a project root. The same bytes every run; a
// file whose bytes are already there is left alone, so builds stay quiet.
#include <CLI/CLI.hpp>

#include <filesystem>
#include <fstream>
#include <iostream>
#include <sstream>

#include "cutsim/cases/cases.h"
#include "cutsim/core/error.h"
#include "cutsim/io/atomic_file.h"

namespace fs = std::filesystem;
using namespace cutsim;

namespace {

bool same_bytes(const fs::path& p, const std::string& bytes) {
  std::error_code ec;
  if (fs::file_size(p, ec) != bytes.size() || ec) return false;
  std::ifstream in(p, std::ios::binary);
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str() == bytes;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"cutsim-cases: write the reference cases (models/, ncprograms/) under a project root"};
  std::string root = ".";
  std::vector<std::string> names;
  bool list = false, committed_only = false, check = false;
  app.add_option("cases", names, "cases to write (default: all)");
  app.add_option("--root", root, "project root (default: .)");
  app.add_flag("--list", list, "list the cases and their files");
  app.add_flag("--committed", committed_only, "only the files kept in git");
  app.add_flag("--check", check, "write nothing; exit 1 when a file differs from what would be written");
  CLI11_PARSE(app, argc, argv);
  try {
    std::vector<const cases::Case*> todo;
    if (names.empty())
      for (const auto& c : cases::all_cases()) todo.push_back(&c);
    else
      for (const auto& n : names) todo.push_back(&cases::find_case(n));
    int differing = 0;
    for (const cases::Case* c : todo) {
      if (list) {
        std::cout << c->name << ": " << c->summary << "\n";
        continue;
      }
      for (const cases::File& f : c->generate()) {
        if (committed_only && !f.committed) continue;
        const fs::path p = fs::path(root) / f.path;
        if (same_bytes(p, f.bytes)) continue;
        if (check) {
          std::cerr << p.string() << ": differs from what cutsim-cases writes\n";
          ++differing;
          continue;
        }
        fs::create_directories(p.parent_path());
        io::write_file_atomic(p.string(), f.bytes);
        std::cout << "wrote " << p.string() << " (" << f.bytes.size() << " bytes)\n";
      }
    }
    return differing ? 1 : 0;
  } catch (const Error& e) {
    std::cerr << e.format() << "\n";
    return static_cast<int>(e.code());
  } catch (const std::exception& e) {
    std::cerr << "cutsim-cases: error: " << e.what() << "\n";
    return 70;
  }
}
