#include "cutsim/io/tool_library.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <optional>
#include <cstring>
#include <sstream>
#include <vector>

#include "cutsim/config/toml_context.h"
#include "cutsim/core/error.h"

namespace cutsim::io {

namespace {

// TOML's long key names and the spec's short ones.
const std::vector<std::pair<const char*, const char*>> kLongKeys = {
    {"diameter", "d"},          {"corner_radius", "r"},   {"nose_radius", "r"},
    {"flute_length", "l"},      {"neck_diameter", "neck_d"}, {"neck_length", "neck_l"},
    {"shank_diameter", "shank_d"}, {"shank_length", "shank_l"}, {"holder_diameter", "holder_d"},
    {"holder_length", "holder_l"}, {"swing_radius", "swing"}, {"included_angle", "angle"},
    {"rake_angle", "rake"},     {"clearance_angle", "clearance"}, {"orientation", "orient"},
    {"edge_height", "h"},       {"body_length", "body"},
};

const char* short_key(std::string_view k) {
  for (const auto& [l, s] : kLongKeys)
    if (k == l) return s;
  return nullptr;
}

}  // namespace

ToolLibrary parse_tool_library_toml(const std::string& text, const std::string& path) {
  const config::TomlContext ctx{path, text};
  const toml::table root = ctx.parse();
  ctx.only_keys(root, {"tool"}, "a tool library (it holds [[tool]] tables)");
  ToolLibrary lib;
  lib.source = path;
  const toml::array* arr = root["tool"].as_array();
  if (!arr) {
    if (root.contains("tool")) ctx.fail(root.get("tool")->source(), "'tool' must be an array of tables: [[tool]]");
    ctx.fail(toml::source_region{{1, 1}, {1, 1}, {}}, "the library holds no [[tool]] tables");
  }
  for (const toml::node& n : *arr) {
    const toml::table* t = n.as_table();
    if (!t) ctx.fail(n.source(), "each tool must be a table: [[tool]]");
    const toml::node* num = t->get("number");
    if (!num) ctx.fail(t->source(), "this tool has no 'number' (its T number)");
    // Integers only: toml++'s float-to-integer conversion casts out-of-range
    // values unchecked (UB found by fuzzing with `number = 1e21`).
    const auto nv = num->is_integer() ? num->value<int64_t>() : std::nullopt;
    if (!nv || *nv < 1 || *nv > 99999) ctx.fail(num->source(), "'number' must be an integer T number from 1 to 99999");
    const int number = static_cast<int>(*nv);
    if (lib.tools.count(number)) ctx.fail(num->source(), "T" + std::to_string(number) + " is defined twice");
    tool::Tool tl;
    if (const toml::node* spec = t->get("spec")) {
      ctx.only_keys(*t, {"number", "spec", "name"}, "a [[tool]] with a spec");
      const auto sv = spec->value<std::string>();
      if (!sv) ctx.fail(spec->source(), "'spec' must be a string such as \"ball:d=1\"");
      try {
        tl = tool::parse_tool_spec(*sv, path);
      } catch (const ConfigError& e) {
        ctx.fail(spec->source(), e.message());
      }
    } else {
      const toml::node* kind = t->get("kind");
      if (!kind) ctx.fail(t->source(), "T" + std::to_string(number) + " has neither 'kind' nor 'spec'");
      const auto kv = kind->value<std::string>();
      if (!kv) ctx.fail(kind->source(), "'kind' must be a string (ball, flat, bull, flycutter, nose, vtool)");
      std::map<std::string, double> keys;
      for (const auto& [k, v] : *t) {
        if (k.str() == "number" || k.str() == "kind" || k.str() == "name") continue;
        const char* sk = short_key(k.str());
        if (!sk) ctx.fail(k.source(), "unknown key '" + std::string(k.str()) + "' in a [[tool]]");
        if (keys.count(sk)) ctx.fail(k.source(), "'" + std::string(k.str()) + "' repeats a size given already");
        keys[sk] = ctx.number(v, std::string(k.str()));
      }
      try {
        tl = tool::make_tool(*kv, keys, "T" + std::to_string(number), path);
      } catch (const ConfigError& e) {
        ctx.fail(kind->source(), e.message());
      }
    }
    if (const toml::node* name = t->get("name")) {
      const auto s = name->value<std::string>();
      if (!s) ctx.fail(name->source(), "'name' must be a string");
      tl.name = *s;
    }
    tl.number = number;
    lib.tools.emplace(number, tl);
  }
  return lib;
}

ToolLibrary parse_linuxcnc_tbl(std::istream& in, const std::string& path) {
  ToolLibrary lib;
  lib.source = path;
  std::string line;
  int lineno = 0;
  while (std::getline(in, line)) {
    ++lineno;
    if (line.size() > 4096) throw ParseError(SourceLocation{path, lineno, 1, {}}, "line longer than 4096 characters");
    if (!line.empty() && line.back() == '\r') line.pop_back();
    auto fail = [&](std::size_t col, const std::string& msg) -> void {
      throw ParseError(SourceLocation{path, lineno, static_cast<int>(col) + 1, line}, msg);
    };
    const std::size_t semi = line.find(';');
    const std::string body = line.substr(0, semi);
    const std::string comment = semi == std::string::npos ? std::string() : line.substr(semi + 1);
    std::optional<int> T;
    std::optional<double> D;
    std::size_t t_col = 0;
    std::size_t i = 0;
    while (i < body.size()) {
      if (std::isspace(static_cast<unsigned char>(body[i]))) { ++i; continue; }
      const std::size_t col = i;
      const char letter = static_cast<char>(std::toupper(static_cast<unsigned char>(body[i])));
      if (!std::strchr("TPXYZABCUVWDIJQ", letter) || letter == '\0')
        fail(col, std::string("unexpected '") + body[i] + "' (tool table words are T P X Y Z A B C U V W D I J Q)");
      ++i;
      std::size_t j = i;
      while (j < body.size() && !std::isspace(static_cast<unsigned char>(body[j]))) ++j;
      const std::string num = body.substr(i, j - i);
      char* end = nullptr;
      const double v = std::strtod(num.c_str(), &end);
      if (num.empty() || *end != '\0' || !std::isfinite(v))
        fail(i, std::string("the ") + letter + " word needs a number, got '" + num + "'");
      if (letter == 'T') {
        if (T) fail(col, "T given twice on one line");
        if (v != std::floor(v) || v < 1 || v > 99999) fail(i, "T must be an integer from 1 to 99999");
        T = static_cast<int>(v);
        t_col = col;
      } else if (letter == 'D') {
        if (D) fail(col, "D given twice on one line");
        if (!(v > 0)) fail(i, "the diameter D must be positive");
        D = v;
      }
      i = j;
    }
    if (!T && !D) continue;  // blank or comment-only line
    if (!T) fail(0, "a tool table line needs a T number");
    if (!D) fail(body.size(), "T" + std::to_string(*T) + " has no diameter (D word)");
    if (lib.tools.count(*T)) fail(t_col, "T" + std::to_string(*T) + " is defined twice");
    // The comment: the kind and optional sizes as key=value.
    std::string lower = comment;
    std::transform(lower.begin(), lower.end(), lower.begin(), [](unsigned char c) { return std::tolower(c); });
    std::map<std::string, double> keys;
    keys["d"] = *D;
    std::istringstream words(lower);
    std::string w;
    bool bull = false, ball = false;
    while (words >> w) {
      ball |= w.find("ball") != std::string::npos;
      bull |= w.find("bull") != std::string::npos;
      const auto eq = w.find('=');
      if (eq == std::string::npos) continue;
      const std::string k = w.substr(0, eq), val = w.substr(eq + 1);
      static const char* sizes[] = {"r", "l", "neck_d", "neck_l", "shank_d", "shank_l", "holder_d", "holder_l"};
      if (std::find_if(std::begin(sizes), std::end(sizes), [&](const char* s) { return k == s; }) == std::end(sizes))
        continue;
      char* end = nullptr;
      const double v = std::strtod(val.c_str(), &end);
      if (val.empty() || *end != '\0' || !std::isfinite(v))
        fail(semi + 1 + comment.find(k + "="), "'" + k + "=' in the comment needs a number");
      keys[k] = v;
    }
    const std::string kind = bull || (!ball && keys.count("r")) ? "bull" : ball ? "ball" : "flat";
    tool::Tool t;
    try {
      t = tool::make_tool(kind, keys, "T" + std::to_string(*T), path);
    } catch (const ConfigError& e) {
      throw ParseError(SourceLocation{path, lineno, static_cast<int>(t_col) + 1, line}, e.message());
    }
    t.number = *T;
    std::string name = comment;
    name.erase(0, name.find_first_not_of(" \t"));
    if (!name.empty()) t.name = name;
    lib.tools.emplace(*T, t);
  }
  if (lib.tools.empty()) throw ParseError(SourceLocation{path, 0, 0, {}}, "the tool table holds no tools");
  return lib;
}

ToolLibrary load_tool_library(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path, "cannot open tool library: " + std::string(std::strerror(errno)));
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
  if (ext == ".tbl") return parse_linuxcnc_tbl(in, path);
  std::stringstream buf;
  buf << in.rdbuf();
  return parse_tool_library_toml(buf.str(), path);
}

}  // namespace cutsim::io
