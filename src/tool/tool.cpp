#include "cutsim/tool/tool.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <cstdlib>
#include <set>

#include "cutsim/core/error.h"

namespace cutsim::tool {

const char* kind_name(ToolKind k) {
  switch (k) {
    case ToolKind::ball: return "ball";
    case ToolKind::flat: return "flat";
    case ToolKind::bull: return "bull";
    case ToolKind::flycutter: return "flycutter";
    case ToolKind::nose: return "nose";
    case ToolKind::vtool: return "vtool";
  }
  return "?";
}

double Tool::radius() const {
  switch (kind) {
    case ToolKind::flycutter: return swing_radius_mm;
    case ToolKind::nose:
    case ToolKind::vtool: {
      const double b = deg_to_rad(included_angle_deg) / 2, r = corner_radius_mm;
      return edge_height_mm > r ? (edge_height_mm - r) * std::tan(b) + r / std::cos(b) : r;
    }
    default: return diameter_mm / 2;
  }
}

RevolvedEnvelope cutting_envelope(const Tool& t) {
  RevolvedEnvelope e;
  const double R = t.diameter_mm / 2;
  const double rc = t.kind == ToolKind::ball ? R : t.kind == ToolKind::flat ? 0.0 : t.corner_radius_mm;
  e.corner_radius = rc;
  e.disk_radius = R - rc;
  e.core_offset = rc;
  e.core_length = std::max(t.flute_length_mm - rc, 0.0);
  return e;
}

namespace {

double prism_sd(double a, double b) {
  const double ao = std::max(a, 0.0), bo = std::max(b, 0.0);
  return std::sqrt(ao * ao + bo * bo) + std::min(std::max(a, b), 0.0);
}

// Half the width of the edge profile at height z above the tip.
double profile_half_width(const EdgeProfile& e, double z) {
  const double r = e.nose_radius;
  if (z <= r * (1 - std::sin(e.half_angle))) return std::sqrt(std::max(0.0, r * r - (r - z) * (r - z)));
  return (z - r) * std::tan(e.half_angle) + r / std::cos(e.half_angle);
}

// Box of a box given in the cutting frame [x0,x1] x [y0,y1] x [z0,z1],
// turned about Z into the tool frame.
Aabb turned_box(const EdgeProfile& e, double x0, double x1, double y0, double y1, double z0, double z1) {
  Aabb b;
  for (double x : {x0, x1})
    for (double y : {y0, y1})
      for (double z : {z0, z1}) b.extend(Vec3(e.cos_o * x - e.sin_o * y, e.sin_o * x + e.cos_o * y, z));
  return b;
}

// sin and cos of a tool angle, remembered per thread: the distance
// functions are called millions of times with the same few angles.
struct SinCos {
  double s, c;
};
SinCos sin_cos(double a) {
  constexpr int kN = 4;  // a flank body uses three angles
  thread_local double last_a[kN] = {std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::quiet_NaN(),
                                    std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::quiet_NaN()};
  thread_local SinCos last[kN];
  thread_local int next = 0;
  for (int i = 0; i < kN; ++i)
    if (last_a[i] == a) return last[i];
  next = (next + 1) % kN;
  last_a[next] = a;
  last[next] = {std::sin(a), std::cos(a)};
  return last[next];
}

struct Visit {
  const Vec3& p;
  double operator()(const RevolvedEnvelope& e) const {
    const double a = hypot2(p.x(), p.y()) - e.disk_radius;
    const double b = std::max(e.core_offset - p.z(), p.z() - e.core_offset - e.core_length);
    return prism_sd(a, b) - e.corner_radius;
  }
  double operator()(const EdgeProfile& e) const {
    const double xc = e.cos_o * p.x() + e.sin_o * p.y();
    const double yc = -e.sin_o * p.x() + e.cos_o * p.y();
    const double a = std::max(profile_distance_2d(e, yc, p.z()), p.z() - e.height);
    return hypot2(xc, std::max(a, 0.0));
  }
  double operator()(const FlankBody& f) const {
    const SinCos h = sin_cos(f.edge.half_angle), cl = sin_cos(f.clearance), rk = sin_cos(f.rake);
    return flank_distance(f, FlankTrig{h.s, h.c, cl.s, cl.c, rk.s, rk.c}, p);
  }
  double operator()(const SwingTorus& t) const {
    return torus_at(t, p.x(), p.y(), p.z()).D - t.nose_radius;
  }
};

}  // namespace

FlankTrig flank_trig(const FlankBody& f) {
  return {std::sin(f.edge.half_angle), std::cos(f.edge.half_angle), std::sin(f.clearance),
          std::cos(f.clearance),       std::sin(f.rake),            std::cos(f.rake)};
}

double profile_distance_2d(const EdgeProfile& e, double y, double z, double* gy, double* gz) {
  const SinCos h = sin_cos(e.half_angle);
  return profile_distance_2d(e, h.s, h.c, y, z, gy, gz);
}

double shape_distance(const Shape& s, const Vec3& p) { return std::visit(Visit{p}, s); }

Aabb shape_bounds(const Shape& s) {
  return std::visit([](const auto& q) -> Aabb {
    using T = std::decay_t<decltype(q)>;
    if constexpr (std::is_same_v<T, RevolvedEnvelope>) {
      const double R = q.disk_radius + q.corner_radius;
      return Aabb{Vec3(-R, -R, q.core_offset - q.corner_radius),
                  Vec3(R, R, q.core_offset + q.core_length + q.corner_radius)};
    } else if constexpr (std::is_same_v<T, EdgeProfile>) {
      const double w = profile_half_width(q, q.height);
      return turned_box(q, 0, 0, -w, w, 0, q.height);
    } else if constexpr (std::is_same_v<T, FlankBody>) {
      const double w = profile_half_width(q.edge, q.edge.height);
      const double front = std::max(0.0, -q.edge.height * std::tan(q.rake));
      return turned_box(q.edge, -q.length, front, -w, w, 0, q.edge.height);
    } else {
      return Aabb{Vec3(-q.swing, -q.nose_radius, 0), Vec3(q.swing, q.nose_radius, 2 * q.swing)};
    }
  }, s);
}

Aabb shape_bounds_below(const Shape& s, double top) {
  if (const auto* e = std::get_if<EdgeProfile>(&s); e && top < e->height) {
    EdgeProfile low = *e;
    low.height = std::max(top, 0.0);
    return shape_bounds(low);
  }
  if (const auto* f = std::get_if<FlankBody>(&s); f && top < f->edge.height) {
    FlankBody low = *f;
    low.edge.height = std::max(top, 0.0);
    return shape_bounds(low);
  }
  if (const auto* t = std::get_if<SwingTorus>(&s); t && top < 2 * t->swing) {
    // A point of the torus at height z <= top lies within the tip circle
    // (hypot(x, z - swing) <= swing), so x^2 <= 2 swing z - z^2; and its
    // distance from the axis is at least swing - z, so where z <= nose
    // radius its tube offset is at least nose radius - z: y^2 <= 2 r z - z^2.
    // Both grow with z up to swing and r. A fly-cut 3 um deep reaches some
    // 50 um into the stock's reach: its box is then 0.5 mm across Y, not 4.
    const double z = std::max(top, 0.0);
    const double zx = std::min(z, t->swing), zy = std::min(z, t->nose_radius);
    const double hx = std::sqrt(std::max(2 * t->swing * zx - zx * zx, 0.0));
    const double hy = std::sqrt(std::max(2 * t->nose_radius * zy - zy * zy, 0.0));
    return Aabb{Vec3(-hx, -hy, 0), Vec3(hx, hy, z)};
  }
  return shape_bounds(s);
}

namespace {
EdgeProfile edge_of(const Tool& t) {
  EdgeProfile e;
  e.nose_radius = t.corner_radius_mm;
  e.half_angle = deg_to_rad(t.included_angle_deg) / 2;
  e.height = t.edge_height_mm;
  e.cos_o = std::cos(deg_to_rad(t.orientation_deg));
  e.sin_o = std::sin(deg_to_rad(t.orientation_deg));
  return e;
}
}  // namespace

Shape cutting_shape(const Tool& t) {
  switch (t.kind) {
    case ToolKind::flycutter: return SwingTorus{t.swing_radius_mm, t.corner_radius_mm};
    case ToolKind::nose:
    case ToolKind::vtool: return edge_of(t);
    default: return cutting_envelope(t);
  }
}

std::vector<Region> contact_regions(const Tool& t) {
  std::vector<Region> out;
  switch (t.kind) {
    case ToolKind::flycutter: {
      // About the spindle axis (tool +Y) through (0, 0, swing): the
      // flywheel (holder) centred on the swing plane, the arbor (shank)
      // behind it along +Y.
      Pose f = Pose::Identity();
      f.linear() = Eigen::AngleAxisd(-kPi / 2, Vec3::UnitX()).toRotationMatrix();  // local +Z -> tool +Y
      f.translation() = Vec3(0, 0, t.swing_radius_mm);
      if (t.holder_length_mm > 0)
        out.push_back({"holder", RevolvedEnvelope{t.holder_diameter_mm / 2, 0, t.holder_length_mm, -t.holder_length_mm / 2}, f});
      if (t.shank_length_mm > 0)
        out.push_back({"shank", RevolvedEnvelope{t.shank_diameter_mm / 2, 0, t.shank_length_mm, t.holder_length_mm / 2}, f});
      break;
    }
    case ToolKind::nose:
    case ToolKind::vtool:
      out.push_back({"clearance-face", FlankBody{edge_of(t), deg_to_rad(t.clearance_angle_deg),
                                                 deg_to_rad(t.rake_angle_deg), t.body_length_mm}});
      break;
    default: {
      double z = t.flute_length_mm;
      if (t.neck_length_mm > 0) {
        out.push_back({"neck", RevolvedEnvelope{t.neck_diameter_mm / 2, 0, t.neck_length_mm, z}});
        z += t.neck_length_mm;
      }
      out.push_back({"shank", RevolvedEnvelope{t.shank_diameter_mm / 2, 0, t.shank_length_mm, z}});
      z += t.shank_length_mm;
      if (t.holder_length_mm > 0)
        out.push_back({"holder", RevolvedEnvelope{t.holder_diameter_mm / 2, 0, t.holder_length_mm, z}});
    }
  }
  return out;
}

Tool make_tool(const std::string& kind, const std::map<std::string, double>& kv, const std::string& what,
               const std::string& origin) {
  auto fail = [&](const std::string& msg) -> void {
    throw ConfigError(SourceLocation{origin, 0, 0, {}}, "tool '" + what + "': " + msg);
  };
  Tool t;
  t.name = what;
  std::set<std::string> known;
  if (kind == "ball" || kind == "flat" || kind == "bull") {
    t.kind = kind == "ball" ? ToolKind::ball : kind == "flat" ? ToolKind::flat : ToolKind::bull;
    known = {"d", "l", "neck_d", "neck_l", "shank_d", "shank_l", "holder_d", "holder_l"};
    if (t.kind == ToolKind::bull) known.insert("r");
  } else if (kind == "flycutter") {
    t.kind = ToolKind::flycutter;
    known = {"swing", "r", "shank_d", "shank_l", "holder_d", "holder_l"};
  } else if (kind == "nose" || kind == "vtool") {
    t.kind = kind == "nose" ? ToolKind::nose : ToolKind::vtool;
    known = {"angle", "rake", "clearance", "orient", "h", "body"};
    if (t.kind == ToolKind::nose) known.insert("r");
  } else {
    fail("unknown tool kind '" + kind + "' (known: ball, flat, bull, flycutter, nose, vtool)");
  }
  for (const auto& [k, v] : kv) {
    if (!known.count(k)) {
      std::string list;
      for (const auto& n : known) list += (list.empty() ? "" : ", ") + n;
      fail("unknown key '" + k + "' for a " + kind + " tool (known: " + list + ")");
    }
    if (!std::isfinite(v)) fail("value of '" + k + "' is not a finite number");
  }
  auto get = [&](const char* k, double def) {
    const auto it = kv.find(k);
    return it == kv.end() ? def : it->second;
  };
  auto need = [&](const char* k, const std::string& what_it_is) {
    if (!kv.count(k)) fail(what_it_is + " (" + k + ") is missing");
    return kv.at(k);
  };
  auto positive = [&](double v, const std::string& name) {
    if (!(v > 0)) fail(name + " must be positive");
  };

  if (!t.rotating()) {
    t.included_angle_deg = get("angle", t.kind == ToolKind::vtool ? 90.0 : 100.0);
    t.rake_angle_deg = get("rake", 0.0);
    t.clearance_angle_deg = get("clearance", 7.0);
    t.orientation_deg = get("orient", 0.0);
    t.corner_radius_mm = t.kind == ToolKind::nose ? need("r", "the nose radius") : 0.0;
    t.edge_height_mm = get("h", std::max(0.5, 2 * t.corner_radius_mm));
    t.body_length_mm = get("body", 1.0);
    if (t.kind == ToolKind::nose) positive(t.corner_radius_mm, "nose radius r");
    if (!(t.included_angle_deg > 0 && t.included_angle_deg < 180)) fail("included angle must be in (0, 180) deg");
    if (!(t.clearance_angle_deg >= 0 && t.clearance_angle_deg < 45)) fail("clearance angle must be in [0, 45) deg");
    if (!(std::fabs(t.rake_angle_deg) < 45)) fail("rake angle must be in (-45, 45) deg");
    positive(t.edge_height_mm, "edge height h");
    positive(t.body_length_mm, "body length");
    t.diameter_mm = 2 * t.radius();
    return t;
  }
  if (t.kind == ToolKind::flycutter) {
    t.swing_radius_mm = need("swing", "the swing radius");
    t.corner_radius_mm = need("r", "the nose radius");
    positive(t.swing_radius_mm, "swing radius");
    positive(t.corner_radius_mm, "nose radius r");
    if (t.corner_radius_mm >= t.swing_radius_mm) fail("nose radius must be smaller than the swing radius");
    t.diameter_mm = 2 * t.swing_radius_mm;
    t.flute_length_mm = 2 * t.corner_radius_mm;
    // Flywheel: by default reaching to 2 nose radii inside the tip circle,
    // one nose radius thick (half the nose's width, so the tip circle's
    // tube clears it between revolutions); arbor: a third of the swing, 50 mm.
    const double reach = t.swing_radius_mm - 2 * t.corner_radius_mm;
    t.holder_diameter_mm = get("holder_d", std::max(0.0, 2 * reach));
    t.holder_length_mm = get("holder_l", t.holder_diameter_mm > 0 ? t.corner_radius_mm : 0.0);
    t.shank_diameter_mm = get("shank_d", 2 * t.swing_radius_mm / 3);
    t.shank_length_mm = get("shank_l", 50.0);
    if (t.holder_diameter_mm < 0 || t.holder_length_mm < 0 || (t.holder_diameter_mm > 0) != (t.holder_length_mm > 0))
      fail("a flywheel (holder) needs both holder_d and holder_l, positive");
    if (t.holder_diameter_mm / 2 > t.swing_radius_mm - t.corner_radius_mm)
      fail("the flywheel (holder_d / 2) must stay inside the tip circle less the nose radius");
    if (!(t.shank_diameter_mm > 0) || t.shank_length_mm < 0) fail("arbor (shank) sizes must be positive");
    if (t.shank_diameter_mm / 2 > t.swing_radius_mm - t.corner_radius_mm)
      fail("the arbor (shank_d / 2) must stay inside the tip circle less the nose radius");
    return t;
  }
  t.diameter_mm = need("d", "the diameter");
  positive(t.diameter_mm, "diameter");
  const double R = t.diameter_mm / 2;
  if (t.kind == ToolKind::bull) {
    t.corner_radius_mm = need("r", "a bull-nose tool's corner radius");
    if (!(t.corner_radius_mm > 0) || t.corner_radius_mm > R) fail("corner radius must be in (0, d/2]");
  }
  if (t.kind == ToolKind::ball) t.corner_radius_mm = R;
  t.flute_length_mm = get("l", 2 * t.diameter_mm);
  positive(t.flute_length_mm, "flute length");
  if (t.flute_length_mm < t.corner_radius_mm) fail("flute length is shorter than the corner radius");
  t.neck_length_mm = get("neck_l", 0.0);
  t.neck_diameter_mm = get("neck_d", t.neck_length_mm > 0 ? t.diameter_mm : 0.0);
  if (t.neck_length_mm < 0) fail("neck length must not be negative");
  if (t.neck_length_mm > 0) positive(t.neck_diameter_mm, "neck diameter");
  if (kv.count("neck_d") && !(t.neck_length_mm > 0)) fail("a neck diameter needs a neck length (neck_l)");
  t.shank_diameter_mm = get("shank_d", t.diameter_mm);
  t.shank_length_mm = get("shank_l", 30.0);
  positive(t.shank_diameter_mm, "shank diameter");
  positive(t.shank_length_mm, "shank length");
  t.holder_length_mm = get("holder_l", 0.0);
  t.holder_diameter_mm = get("holder_d", 0.0);
  if ((t.holder_length_mm > 0) != (t.holder_diameter_mm > 0) || t.holder_length_mm < 0 || t.holder_diameter_mm < 0)
    fail("a holder needs both holder_d and holder_l, positive");
  return t;
}

Tool parse_tool_spec(const std::string& spec, const std::string& origin) {
  auto fail = [&](const std::string& msg) -> void {
    throw ConfigError(SourceLocation{origin, 0, 0, {}}, "tool '" + spec + "': " + msg);
  };
  const auto colon = spec.find(':');
  const std::string kind = spec.substr(0, colon);
  std::map<std::string, double> kv;
  if (colon != std::string::npos) {
    const std::string rest = spec.substr(colon + 1);
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
      if (kv.count(key)) fail("key '" + key + "' given twice");
      kv[key] = v;
      if (comma == std::string::npos) break;
      pos = comma + 1;
    }
  }
  return make_tool(kind, kv, spec, origin);
}

}  // namespace cutsim::tool
