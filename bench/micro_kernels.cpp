// Google Benchmark micro-benchmarks of the hot kernels: the block reader,
// sweep distances, the stock update, the deviation query and the
// comparison's voxel queries.
#include <benchmark/benchmark.h>

#include <cmath>
#include <sstream>

#include "cutsim/cases/cases.h"
#include "cutsim/compare/target.h"
#include "cutsim/gcode/block_reader.h"
#include "cutsim/motion/interpreter.h"
#include "cutsim/stock/stock.h"
#include "cutsim/sweep/sweep.h"

namespace {

using namespace cutsim;

motion::Move make_move(const std::string& program) {
  std::istringstream in(program);
  gcode::BlockReader reader(in, "b.nc");
  motion::Interpreter interp("b.nc");
  std::vector<motion::Move> moves;
  gcode::Block b;
  while (reader.next(b)) interp.execute(b, moves);
  return moves.back();
}

void BM_ParseLine(benchmark::State& state) {
  const std::string line = "G1 X12.345678 Y-3.141593 Z-0.012345 F1200";
  gcode::Block b;
  for (auto _ : state) {
    gcode::BlockReader::parse_line("b.nc", 1, line, b);
    benchmark::DoNotOptimize(b.words.data());
  }
  state.SetBytesProcessed(static_cast<int64_t>(state.iterations() * (line.size() + 1)));
}
BENCHMARK(BM_ParseLine);

void sweep_distance(benchmark::State& state, const std::string& program, const std::string& tool_spec) {
  const auto s = sweep::sweep_move(make_move(program), tool::parse_tool_spec(tool_spec));
  Vec3 p(0.3, 0.2, -0.1);
  for (auto _ : state) {
    benchmark::DoNotOptimize(s.distance(p));
    p.x() += 1e-9;
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK_CAPTURE(sweep_distance, ball_line, "G0 X0 Y0 Z0\nG1 X1 Y0.5 Z-0.1 F1\n", "ball:d=1");
BENCHMARK_CAPTURE(sweep_distance, flat_horizontal, "G0 X0 Y0 Z0\nG1 X1 Y0.5 F1\n", "flat:d=1");
BENCHMARK_CAPTURE(sweep_distance, flat_ramp, "G0 X0 Y0 Z0\nG1 X1 Y0.5 Z-0.1 F1\n", "flat:d=1");
BENCHMARK_CAPTURE(sweep_distance, flat_g17_arc, "G0 X1 Y0 Z0\nG3 X-1 Y0 R1 F1\n", "flat:d=1");

// A ball end turning while it moves (5-axis finishing, as the blade's):
// the hull piece of a 1 mm ball with a 2.5 mm core, 10 um along the path
// while its axis tilts 0.5 deg. Points on a sphere around the start's
// centre at the ball's radius +-3 um: where the stock update asks.
void BM_HullPieceDistance(benchmark::State& state) {
  const double a = 0.5 * M_PI / 180, L = 2.5;
  const Vec3 c0(0, 0, 0), c1(0.01, 0.002, 0.001);
  const sweep::Primitive p = sweep::hull_prim(c0, c0 + Vec3(0, 0, L), c1, c1 + L * Vec3(std::sin(a), 0, std::cos(a)), 0.5);
  std::vector<Vec3> pts;
  for (int i = 0; i < 4096; ++i) {
    const double z = 1 - 2 * (i + 0.5) / 4096, r = std::sqrt(1 - z * z), phi = 2.399963229728653 * i;
    pts.push_back((0.5 + 0.003 * std::sin(7.0 * i)) * Vec3(r * std::cos(phi), r * std::sin(phi), z));
  }
  std::size_t k = 0;
  for (auto _ : state) {
    benchmark::DoNotOptimize(sweep::distance(p, pts[k]));
    k = (k + 1) & 4095;
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_HullPieceDistance);

void BM_StockSubtractBallPass(benchmark::State& state) {
  const double h = 0.001 * static_cast<double>(state.range(0));
  const tool::Tool t = tool::parse_tool_spec("ball:d=1");
  stock::StockOptions opt;
  opt.voxel_mm = h;
  const Aabb box{Vec3(-1, -1, -1), Vec3(3, 1, 0)};
  std::size_t voxels = 0;
  for (auto _ : state) {
    state.PauseTiming();
    stock::Stock st(box, box, opt);
    const auto s = sweep::sweep_move(make_move("G0 X0 Y0 Z-0.05\nG1 X2 F1\n"), t);
    state.ResumeTiming();
    st.subtract(s);
    voxels = st.stats().active_voxels;
  }
  state.counters["active_voxels"] = static_cast<double>(voxels);
}
BENCHMARK(BM_StockSubtractBallPass)->Arg(10)->Arg(5)->Unit(benchmark::kMillisecond);

// The deviation query: signed distance to a target mesh at points near its
// surface, as the comparison asks it at every machined vertex. The target is
// a height field of 2 x range(0)^2 triangles (a wavy 1 x 1 mm face on a block).
void BM_DeviationQuery(benchmark::State& state) {
  const int n = static_cast<int>(state.range(0));
  std::vector<double> xs;
  for (int i = 0; i <= n; ++i) xs.push_back(static_cast<double>(i) / n);
  const auto wave = [](double x, double y) { return 0.01 * std::sin(20 * x) * std::cos(15 * y); };
  const compare::Target target(cases::height_field_solid(xs, xs, wave, -1));
  std::uint64_t k = 0;
  for (auto _ : state) {
    // A low-discrepancy walk over the face, 1 um above or below it.
    const double x = std::fmod(0.5 + 0.6180339887 * static_cast<double>(k), 1.0);
    const double y = std::fmod(0.5 + 0.7548776662 * static_cast<double>(k), 1.0);
    const double dz = (k & 1) ? 0.001 : -0.001;
    benchmark::DoNotOptimize(target.signed_distance_within(Vec3(x, y, wave(x, y) + dz), 0.01));
    ++k;
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_DeviationQuery)->Arg(100)->Arg(1000);

// The comparison's voxel queries: four points a voxel apart (0.5 um) ask
// for the surface within 1.5 voxels over the triangles near them, as an
// eighth's voxels do, one query each (0) or four at a time (1: with AVX2
// where the CPU has it). The wavy face of 2 x 400^2 triangles; the points
// lie within a few voxels of it, some finding it and some not.
void BM_VoxelQueries(benchmark::State& state) {
  const bool together = state.range(0) == 1;
  std::vector<double> xs;
  for (int i = 0; i <= 400; ++i) xs.push_back(static_cast<double>(i) / 400);
  const auto wave = [](double x, double y) { return 0.01 * std::sin(20 * x) * std::cos(15 * y); };
  const compare::Target target(cases::height_field_solid(xs, xs, wave, -1));
  const double h = 0.0005;
  struct Place {
    double px[4], py[4], pz[4];
    std::vector<unsigned> near;
  };
  std::vector<Place> places(256);
  for (std::size_t k = 0; k < places.size(); ++k) {
    const double x = std::fmod(0.5 + 0.6180339887 * static_cast<double>(k), 1.0);
    const double y = std::fmod(0.5 + 0.7548776662 * static_cast<double>(k), 1.0);
    const double z = wave(x, y) + h * (static_cast<double>(k % 7) - 3);
    Place& p = places[k];
    for (int i = 0; i < 4; ++i) {
      p.px[i] = x + h * (i & 1);
      p.py[i] = y + h * (i >> 1);
      p.pz[i] = z;
    }
    target.triangles_near(Vec3(x + 0.5 * h, y + 0.5 * h, z), 2.5 * h, p.near);
  }
  std::size_t k = 0;
  double out[4];
  for (auto _ : state) {
    const Place& p = places[k++ % places.size()];
    if (together) target.signed_distances_if_within(4, p.px, p.py, p.pz, 1.5 * h, p.near, out);
    else target.signed_distances_if_within_scalar(4, p.px, p.py, p.pz, 1.5 * h, p.near, out);
    benchmark::DoNotOptimize(out);
  }
  state.SetItemsProcessed(4 * static_cast<std::int64_t>(state.iterations()));
}
BENCHMARK(BM_VoxelQueries)->Arg(0)->Arg(1);

}  // namespace

BENCHMARK_MAIN();
