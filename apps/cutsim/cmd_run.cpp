// cutsim run PROG.nc: simulate and write OUTDIR/<stem>.glb and .report.json.
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <future>
#include <iostream>
#include <array>
#include <cmath>
#include <memory>
#include <optional>
#include <vector>

#include <tbb/global_control.h>

#include "commands.h"
#include "outputs.h"
#include "cutsim/core/error.h"
#include "cutsim/core/huge_pages.h"
#include "cutsim/io/atomic_file.h"
#include "cutsim/io/gltf_writer.h"
#include "cutsim/io/job.h"
#include "cutsim/sim/interference.h"
#include "cutsim/sim/report.h"
#include "cutsim/sim/simulate.h"

namespace cutsim::app {

namespace fs = std::filesystem;

namespace {
struct RunArgs {
  std::string program;
  std::string job;
  std::string outdir = ".";
  double voxel = 0;
  std::string format = "text";
  std::string stock_box;
  std::string tool;
  std::string tools;
  double contact_tolerance = -1;
  bool stop_at_contact = false;
  bool save_vdb = false;
  int threads = 0;
  double mesh_adaptivity = 0.01;
  std::string dialect;
  bool block_delete = false;
  std::string machine;
  std::vector<std::string> joint_errors;
  std::string tool_setting, workpiece_setting, environment;
  bool partial = false;
  std::size_t measure_band = 0;
  std::string target;
  double tolerance = -1;
  double glb_scale = 1.0;
};

// A marker at a contact: an octahedron of radius r with flat faces.
TriMesh octahedron(const Vec3& c, double r) {
  TriMesh m;
  const Vec3 v[6] = {c + Vec3(r, 0, 0), c - Vec3(r, 0, 0), c + Vec3(0, r, 0),
                     c - Vec3(0, r, 0), c + Vec3(0, 0, r), c - Vec3(0, 0, r)};
  const int faces[8][3] = {{0, 2, 4}, {2, 1, 4}, {1, 3, 4}, {3, 0, 4}, {2, 0, 5}, {1, 2, 5}, {3, 1, 5}, {0, 3, 5}};
  for (const auto& f : faces) {
    const Vec3 n = (v[f[1]] - v[f[0]]).cross(v[f[2]] - v[f[0]]).normalized();
    for (int k = 0; k < 3; ++k) {
      m.positions.push_back(v[f[k]]);
      m.normals.push_back(n.cast<float>());
    }
    const auto b = static_cast<std::uint32_t>(m.positions.size() - 3);
    m.triangles.push_back({b, b + 1, b + 2});
  }
  return m;
}
}  // namespace

Action add_run_command(CLI::App& app) {
  auto args = std::make_shared<RunArgs>();
  CLI::App* cmd = app.add_subcommand("run", "simulate a program and write the machined stock (.glb) and a report (.json)");
  cmd->add_option("program", args->program, "NC program (G-code)")->required();
  cmd->add_option("--job", args->job, "job file (TOML); default: <program stem>.toml beside the program, if present");
  cmd->add_option("-o,--output", args->outdir, "output directory (created if missing)");
  cmd->add_option("--voxel", args->voxel, "voxel size, mm")->check(kPositive);
  cmd->add_option("--format", args->format, "console output: text or json")->check(CLI::IsMember({"text", "json"}));
  cmd->add_option("--stock-box", args->stock_box, "stock box XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX in mm");
  cmd->add_option("--tool", args->tool,
                  "tool spec: ball:d=1, flat:d=6[,l=12], bull:d=2,r=0.2, flycutter:swing=18,r=2, "
                  "nose:r=0.9789,clearance=10, vtool:angle=90,clearance=7 (keys in the README)");
  cmd->add_option("--tools", args->tools, "tool library by T number: TOML ([[tool]]) or a LinuxCNC .tbl table");
  cmd->add_option("--contact-tolerance", args->contact_tolerance,
                  "contacts shallower than this are not reported, mm (default: a quarter voxel)")
      ->check(kNonNegative);
  cmd->add_flag("--stop-at-contact", args->stop_at_contact, "stop at the first contact and write the stock as it is then");
  cmd->add_option("--threads", args->threads, "worker threads (default: all cores)")->check(kNonNegative);
  cmd->add_flag("--save-vdb", args->save_vdb,
                "also write the stock grid as OUTDIR/<stem>.vdb (OpenVDB), for 'cutsim compare' later");
  cmd->add_option("--dialect", args->dialect, "G-code dialect: rs274ngc (default) or fanuc")
      ->check(CLI::IsMember({"rs274ngc", "fanuc"}));
  cmd->add_flag("--block-delete", args->block_delete, "skip lines that start with '/'");
  cmd->add_option("--machine", args->machine, "machine: preset (xyz, xyza, xyzbc, xzc, flycut) or a .toml file");
  cmd->add_option("--joint-error", args->joint_errors,
                  "assembly error of a joint, e.g. A:dy=-0.5,gamma=1e-5 (dx dy dz mm, alpha beta gamma rad); repeatable");
  cmd->add_option("--tool-setting", args->tool_setting, "setting error of the tool: dx=..,dy=..,dz=..,alpha=..,beta=..,gamma=..");
  cmd->add_option("--workpiece-setting", args->workpiece_setting, "setting error of the workpiece (same keys)");
  cmd->add_option("--environment", args->environment,
                  "environment log CSV (time_s, temperature_c, humidity_pct, pressure_hpa) for laser-scale axes");
  cmd->add_option("--measure-band", args->measure_band,
                  "also count the voxels the moves' bands reach (the report's band_voxels, for 'cutsim bench'), "
                  "evaluating 1 leaf in N one voxel at a time; slow at N = 1")
      ->check(kPositive);
  cmd->add_flag("--partial", args->partial,
                "on Ctrl-C or SIGTERM while cutting, write what was cut so far as <stem>.partial.glb and "
                "<stem>.partial.report.json (default: write nothing)");
  cmd->add_option("--target", args->target, "target (design) mesh: STL, OBJ, PLY, glTF or glb, in the workpiece frame");
  cmd->add_option("--tolerance", args->tolerance, "deviation band counted as in tolerance, mm (default 0.001)")
      ->check(kNonNegative);
  cmd->add_option("--glb-scale", args->glb_scale,
                  "scale of the glb's root node (1: metres; 1000 shows a 1 mm part as 1 m)")
      ->check(kPositive);
  cmd->add_option("--mesh-adaptivity", args->mesh_adaptivity,
                  "0: one quad per surface voxel; 0.01 (default) to 1: merge ever less flat regions into larger polygons "
                  "(the machined surface and the overcut and undercut regions)")
      ->check(CLI::Range(0.0, 1.0));

  return [args]() -> int {
    const auto t0 = std::chrono::steady_clock::now();
    std::optional<tbb::global_control> threads;
    if (args->threads > 0)
      threads.emplace(tbb::global_control::max_allowed_parallelism, static_cast<std::size_t>(args->threads));
    sim::SimOptions opt;
    opt.program = args->program;
    if (!fs::exists(opt.program)) throw InputError(opt.program, "no such file");
    if (fs::is_directory(opt.program)) throw InputError(opt.program, "is a directory, not a program");
    std::string job_path = args->job;
    if (job_path.empty()) {
      fs::path beside = fs::path(opt.program).replace_extension(".toml");
      if (fs::exists(beside)) job_path = beside.string();
    }
    if (!job_path.empty()) opt.job = io::load_job(job_path);
    if (!args->stock_box.empty()) opt.stock_box = io::parse_box(args->stock_box, "--stock-box");
    if (!args->tool.empty()) opt.tool = tool::parse_tool_spec(args->tool, "--tool");
    if (!args->tools.empty()) opt.tools_file = args->tools;
    if (args->contact_tolerance >= 0) opt.contact_tolerance_mm = args->contact_tolerance;
    opt.stop_at_first_contact = args->stop_at_contact;
    if (args->voxel > 0) opt.voxel_mm = args->voxel;
    if (!args->dialect.empty()) opt.dialect = io::parse_dialect(args->dialect, "--dialect");
    opt.block_delete = args->block_delete;
    if (!args->machine.empty()) opt.machine = args->machine;
    opt.joint_errors = args->joint_errors;
    if (!args->tool_setting.empty()) opt.tool_setting = args->tool_setting;
    if (!args->workpiece_setting.empty()) opt.workpiece_setting = args->workpiece_setting;
    if (!args->environment.empty()) opt.environment = args->environment;
    opt.keep_partial = args->partial;
    opt.measure_band_every = args->measure_band;
    // The target is read and checked while the program's passes run
    // (both on one thread each: 0.15 s and 0.1 s for the snowflake), and
    // the simulation waits for it before building any grid: a target that
    // cannot be read, is not closed or misses the stock stops the run
    // there. Its distance structure (normals, Embree's tree: some 0.2 s
    // for the snowflake's 555k triangles, mostly on one thread) is then
    // built beside the simulation, whose serial stretches leave a core
    // idle. Held to one thread, the run reads the target first and builds
    // the structure at the export, as before.
    const std::string target_file = !args->target.empty() ? args->target : opt.job.target.value_or("");
    auto load = [target_file, from_job = args->target.empty(), scale = opt.job.target_scale,
                 rotate = opt.job.target_rotate_deg, offset = opt.job.target_offset_mm] {
      return from_job ? sim::load_target(target_file, scale, rotate, offset)
                      : sim::load_target(target_file, 1.0, Vec3::Zero(), Vec3::Zero());
    };
    std::optional<TriMesh> target_mesh;  // (held to one thread)
    // (Declared before the future, whose end waits for the reading thread:
    // the promise must outlive it, whatever ends the run.)
    std::promise<Aabb> target_read;  // its bounds, or why it cannot be read
    std::future<compare::Target> target_ready;
    if (!target_file.empty()) {
      opt.target_file = target_file;
      if (args->threads != 1) {
        opt.target_bounds = [bounds = target_read.get_future().share()] { return bounds.get(); };
        target_ready = std::async(std::launch::async, [&target_read, load]() {
          TriMesh m;
          try {
            m = load();
          } catch (...) {
            target_read.set_exception(std::current_exception());
            throw;
          }
          target_read.set_value(m.bounds());
          return compare::Target(std::move(m));
        });
      } else {
        target_mesh = load();
        opt.target_bounds = [b = target_mesh->bounds()] { return b; };
      }
    }
    const double tolerance = args->tolerance >= 0 ? args->tolerance : opt.job.tolerance_mm.value_or(0.001);
    const io::OutputDirectory output_dir(args->outdir);  // removed again if the run fails before writing

    ProgressBar bar;
    opt.progress = [&bar](double f, int line) { bar.update(f, line); };
    sim::SimResult res = sim::simulate(opt);
    bar.finish();

    const std::string stem = fs::path(opt.program).stem().string() + (res.interrupted ? ".partial" : "");
    sim::ReportOutputs out;
    out.glb = (fs::path(args->outdir) / (stem + ".glb")).string();
    out.report = (fs::path(args->outdir) / (stem + ".report.json")).string();

    const auto t_exp = std::chrono::steady_clock::now();
    res.timing.peak_rss_simulate_mb = sim::peak_rss_mb();
    auto since = [](auto t) { return std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count(); };
    const SmallPagesForNewMemory small_pages;  // (the export's memory is new, and written once)
    const TriMesh mesh = res.stock->surface_mesh(args->mesh_adaptivity);
    res.timing.mesh_s = since(t_exp);
    const auto t_cmp = std::chrono::steady_clock::now();
    io::GltfPart part{"machined_stock", &mesh, {0.75f, 0.75f, 0.78f, 1.0f}};
    io::GltfOptions gopt;
    gopt.scale = args->glb_scale;
    std::vector<std::array<float, 4>> colors;
    std::vector<io::GltfPart> parts;
    if (!target_file.empty()) {
      const compare::Target target = target_ready.valid() ? target_ready.get() : compare::Target(std::move(*target_mesh));
      compare::CompareOptions compare_options{tolerance};
      compare_options.region_mesh_adaptivity = args->mesh_adaptivity;
      res.comparison = compare::compare(*res.stock, target, mesh, compare_options);
      parts = comparison_parts(*res.comparison, part, gopt, colors);
    } else {
      parts.push_back(part);
    }
    res.timing.compare_s = since(t_cmp);
    const auto t_write = std::chrono::steady_clock::now();
    // Contact markers: one node per contact (the 200 that matter most:
    // rapids, then holder, shank and neck, then the deepest), named by its
    // NC line; rapids magenta, clearance faces orange, neck/shank/holder yellow.
    std::vector<TriMesh> markers;
    std::vector<std::string> marker_names;
    const std::vector<std::size_t> marked = sim::most_severe_contacts(res.contacts, 200);
    const std::size_t n_markers = marked.size();
    markers.reserve(n_markers);
    for (std::size_t i = 0; i < n_markers; ++i) {
      const auto& c = res.contacts[marked[i]];
      markers.push_back(octahedron(c.where, std::max(8 * res.voxel_mm, c.depth_mm)));
      char name[96];
      std::snprintf(name, sizeof name, "contact line %d %s%s %.3g um", c.line, c.rapid ? "rapid " : "",
                    c.region.c_str(), c.depth_mm * 1000);
      marker_names.push_back(name);
    }
    for (std::size_t i = 0; i < n_markers; ++i) {
      const auto& c = res.contacts[marked[i]];
      const std::array<float, 4> col = c.rapid ? std::array<float, 4>{0.9f, 0.1f, 0.9f, 1.0f}
                                       : c.region == "clearance-face" ? std::array<float, 4>{1.0f, 0.45f, 0.0f, 1.0f}
                                                                      : std::array<float, 4>{0.95f, 0.85f, 0.1f, 1.0f};
      io::GltfPart mp{marker_names[i], &markers[i], col};
      mp.extras_text = {{"kind", "contact"}, {"region", c.region}, {"text", c.text}, {"motion", c.rapid ? "rapid" : "feed"}};
      mp.extras_number = {{"line", c.line}, {"depth_mm", c.depth_mm}, {"depth_at_least", c.at_least ? 1.0 : 0.0},
                          {"poses", c.poses}};
      parts.push_back(std::move(mp));
    }
    io::write_glb(out.glb, parts, gopt);
    if (args->save_vdb) {
      out.vdb = (fs::path(args->outdir) / (stem + ".vdb")).string();
      try {
        res.stock->save_vdb(out.vdb);
      } catch (...) {
        std::error_code ec;
        fs::remove(out.glb, ec);
        throw;
      }
    }
    res.timing.write_s = since(t_write);
    res.timing.export_s = since(t_exp);
    res.timing.total_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const std::string json = sim::report_json(res, out);
    try {
      io::write_file_atomic(out.report, json);
    } catch (...) {
      std::error_code ec;
      fs::remove(out.glb, ec);  // no half a result
      if (!out.vdb.empty()) fs::remove(out.vdb, ec);
      throw;
    }
    if (args->format == "json") std::cout << json;
    else std::cout << sim::report_text(res, out);
    if (res.interrupted) {
      std::cerr << res.interrupt_message << "\npartial result written (" << out.glb << ")\n";
      return res.interrupt_status;
    }
    return res.contacts.empty() ? 0 : static_cast<int>(ExitCode::contacts);
  };
}

}  // namespace cutsim::app
