// cutsim compare MACHINED TARGET: a stock saved by `run --save-vdb` (or a
// closed mesh) against a target, without simulating again.
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <memory>

#include <nlohmann/json.hpp>

#include "commands.h"
#include "cutsim/core/error.h"
#include "cutsim/core/huge_pages.h"
#include "cutsim/io/atomic_file.h"
#include "cutsim/io/job.h"
#include "cutsim/io/mesh_io.h"
#include "cutsim/sim/report.h"
#include "cutsim/sim/simulate.h"
#include "outputs.h"

namespace cutsim::app {

namespace fs = std::filesystem;

namespace {
struct CompareArgs {
  std::string machined, target, job, outdir = ".", format = "text";
  double tolerance = -1, voxel = 0, glb_scale = 1.0, mesh_adaptivity = 0.01;
};
}  // namespace

Action add_compare_command(CLI::App& app) {
  auto a = std::make_shared<CompareArgs>();
  CLI::App* cmd = app.add_subcommand(
      "compare", "compare a machined stock (.vdb from 'run --save-vdb') or a closed mesh with a target, without simulating");
  cmd->add_option("machined", a->machined, "machined stock: .vdb written by 'cutsim run --save-vdb', or STL/OBJ/PLY/glTF")
      ->required();
  cmd->add_option("target", a->target, "target (design) mesh: STL, OBJ, PLY, glTF or glb")->required();
  cmd->add_option("--job", a->job, "job file whose [target] places the target (offset, rotate_deg, scale) and sets the tolerance");
  cmd->add_option("-o,--output", a->outdir, "output directory (created if missing)");
  cmd->add_option("--tolerance", a->tolerance, "deviation band counted as in tolerance, mm (default 0.001)")
      ->check(kNonNegative);
  cmd->add_option("--voxel", a->voxel, "voxel size for a mesh MACHINED, mm (default: its largest side / 1000)")
      ->check(kPositive);
  cmd->add_option("--glb-scale", a->glb_scale, "scale of the glb's root node (1: metres)")->check(kPositive);
  cmd->add_option("--mesh-adaptivity", a->mesh_adaptivity,
                  "mesh adaptivity, 0 to 1: the surface of a .vdb and the overcut and undercut regions")
      ->check(CLI::Range(0.0, 1.0));
  cmd->add_option("--format", a->format, "console output: text or json")->check(CLI::IsMember({"text", "json"}));

  return [a]() -> int {
    const SmallPagesForNewMemory small_pages;  // (all of its memory is new: see huge_pages.h)
    if (!fs::exists(a->machined)) throw InputError(a->machined, "no such file");
    if (!fs::exists(a->target)) throw InputError(a->target, "no such file");
    io::Job job;
    if (!a->job.empty()) job = io::load_job(a->job);
    TriMesh target_mesh = a->job.empty() ? sim::load_target(a->target, 1.0, Vec3::Zero(), Vec3::Zero())
                                         : sim::load_target(a->target, job.target_scale, job.target_rotate_deg,
                                                            job.target_offset_mm);
    const double tolerance = a->tolerance >= 0 ? a->tolerance : job.tolerance_mm.value_or(0.001);
    const io::OutputDirectory output_dir(a->outdir);  // removed again if the run fails before writing

    std::string ext = fs::path(a->machined).extension().string();
    for (auto& ch : ext) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
    std::unique_ptr<stock::Stock> stock;
    TriMesh machined;
    std::string note;
    if (ext == ".vdb") {
      stock = std::make_unique<stock::Stock>(stock::Stock::load_vdb(a->machined));
      machined = stock->surface_mesh(a->mesh_adaptivity);
    } else {
      machined = io::load_mesh(a->machined);
      io::require_closed(machined, a->machined,
                         "the machined mesh (a run's .glb is not one solid: compare its --save-vdb file)");
      double h = a->voxel;
      if (!(h > 0)) {
        h = machined.bounds().size().maxCoeff() / 1000;
        note = "voxel: " + std::to_string(h) + " mm (default: the mesh's largest side / 1000; set --voxel)";
      }
      stock = std::make_unique<stock::Stock>(stock::Stock::from_mesh(machined, h));
    }
    if (!target_mesh.bounds().overlaps(stock->box()))
      throw GeometryError(SourceLocation{a->target, 0, 0, {}},
                          "the target does not overlap the machined stock: nothing to compare; check its placement");
    const compare::Target target(std::move(target_mesh));
    compare::CompareOptions compare_options{tolerance};
    compare_options.region_mesh_adaptivity = a->mesh_adaptivity;
    const compare::CompareResult c = compare::compare(*stock, target, machined, compare_options);

    const std::string stem = fs::path(a->machined).stem().string() + ".compare";
    const std::string glb = (fs::path(a->outdir) / (stem + ".glb")).string();
    const std::string rep = (fs::path(a->outdir) / (stem + ".json")).string();
    io::GltfOptions gopt;
    gopt.scale = a->glb_scale;
    std::vector<std::array<float, 4>> colors;
    const auto parts = comparison_parts(c, io::GltfPart{"machined_stock", &machined, {0.75f, 0.75f, 0.78f, 1.0f}}, gopt, colors);
    io::write_glb(glb, parts, gopt);

    nlohmann::ordered_json j;
    j["machined"] = a->machined;
    j["target"] = a->target;
    j["voxel_size_mm"] = stock->voxel_mm();
    for (const auto& [k, v] : sim::comparison_fields(c)) j[k] = v;
    j["defaults"] = note.empty() ? nlohmann::ordered_json::array() : nlohmann::ordered_json::array({note});
    j["outputs"] = {{"glb", glb}, {"report", rep}};
    const std::string json = j.dump(2) + "\n";
    try {
      io::write_file_atomic(rep, json);
    } catch (...) {
      std::error_code ec;
      fs::remove(glb, ec);
      throw;
    }
    if (a->format == "json") {
      std::cout << json;
    } else {
      if (!note.empty()) std::cout << "note: " << note << "\n";
      std::cout << sim::comparison_text(c) << "wrote " << glb << "\nwrote " << rep << "\n";
    }
    return 0;
  };
}

}  // namespace cutsim::app
