#pragma once
// Tool libraries: tools by T number, from a TOML file or a LinuxCNC tool
// table (.tbl, end mills only).
#include <istream>
#include <map>
#include <string>

#include "cutsim/tool/tool.h"

namespace cutsim::io {

struct ToolLibrary {
  std::string source;                 ///< file it came from
  std::map<int, tool::Tool> tools;    ///< by T number
  /// The tool numbered `t`, or nullptr.
  const tool::Tool* find(int t) const {
    const auto it = tools.find(t);
    return it == tools.end() ? nullptr : &it->second;
  }
};

/// Reads `[[tool]]` tables: `number`, `kind` and the sizes by their long
/// names (diameter, corner_radius, nose_radius, flute_length, ...), or
/// `number` and `spec = "ball:d=1"`. See the README for every key.
/// @throw ConfigError at file:line:col for anything malformed or out of range.
ToolLibrary parse_tool_library_toml(const std::string& text, const std::string& path);

/// Reads a LinuxCNC tool table: `T<n> P<pocket> D<diameter> Z<offset> ;comment`.
/// The comment names the kind ("ball", "bull"; otherwise flat) and may give
/// sizes as `r=0.2 l=3 shank_d=6 ...`.
/// @throw ParseError at file:line:col for a malformed word, a missing T or D,
///        or a T number given twice.
ToolLibrary parse_linuxcnc_tbl(std::istream& in, const std::string& path);

/// Loads a library by extension: `.tbl` as a LinuxCNC table, anything else
/// as TOML. @throw InputError when the file cannot be read.
ToolLibrary load_tool_library(const std::string& path);

}  // namespace cutsim::io
