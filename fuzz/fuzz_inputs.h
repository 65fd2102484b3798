#pragma once
// What the fuzz targets do with one input; shared with the regression test
// that replays tests/fuzz_regressions/. A cutsim::Error is a correct answer.
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <sstream>
#include <string>
#include <unistd.h>
#include <vector>

#include "cutsim/core/error.h"
#include "cutsim/gcode/program_reader.h"
#include "cutsim/io/job.h"
#include "cutsim/io/mesh_io.h"
#include "cutsim/io/tool_library.h"
#include "cutsim/machine/environment.h"
#include "cutsim/machine/kinematics.h"
#include "cutsim/motion/interpreter.h"

namespace cutsim::fuzz {

/// First byte: bit 0 dialect (1 fanuc), bit 1 block delete; the rest is the program.
inline void gcode_input(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return;
  const auto dialect = (data[0] & 1) ? gcode::Dialect::fanuc : gcode::Dialect::rs274ngc;
  std::istringstream in(std::string(reinterpret_cast<const char*>(data) + 1, size - 1));
  gcode::ReaderOptions ro;
  ro.dialect = dialect;
  ro.block_delete = (data[0] & 2) != 0;
  ro.max_lines_executed = 20000;
  ro.max_line_bytes = 1 << 16;
  motion::InterpreterOptions io;
  io.dialect = dialect;
  try {
    gcode::ProgramReader reader(in, "fuzz.nc", ro);
    motion::Interpreter interp("fuzz.nc", io);
    gcode::Block b;
    std::vector<motion::Move> moves;
    while (reader.next(b)) {
      moves.clear();
      interp.execute(b, moves);
      for (const auto& m : moves) {
        volatile double sink = m.length() + m.path_bounds().volume();
        (void)sink;
      }
    }
  } catch (const Error&) {
  }
}

/// The whole input is a job file; its first 64 bytes also a tool spec.
inline void job_input(const std::uint8_t* data, std::size_t size) {
  static const std::string path = "/tmp/cutsim-fuzz-job-" + std::to_string(::getpid()) + ".toml";
  if (FILE* f = std::fopen(path.c_str(), "wb")) {
    std::fwrite(data, 1, size, f);
    std::fclose(f);
    try {
      io::load_job(path);
    } catch (const Error&) {
    }
    std::remove(path.c_str());
  }
  try {
    tool::parse_tool_spec(std::string(reinterpret_cast<const char*>(data), size < 64 ? size : 64));
  } catch (const Error&) {
  }
}

namespace detail {
inline std::string write_temp(const char* what, const std::uint8_t* data, std::size_t size) {
  const std::string path = std::string("/tmp/cutsim-fuzz-") + what + "-" + std::to_string(::getpid());
  if (FILE* f = std::fopen(path.c_str(), "wb")) {
    std::fwrite(data, 1, size, f);
    std::fclose(f);
  }
  return path;
}
}  // namespace detail

/// The whole input is a machine file; a loaded machine is run through its
/// kinematics at a few joint values.
inline void machine_input(const std::uint8_t* data, std::size_t size) {
  const std::string path = detail::write_temp("machine.toml", data, size);
  try {
    const machine::Kinematics k(machine::load_machine(path));
    for (double v : {0.0, 1.0, -2.5})
      (void)k.tool_pose({v, v, v, v, v, v});
    (void)k.solve_tip(Vec3(1, 2, 3), {0, 0, 0, 0.1, 0.2, 0.3});
  } catch (const Error&) {
  }
  std::remove(path.c_str());
}

/// First byte: the format (stl, obj, ply, glb, gltf); the rest is the
/// file. A loaded mesh is also checked for closedness.
inline void mesh_input(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return;
  static const char* kExt[] = {"stl", "obj", "ply", "glb", "gltf"};
  const std::string path = detail::write_temp((std::string("mesh.") + kExt[data[0] % 5]).c_str(), data + 1, size - 1);
  try {
    const TriMesh m = io::load_mesh(path);
    (void)io::find_defects(m);
  } catch (const Error&) {
  }
  std::remove(path.c_str());
}

/// The whole input is an environment log (CSV).
inline void environment_input(const std::uint8_t* data, std::size_t size) {
  const std::string path = detail::write_temp("env.csv", data, size);
  try {
    const auto log = machine::EnvironmentLog::load_csv(path);
    for (double t : {-1.0, 0.0, 1.5, 1e9}) (void)log.refractive_index(t);
  } catch (const Error&) {
  }
  std::remove(path.c_str());
}

/// First byte: bit 0 chooses a LinuxCNC table (1) or a TOML library (0);
/// the rest is the file. Each loaded tool's regions are measured.
inline void tools_input(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return;
  const std::string text(reinterpret_cast<const char*>(data) + 1, size - 1);
  try {
    io::ToolLibrary lib;
    if (data[0] & 1) {
      std::istringstream in(text);
      lib = io::parse_linuxcnc_tbl(in, "fuzz.tbl");
    } else {
      lib = io::parse_tool_library_toml(text, "fuzz.toml");
    }
    for (const auto& [n, t] : lib.tools) {
      volatile double sink = tool::shape_distance(tool::cutting_shape(t), Vec3(0.1, 0.2, 0.3));
      for (const auto& r : tool::contact_regions(t)) sink = sink + tool::shape_bounds(r.shape).volume();
      (void)sink;
    }
  } catch (const Error&) {
  }
}

}  // namespace cutsim::fuzz
