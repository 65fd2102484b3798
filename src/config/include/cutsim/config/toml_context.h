#pragma once
// Reading TOML files with errors at file:line:col (the source line and a
// caret). For the loaders' .cpp files only: it brings toml++ in.
#include <cmath>
#include <initializer_list>
#include <sstream>
#include <string>

#include <toml++/toml.h>

#include "cutsim/core/error.h"
#include "cutsim/core/geometry.h"

namespace cutsim::config {

struct TomlContext {
  std::string path;  ///< for messages
  std::string text;  ///< the file's text, for the source line under an error

  /// Parses `text`. @throw ConfigError at the syntax error.
  toml::table parse() const {
    try {
      return toml::parse(text, path);
    } catch (const toml::parse_error& e) {
      fail(e.source(), std::string(e.description()));
    }
  }
  [[noreturn]] void fail(const toml::source_region& r, const std::string& msg) const {
    const int line = static_cast<int>(r.begin.line), col = static_cast<int>(r.begin.column);
    throw ConfigError(SourceLocation{path, line, col, line_of(line)}, msg);
  }
  /// @throw ConfigError at the first key of `t` not in `keys`.
  void only_keys(const toml::table& t, std::initializer_list<const char*> keys, const std::string& where) const {
    for (const auto& [k, v] : t) {
      bool ok = false;
      for (const char* kk : keys) ok |= (k.str() == kk);
      if (!ok) fail(k.source(), "unknown key '" + std::string(k.str()) + "' in " + where);
    }
  }
  double number(const toml::node& n, const std::string& what) const {
    if (auto v = n.value<double>(); v && std::isfinite(*v)) return *v;
    fail(n.source(), what + " must be a finite number");
  }
  Vec3 vec3(const toml::node& n, const std::string& what) const {
    const auto* a = n.as_array();
    if (!a || a->size() != 3) fail(n.source(), what + " must be an array of 3 numbers");
    return Vec3(number(*a->get(0), what), number(*a->get(1), what), number(*a->get(2), what));
  }

private:
  std::string line_of(int line) const {
    std::istringstream is(text);
    std::string s;
    for (int i = 0; i < line && std::getline(is, s); ++i) {}
    return s;
  }
};

}  // namespace cutsim::config
