#include "cutsim/machine/machine.h"

#include <cmath>
#include <fstream>
#include <map>
#include <sstream>

#include "cutsim/config/toml_context.h"

#include "cutsim/core/error.h"

namespace cutsim::machine {

const std::map<std::string, std::string>& preset_texts();

Pose JointError::transform() const {
  Pose p = Pose::Identity();
  p.translation() = Vec3(dx, dy, dz);
  p.linear() = (Eigen::AngleAxisd(gamma, Vec3::UnitZ()) * Eigen::AngleAxisd(beta, Vec3::UnitY()) *
                Eigen::AngleAxisd(alpha, Vec3::UnitX())).toRotationMatrix();
  return p;
}

int Machine::joint_of(char axis) const {
  for (std::size_t i = 0; i < chain.size(); ++i)
    if (chain[i].axis == axis) return static_cast<int>(i);
  return -1;
}

bool Machine::has_rotary() const {
  for (const Joint& j : chain)
    if (j.type == JointType::rotary) return true;
  return false;
}

std::vector<std::string> preset_names() {
  std::vector<std::string> n;
  for (const auto& [k, v] : preset_texts()) n.push_back(k);
  return n;
}

namespace {

struct Ctx : config::TomlContext {
  JointError error(const toml::node& n, const std::string& where) const {
    const auto* t = n.as_table();
    if (!t) fail(n.source(), where + " must be a table {dx, dy, dz, alpha, beta, gamma}");
    only_keys(*t, {"dx", "dy", "dz", "alpha", "beta", "gamma"}, where);
    JointError e;
    if (auto* v = t->get("dx")) e.dx = number(*v, "dx");
    if (auto* v = t->get("dy")) e.dy = number(*v, "dy");
    if (auto* v = t->get("dz")) e.dz = number(*v, "dz");
    if (auto* v = t->get("alpha")) e.alpha = number(*v, "alpha");
    if (auto* v = t->get("beta")) e.beta = number(*v, "beta");
    if (auto* v = t->get("gamma")) e.gamma = number(*v, "gamma");
    return e;
  }
};

Machine parse_machine(const std::string& path, const std::string& text) {
  const Ctx ctx{{path, text}};
  const toml::table root = ctx.parse();
  ctx.only_keys(root, {"name", "description", "joint", "tool_setting", "workpiece_setting", "rapid_fraction"}, "the machine");
  Machine m;
  m.source = path;
  if (auto v = root["name"].value<std::string>()) m.name = *v;
  if (auto v = root["description"].value<std::string>()) m.description = *v;
  if (auto* v = root.get("rapid_fraction")) {
    m.rapid_fraction = ctx.number(*v, "rapid_fraction");
    if (!(m.rapid_fraction > 0 && m.rapid_fraction <= 1)) ctx.fail(v->source(), "rapid_fraction must be in (0, 1]");
  }
  const auto* joints = root["joint"].as_array();
  if (!joints || joints->empty()) throw ConfigError(SourceLocation{path, 1, 1, {}}, "a machine needs [[joint]] entries");
  for (const auto& node : *joints) {
    const auto* t = node.as_table();
    if (!t) ctx.fail(node.source(), "[[joint]] must be a table");
    ctx.only_keys(*t, {"axis", "type", "direction", "origin", "stroke", "max_velocity", "max_acceleration", "error", "laser"},
                  "[[joint]]");
    Joint j;
    const auto axis = (*t)["axis"].value<std::string>();
    if (!axis || axis->size() != 1 || std::string("XYZABC").find((*axis)[0]) == std::string::npos)
      ctx.fail(t->source(), "joint axis must be one of X Y Z A B C");
    j.axis = (*axis)[0];
    if (m.joint_of(j.axis) >= 0) ctx.fail(t->source(), std::string("axis ") + j.axis + " appears twice");
    const auto type = (*t)["type"].value<std::string>();
    if (!type || (*type != "linear" && *type != "rotary")) ctx.fail(t->source(), "joint type must be \"linear\" or \"rotary\"");
    j.type = *type == "linear" ? JointType::linear : JointType::rotary;
    const bool rot = j.type == JointType::rotary;
    const double unit = rot ? kPi / 180 : 1.0;  // degrees in the file, radians inside
    if (auto* v = t->get("direction")) {
      j.direction = ctx.vec3(*v, "direction");
      const double len = j.direction.norm();
      if (!(len > 1e-12) || !std::isfinite(len)) ctx.fail(v->source(), "direction must be a finite, non-zero vector");
      j.direction.normalize();
    } else {
      ctx.fail(t->source(), "joint needs a direction");
    }
    if (auto* v = t->get("origin")) j.origin = ctx.vec3(*v, "origin");
    if (auto* v = t->get("stroke")) {
      const auto* a = v->as_array();
      if (!a || a->size() != 2) ctx.fail(v->source(), "stroke must be [min, max]");
      j.stroke_min = ctx.number(*a->get(0), "stroke") * unit;
      j.stroke_max = ctx.number(*a->get(1), "stroke") * unit;
      if (!(j.stroke_min < j.stroke_max)) ctx.fail(v->source(), "stroke min must be below max");
    }
    if (auto* v = t->get("max_velocity")) j.max_velocity = ctx.number(*v, "max_velocity") * unit;
    if (auto* v = t->get("max_acceleration")) j.max_acceleration = ctx.number(*v, "max_acceleration") * unit;
    if (j.max_velocity < 0 || j.max_acceleration < 0) ctx.fail(t->source(), "limits must not be negative");
    if (auto* v = t->get("error")) j.error = ctx.error(*v, "error");
    if (auto* v = t->get("laser")) {
      const auto* lt = v->as_table();
      if (!lt) ctx.fail(v->source(), "laser must be a table {dead_path_mm, origin_mm}");
      ctx.only_keys(*lt, {"dead_path_mm", "origin_mm"}, "laser");
      if (rot) ctx.fail(v->source(), "a laser scale needs a linear axis");
      LaserScale ls;
      if (auto* d = lt->get("dead_path_mm")) ls.dead_path_mm = ctx.number(*d, "dead_path_mm");
      if (auto* o = lt->get("origin_mm")) ls.origin_mm = ctx.number(*o, "origin_mm");
      j.laser = ls;
    }
    m.chain.push_back(j);
  }
  for (const char* key : {"tool_setting", "workpiece_setting"})
    if (auto* v = root.get(key)) {
      const Pose p = ctx.error(*v, key).transform();
      (std::string(key) == "tool_setting" ? m.tool_setting : m.workpiece_setting) = p;
    }
  return m;
}

}  // namespace

Machine load_machine(const std::string& name_or_file) {
  const auto& presets = preset_texts();
  if (auto it = presets.find(name_or_file); it != presets.end()) {
    Machine m = parse_machine("preset:" + name_or_file, it->second);
    m.source = "preset";
    return m;
  }
  std::ifstream in(name_or_file, std::ios::binary);
  if (!in) {
    if (name_or_file.find('/') == std::string::npos && name_or_file.find(".toml") == std::string::npos) {
      std::string known;
      for (const auto& [k, v] : presets) known += (known.empty() ? "" : ", ") + k;
      throw ConfigError(SourceLocation{"--machine", 0, 0, {}},
                        "unknown machine '" + name_or_file + "' (presets: " + known + "; or a .toml file)");
    }
    throw InputError(name_or_file, "cannot open machine file");
  }
  std::stringstream buf;
  buf << in.rdbuf();
  return parse_machine(name_or_file, buf.str());
}

}  // namespace cutsim::machine
