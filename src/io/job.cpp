#include "cutsim/io/job.h"

#include <cmath>
#include <filesystem>
#include <cstdlib>
#include <fstream>
#include <sstream>

#include "cutsim/config/toml_context.h"

#include "cutsim/core/error.h"
#include "cutsim/core/geometry.h"

namespace cutsim::io {

using Ctx = config::TomlContext;

Aabb parse_box(const std::string& text, const std::string& origin) {
  std::vector<double> v;
  std::stringstream ss(text);
  std::string item;
  while (std::getline(ss, item, ',')) {
    char* end = nullptr;
    const double d = std::strtod(item.c_str(), &end);
    if (item.empty() || *end != '\0' || !std::isfinite(d))
      throw ConfigError(SourceLocation{origin, 0, 0, {}}, "stock box: '" + item + "' is not a number");
    v.push_back(d);
  }
  if (v.size() != 6)
    throw ConfigError(SourceLocation{origin, 0, 0, {}}, "stock box needs 6 numbers XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX");
  Aabb b{Vec3(v[0], v[1], v[2]), Vec3(v[3], v[4], v[5])};
  if ((b.max.array() <= b.min.array()).any())
    throw ConfigError(SourceLocation{origin, 0, 0, {}}, "stock box: each max must exceed its min");
  return b;
}

gcode::Dialect parse_dialect(const std::string& name, const std::string& origin) {
  if (name == "rs274ngc") return gcode::Dialect::rs274ngc;
  if (name == "fanuc") return gcode::Dialect::fanuc;
  throw ConfigError(SourceLocation{origin, 0, 0, {}}, "unknown dialect '" + name + "' (known: rs274ngc, fanuc)");
}

Job load_job(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path, "cannot open job file");
  std::stringstream buf;
  buf << in.rdbuf();
  const Ctx ctx{path, buf.str()};
  const toml::table root = ctx.parse();
  Job job;
  job.source = path;
  ctx.only_keys(root, {"program", "machine", "stock", "tool", "simulation", "target", "report", "bench"}, "the job");
  if (auto* bt = root["bench"].as_table()) {
    ctx.only_keys(*bt, {"max_wall_s", "max_rss_mb", "min_moves_per_s"}, "[bench]");
    BenchGoals g;
    auto goal = [&](const char* key, std::optional<double>& out) {
      if (auto* v = bt->get(key)) {
        out = ctx.number(*v, key);
        if (!(*out > 0)) ctx.fail(v->source(), std::string(key) + " must be positive");
      }
    };
    goal("max_wall_s", g.max_wall_s);
    goal("max_rss_mb", g.max_rss_mb);
    goal("min_moves_per_s", g.min_moves_per_s);
    job.bench = g;
  } else if (root.contains("bench")) {
    ctx.fail(root.get("bench")->source(), "[bench] must be a table");
  }
  if (auto* rt = root["report"].as_table()) {
    ctx.only_keys(*rt, {"profile"}, "[report]");
    if (auto* pv = rt->get("profile")) {
      auto* pt = pv->as_table();
      if (!pt) ctx.fail(pv->source(), "[report] profile must be a table { along, at, from, to, step }");
      ctx.only_keys(*pt, {"along", "at", "from", "to", "step"}, "[report] profile");
      ProfileSpec ps;
      auto need = [&](const char* key) -> const toml::node& {
        if (auto* n = pt->get(key)) return *n;
        ctx.fail(pv->source(), std::string("[report] profile needs '") + key + "'");
      };
      const auto along = need("along").value<std::string>();
      if (!along || (*along != "x" && *along != "y"))
        ctx.fail(need("along").source(), "[report] profile along must be \"x\" or \"y\"");
      ps.along = (*along)[0];
      ps.at = ctx.number(need("at"), "[report] profile at");
      ps.from = ctx.number(need("from"), "[report] profile from");
      ps.to = ctx.number(need("to"), "[report] profile to");
      ps.step = ctx.number(need("step"), "[report] profile step");
      if (!(ps.step > 0) || !(ps.to > ps.from) || (ps.to - ps.from) / ps.step > 1e6)
        ctx.fail(pv->source(), "[report] profile needs from < to and 0 < step, at most 1e6 samples");
      job.profile = ps;
    }
  } else if (root.contains("report")) {
    ctx.fail(root.get("report")->source(), "[report] must be a table");
  }
  if (auto* tt = root["target"].as_table()) {
    ctx.only_keys(*tt, {"file", "offset", "rotate_deg", "scale", "tolerance_mm"}, "[target]");
    const auto dir = std::filesystem::path(path).parent_path();
    if (auto* f = tt->get("file")) {
      const auto v = f->value<std::string>();
      if (!v) ctx.fail(f->source(), "[target] file must be a string");
      job.target = std::filesystem::path(*v).is_relative() ? (dir / *v).string() : *v;
    }
    if (auto* v = tt->get("offset")) job.target_offset_mm = ctx.vec3(*v, "[target] offset");
    if (auto* v = tt->get("rotate_deg")) job.target_rotate_deg = ctx.vec3(*v, "[target] rotate_deg");
    if (auto* v = tt->get("scale")) {
      job.target_scale = ctx.number(*v, "[target] scale");
      if (!(job.target_scale > 0)) ctx.fail(v->source(), "[target] scale must be positive");
    }
    if (auto* v = tt->get("tolerance_mm")) {
      job.tolerance_mm = ctx.number(*v, "[target] tolerance_mm");
      if (!(*job.tolerance_mm >= 0)) ctx.fail(v->source(), "[target] tolerance_mm must not be negative");
    }
  } else if (root.contains("target")) {
    ctx.fail(root.get("target")->source(), "[target] must be a table");
  }
  if (auto* mt = root["machine"].as_table()) {
    ctx.only_keys(*mt, {"name", "errors", "tool_setting", "workpiece_setting", "environment"}, "[machine]");
    const auto dir = std::filesystem::path(path).parent_path();
    auto str = [&](const char* key) -> std::optional<std::string> {
      auto* n = mt->get(key);
      if (!n) return std::nullopt;
      auto v = n->value<std::string>();
      if (!v) ctx.fail(n->source(), std::string("[machine] ") + key + " must be a string");
      return v;
    };
    job.machine = str("name");
    if (job.machine && job.machine->find(".toml") != std::string::npos && std::filesystem::path(*job.machine).is_relative())
      job.machine = (dir / *job.machine).string();
    job.tool_setting = str("tool_setting");
    job.workpiece_setting = str("workpiece_setting");
    if (auto e = str("environment")) job.environment = std::filesystem::path(*e).is_relative() ? (dir / *e).string() : *e;
    if (auto* er = mt->get("errors")) {
      const auto* t = er->as_table();
      if (!t) ctx.fail(er->source(), "[machine] errors must be a table of AXIS = \"dx=..,dy=..\"");
      for (const auto& [k, v] : *t) {
        auto sv = v.value<std::string>();
        if (!sv) ctx.fail(v.source(), "an error spec must be a string such as \"dy=-0.5\"");
        job.joint_errors.emplace_back(std::string(k.str()), *sv);
      }
    }
  } else if (root.contains("machine")) {
    ctx.fail(root.get("machine")->source(), "[machine] must be a table");
  }
  if (auto* pr = root["program"].as_table()) {
    ctx.only_keys(*pr, {"dialect", "block_delete"}, "[program]");
    if (auto* d = pr->get("dialect")) {
      const auto v = d->value<std::string>();
      if (!v) ctx.fail(d->source(), "[program] dialect must be a string");
      try {
        job.dialect = parse_dialect(*v, path);
      } catch (const ConfigError& e) {
        ctx.fail(d->source(), e.message());
      }
    }
    if (auto* b = pr->get("block_delete")) {
      const auto v = b->value<bool>();
      if (!v) ctx.fail(b->source(), "[program] block_delete must be true or false");
      job.block_delete = *v;
    }
  } else if (root.contains("program")) {
    ctx.fail(root.get("program")->source(), "[program] must be a table");
  }
  if (auto* st = root["stock"].as_table()) {
    ctx.only_keys(*st, {"box"}, "[stock]");
    if (auto* b = st->get("box")) {
      const auto* a = b->as_array();
      if (!a || a->size() != 6) ctx.fail(b->source(), "[stock] box must be [xmin, ymin, zmin, xmax, ymax, zmax]");
      double v[6];
      for (int i = 0; i < 6; ++i) v[i] = ctx.number(*a->get(static_cast<std::size_t>(i)), "[stock] box");
      Aabb box{Vec3(v[0], v[1], v[2]), Vec3(v[3], v[4], v[5])};
      if ((box.max.array() <= box.min.array()).any()) ctx.fail(b->source(), "[stock] box: each max must exceed its min");
      job.stock_box = box;
    }
  } else if (root.contains("stock")) {
    ctx.fail(root.get("stock")->source(), "[stock] must be a table");
  }
  if (auto* t = root["tool"].as_table()) {
    ctx.only_keys(*t, {"spec", "library"}, "[tool]");
    if (auto* l = t->get("library")) {
      const auto v = l->value<std::string>();
      if (!v) ctx.fail(l->source(), "[tool] library must be a string (a .toml or .tbl file)");
      const auto dir = std::filesystem::path(path).parent_path();
      job.tool_library = std::filesystem::path(*v).is_relative() ? (dir / *v).string() : *v;
    }
    if (auto* s = t->get("spec")) {
      const auto v = s->value<std::string>();
      if (!v) ctx.fail(s->source(), "[tool] spec must be a string such as \"ball:d=1\"");
      try {
        job.tool = tool::parse_tool_spec(*v, path);
      } catch (const ConfigError& e) {
        ctx.fail(s->source(), e.message());
      }
    }
  } else if (root.contains("tool")) {
    ctx.fail(root.get("tool")->source(), "[tool] must be a table");
  }
  if (auto* s = root["simulation"].as_table()) {
    ctx.only_keys(*s, {"voxel_mm", "start", "memory_limit_mb", "contact_tolerance_mm", "stop_at_first_contact"},
                  "[simulation]");
    if (auto* v = s->get("contact_tolerance_mm")) {
      job.contact_tolerance_mm = ctx.number(*v, "contact_tolerance_mm");
      if (!(*job.contact_tolerance_mm >= 0)) ctx.fail(v->source(), "contact_tolerance_mm must not be negative");
    }
    if (auto* v = s->get("stop_at_first_contact")) {
      const auto b = v->value<bool>();
      if (!b) ctx.fail(v->source(), "stop_at_first_contact must be true or false");
      job.stop_at_first_contact = *b;
    }
    if (auto* v = s->get("voxel_mm")) {
      job.voxel_mm = ctx.number(*v, "voxel_mm");
      if (!(*job.voxel_mm > 0)) ctx.fail(v->source(), "voxel_mm must be positive");
      if (*job.voxel_mm < kFinestVoxelMm) {
        std::ostringstream os;
        os << "voxel_mm " << *job.voxel_mm << " is finer than the stock grid can hold (" << kFinestVoxelMm << " mm at least)";
        ctx.fail(v->source(), os.str());
      }
    }
    if (auto* v = s->get("start")) job.start_mm = ctx.vec3(*v, "start");
    if (auto* v = s->get("memory_limit_mb")) {
      job.memory_limit_mb = ctx.number(*v, "memory_limit_mb");
      if (!(*job.memory_limit_mb > 0)) ctx.fail(v->source(), "memory_limit_mb must be positive");
    }
  } else if (root.contains("simulation")) {
    ctx.fail(root.get("simulation")->source(), "[simulation] must be a table");
  }
  return job;
}

}  // namespace cutsim::io
