#include "cutsim/tool/tool.h"

#include <cmath>
#include <cstdlib>
#include <map>

#include "cutsim/core/error.h"

namespace cutsim::tool {

RevolvedEnvelope cutting_envelope(const Tool& t) {
  RevolvedEnvelope e;
  const double R = t.radius();
  const double rc = t.kind == ToolKind::ball ? R : t.kind == ToolKind::flat ? 0.0 : t.corner_radius_mm;
  e.corner_radius = rc;
  e.disk_radius = R - rc;
  e.core_offset = rc;
  e.core_length = std::max(t.flute_length_mm - rc, 0.0);
  return e;
}

Tool parse_tool_spec(const std::string& spec, const std::string& origin) {
  auto fail = [&](const std::string& msg) -> void {
    throw ConfigError(SourceLocation{origin, 0, 0, {}}, "tool '" + spec + "': " + msg);
  };
  const auto colon = spec.find(':');
  const std::string kind = spec.substr(0, colon);
  Tool t;
  t.name = spec;
  if (kind == "ball") t.kind = ToolKind::ball;
  else if (kind == "flat") t.kind = ToolKind::flat;
  else if (kind == "bull") t.kind = ToolKind::bull;
  else fail("unknown tool kind '" + kind + "' (known: ball, flat, bull)");

  std::map<std::string, double> kv;
  if (colon != std::string::npos) {
    std::string rest = spec.substr(colon + 1);
    std::size_t pos = 0;
    while (pos <= rest.size()) {
      const std::size_t comma = rest.find(',', pos);
      const std::string item = rest.substr(pos, comma == std::string::npos ? std::string::npos : comma - pos);
      const std::size_t eq = item.find('=');
      if (eq == std::string::npos) fail("expected key=value, got '" + item + "'");
      const std::string key = item.substr(0, eq);
      const std::string val = item.substr(eq + 1);
      char* endp = nullptr;
      const double v = std::strtod(val.c_str(), &endp);
      if (val.empty() || *endp != '\0' || !std::isfinite(v)) fail("value of '" + key + "' is not a number: '" + val + "'");
      if (key != "d" && key != "r" && key != "l") fail("unknown key '" + key + "' (known: d, r, l)");
      if (kv.count(key)) fail("key '" + key + "' given twice");
      kv[key] = v;
      if (comma == std::string::npos) break;
      pos = comma + 1;
    }
  }
  if (!kv.count("d")) fail("the diameter d is missing");
  t.diameter_mm = kv["d"];
  if (!(t.diameter_mm > 0)) fail("diameter must be positive");
  if (t.kind == ToolKind::bull) {
    if (!kv.count("r")) fail("a bull-nose tool needs its corner radius r");
    t.corner_radius_mm = kv["r"];
    if (!(t.corner_radius_mm > 0) || t.corner_radius_mm > t.radius())
      fail("corner radius must be in (0, d/2]");
  } else if (kv.count("r")) {
    fail("key 'r' applies only to bull-nose tools");
  }
  if (t.kind == ToolKind::ball) t.corner_radius_mm = t.radius();
  t.flute_length_mm = kv.count("l") ? kv["l"] : 2 * t.diameter_mm;
  if (!(t.flute_length_mm > 0)) fail("flute length must be positive");
  if (t.flute_length_mm < t.corner_radius_mm) fail("flute length is shorter than the corner radius");
  return t;
}

}  // namespace cutsim::tool
