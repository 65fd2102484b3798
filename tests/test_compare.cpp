// Comparison with the target: overcut and undercut against closed forms,
// their positions, a mesh with a hole refused, the coloured glb read back.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <random>
#include <tuple>

#include <nlohmann/json.hpp>
#include <tiny_gltf.h>

#include "cutsim/compare/compare.h"
#include "cutsim/core/error.h"
#include "cutsim/io/mesh_io.h"
#include "helpers.h"

namespace cutsim::test {
namespace {

// A 6 x 4 x 1 mm block (x 0..6, y -2..2, z -1..0) with a slot 2 mm wide and
// 0.1 mm deep along X: the U profile in (y, z) extruded along x.
TriMesh slotted_block() {
  const std::vector<std::array<double, 2>> prof = {{-2, -1}, {2, -1}, {2, 0}, {1, 0}, {1, -0.1}, {-1, -0.1}, {-1, 0}, {-2, 0}};
  const std::vector<std::array<std::uint32_t, 3>> cap = {{0, 1, 4}, {0, 4, 5}, {1, 2, 3}, {1, 3, 4}, {0, 5, 6}, {0, 6, 7}};
  TriMesh m;
  const auto n = static_cast<std::uint32_t>(prof.size());
  for (double x : {0.0, 6.0})
    for (const auto& p : prof) m.positions.emplace_back(x, p[0], p[1]);
  for (const auto& t : cap) {
    m.triangles.push_back({t[0], t[2], t[1]});              // x = 0, facing -x
    m.triangles.push_back({n + t[0], n + t[1], n + t[2]});  // x = 6, facing +x
  }
  for (std::uint32_t i = 0; i < n; ++i) {
    const std::uint32_t j = (i + 1) % n;
    m.triangles.push_back({i, j, n + j});
    m.triangles.push_back({i, n + j, n + i});
  }
  if (m.signed_volume() < 0)
    for (auto& t : m.triangles) std::swap(t[1], t[2]);
  return m;
}

std::string write_stl(const TempDir& dir, const TriMesh& m, const std::string& name) {
  std::string s = "solid t\n";
  for (const auto& t : m.triangles) {
    s += "facet normal 0 0 0\nouter loop\n";
    for (int k = 0; k < 3; ++k) {
      const Vec3& p = m.positions[t[static_cast<std::size_t>(k)]];
      s += "vertex " + std::to_string(p.x()) + " " + std::to_string(p.y()) + " " + std::to_string(p.z()) + "\n";
    }
    s += "endloop\nendfacet\n";
  }
  return dir.write(name, s + "endsolid t\n");
}

struct SlotRun {
  nlohmann::json report;
  std::string glb;
};

// The slot cut with a 2 mm flat end mill, `first_depth` deep up to X3 and
// 0.1 mm deep from there on.
SlotRun cut_slot(const TempDir& dir, double first_depth) {
  const auto target = write_stl(dir, slotted_block(), "target.stl");
  const std::string prog = "G0 X-2 Y0 Z1\nG1 Z" + std::to_string(-first_depth) +
                           " F100\nG1 X3\nG1 Z-0.1\nG1 X8\nG0 Z1\n";
  const auto p = dir.write("slot.nc", prog);
  std::string out, err;
  const int code = run_cli("run " + p + " --tool flat:d=2 --stock-box 0,-2,-1,6,2,0 --voxel 0.005 --target " + target +
                               " --tolerance 0.001 --format json -o " + dir.file("out"),
                           &out, &err);
  EXPECT_EQ(code, 0) << err;
  SlotRun r;
  r.report = nlohmann::json::parse(out);
  r.glb = dir.file("out/slot.glb");
  return r;
}

// Accuracy: the deviation region is a 5 um slab between planar faces on
// voxel planes; we allow 0.05 h per mm^2 of its top and bottom faces.
constexpr double kH = 0.005;
constexpr double kFootprint = 2 * 3 + kPi / 2;  // deep stretch in the block: 2 x 3 mm plus the half disk

TEST(Compare, SlotCutTooDeepOverHalfItsLengthIsOvercutOfTheClosedForm) {
  TempDir dir;
  const SlotRun r = cut_slot(dir, 0.105);
  const double exact = 0.005 * kFootprint;
  EXPECT_NEAR(r.report["overcut_volume_mm3"].get<double>(), exact, 0.05 * kH * 2 * kFootprint);
  EXPECT_LT(r.report["undercut_volume_mm3"].get<double>(), 0.05 * kH * 2 * kFootprint);
  EXPECT_NEAR(r.report["max_overcut_mm"].get<double>(), 0.005, kH / 4);
  EXPECT_NEAR(r.report["overcut_volume_um3"].get<double>(), r.report["overcut_volume_mm3"].get<double>() * 1e9, 1e-3);

  // Where: the overcut vertices are on the deep stretch (x < 4), none beyond.
  tinygltf::Model model;
  tinygltf::TinyGLTF loader;
  std::string err, warn;
  ASSERT_TRUE(loader.LoadBinaryFromFile(&model, &err, &warn, r.glb)) << err;
  const auto& node = model.nodes[model.nodes[0].children[0]];
  const auto& prim = model.meshes[node.mesh].primitives[0];
  auto floats = [&](const std::string& attr) {
    const auto& acc = model.accessors[prim.attributes.at(attr)];
    const auto& view = model.bufferViews[acc.bufferView];
    return reinterpret_cast<const float*>(model.buffers[view.buffer].data.data() + view.byteOffset + acc.byteOffset);
  };
  const std::size_t n = model.accessors[prim.attributes.at("POSITION")].count;
  const float* pos = floats("POSITION");
  const float* dev = floats("_DEVIATION");
  const float* col = floats("COLOR_0");
  int over = 0;
  double most = 0;
  for (std::size_t i = 0; i < n; ++i) {
    most = std::min(most, static_cast<double>(dev[i]));
    if (dev[i] < -0.004) {  // beyond the ~0.66 h rounding of sharp block edges
      ++over;
      const double x_mm = (node.translation[0] + pos[3 * i]) * 1000;
      EXPECT_LT(x_mm, 4.01) << "overcut at x = " << x_mm;
      EXPECT_GT(col[4 * i], 2 * col[4 * i + 1]) << "overcut vertices are red";
      EXPECT_GT(col[4 * i], 2 * col[4 * i + 2]);
    }
  }
  EXPECT_GT(over, 100);
  EXPECT_NEAR(-most, r.report["max_overcut_mm"].get<double>(), 1e-6) << "the attribute matches the report";

  // The overcut region is its own node: a thin slab under the deep stretch.
  const tinygltf::Node* oc = nullptr;
  for (int c : model.nodes[0].children)
    if (model.nodes[c].name == "overcut") oc = &model.nodes[c];
  ASSERT_NE(oc, nullptr);
  const auto& oprim = model.meshes[oc->mesh].primitives[0];
  const auto& oacc = model.accessors[oprim.attributes.at("POSITION")];
  const auto& oview = model.bufferViews[oacc.bufferView];
  const float* op = reinterpret_cast<const float*>(model.buffers[oview.buffer].data.data() + oview.byteOffset + oacc.byteOffset);
  const auto& iacc = model.accessors[oprim.indices];
  const auto& iview = model.bufferViews[iacc.bufferView];
  const auto* idx = reinterpret_cast<const std::uint32_t*>(model.buffers[iview.buffer].data.data() + iview.byteOffset + iacc.byteOffset);
  auto vertex = [&](std::uint32_t i) -> Vec3 {
    return Vec3(oc->translation[0] + op[3 * i], oc->translation[1] + op[3 * i + 1], oc->translation[2] + op[3 * i + 2]) * 1000;
  };
  // A thin slab: its area is about twice its footprint, its area-weighted
  // centre under the deep stretch (x 0..4, y 0, z between the floors).
  double area = 0;
  Vec3 centre = Vec3::Zero();
  for (std::size_t t = 0; t + 2 < iacc.count; t += 3) {
    const Vec3 a = vertex(idx[t]), b = vertex(idx[t + 1]), c = vertex(idx[t + 2]);
    const double ar = 0.5 * (b - a).cross(c - a).norm();
    area += ar;
    centre += ar * (a + b + c) / 3;
  }
  centre /= area;
  EXPECT_NEAR(area, 2 * kFootprint, 0.2 * 2 * kFootprint);
  EXPECT_NEAR(centre.x(), (2 * 3 * 1.5 + kPi / 2 * (3 + 4 / (3 * kPi))) / kFootprint, 0.1);
  EXPECT_NEAR(centre.y(), 0, 0.05);
  EXPECT_NEAR(centre.z(), -0.1025, 2 * kH);

  // Khronos' validator on the coloured file.
  const std::string cmd = "cd " + std::string(CUTSIM_GLTF_VALIDATOR_DIR) + " && node " + CUTSIM_SOURCE_DIR +
                          "/tests/tools/validate_gltf.mjs " + r.glb;
  std::string vout;
  EXPECT_EQ(run_cli_raw(cmd, &vout), 0) << vout;
  EXPECT_NE(vout.find(": 0 errors"), std::string::npos) << vout;
}

// Large regions are drawn on a coarser grid; the volumes stay the voxels'.
// A UV sphere of radius 1: `rings` bands of `segs` quads, closed, outward.
TriMesh uv_sphere(int rings, int segs) {
  TriMesh m;
  m.positions.emplace_back(0, 0, 1);
  for (int i = 1; i < rings; ++i) {
    const double th = kPi * i / rings;
    for (int j = 0; j < segs; ++j) {
      const double ph = 2 * kPi * j / segs;
      m.positions.emplace_back(std::sin(th) * std::cos(ph), std::sin(th) * std::sin(ph), std::cos(th));
    }
  }
  m.positions.emplace_back(0, 0, -1);
  const auto ring = [&](int i, int j) { return static_cast<std::uint32_t>(1 + (i - 1) * segs + (j % segs)); };
  const auto south = static_cast<std::uint32_t>(m.positions.size() - 1);
  for (int j = 0; j < segs; ++j) {
    m.triangles.push_back({0, ring(1, j), ring(1, j + 1)});
    m.triangles.push_back({south, ring(rings - 1, j + 1), ring(rings - 1, j)});
    for (int i = 1; i + 1 < rings; ++i) {
      m.triangles.push_back({ring(i, j), ring(i + 1, j), ring(i + 1, j + 1)});
      m.triangles.push_back({ring(i, j), ring(i + 1, j + 1), ring(i, j + 1)});
    }
  }
  if (m.signed_volume() < 0)
    for (auto& t : m.triangles) std::swap(t[1], t[2]);
  return m;
}

// The comparison searches the mesh once per block and tries only the
// triangles near it for each voxel's query: the answers must be the whole
// mesh's, where the near set's ball holds the query's.
TEST(Compare, NearTrianglesAnswerAsTheWholeMesh) {
  const compare::Target target(uv_sphere(96, 192));
  const std::size_t all = target.mesh().triangles.size();
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1, 1);
  std::vector<unsigned> near, sub;
  std::size_t found = 0, largest = 0, smaller = 0;
  for (int k = 0; k < 20000; ++k) {
    Vec3 dir(u(rng), u(rng), u(rng));
    if (dir.norm() < 0.1) continue;
    // Balls of several facets (each about 0.03 across), so that a set
    // missing the far ones would show.
    const Vec3 p = dir.normalized() * (1 + 0.1 * u(rng));
    const double r = 0.02 + 0.05 * (u(rng) + 1);
    const Vec3 c = p + 0.1 * Vec3(u(rng), u(rng), u(rng));
    target.triangles_near(c, (p - c).norm() + r, near);
    largest = std::max(largest, near.size());
    const auto whole = target.signed_distance_if_within(p, r);
    const auto local = target.signed_distance_if_within(p, r, near);
    ASSERT_EQ(whole.has_value(), local.has_value()) << "at (" << p.transpose() << "), r " << r;
    if (!whole) continue;
    ++found;
    ASSERT_EQ(*local, *whole) << "at (" << p.transpose() << "), r " << r;
    // The set for the query's own ball, taken from the larger one (as a
    // voxel quarter's from its block's): triangle by triangle, so smaller.
    target.triangles_near(p, r, near, sub);
    ASSERT_LE(sub.size(), near.size());
    const auto own = target.signed_distance_if_within(p, r, sub);
    ASSERT_TRUE(own.has_value()) << "at (" << p.transpose() << "), r " << r;
    ASSERT_EQ(*own, *whole) << "at (" << p.transpose() << "), r " << r;
    smaller += sub.size() < near.size();
    // The distance to a sphere of 192 x 96 facets: within its sagitta.
    EXPECT_NEAR(*whole, p.norm() - 1, 1e-3);
  }
  EXPECT_GT(found, 10000u);
  EXPECT_GT(smaller, found / 2) << "a smaller ball inside should keep fewer triangles";
  EXPECT_LT(largest, all / 10) << "the near set should be a small part of the mesh";
}

// The comparison asks an eighth's voxels four at a time
// (signed_distances_if_within): the same bits as one query each, found or
// not, on a fine sphere and on a coarse one (whose large facets put many
// points nearest an edge or a corner, where the sign comes from the
// pseudonormals), and about the slotted block's edges and corners
// (concave ones too), for groups of 1 to 4 points about as far apart as an
// eighth's voxels.
TEST(Compare, BatchQueriesGiveTheBitsOfOneQueryEach) {
  std::mt19937 rng(19);
  std::uniform_real_distribution<double> u(-1, 1);
  std::size_t found = 0, missed = 0, inside = 0;
  for (int mesh = 0; mesh < 3; ++mesh) {
    const compare::Target target(mesh == 0 ? uv_sphere(96, 192) : mesh == 1 ? uv_sphere(5, 8) : slotted_block());
    std::vector<unsigned> near;
    for (int k = 0; k < 5000; ++k) {
      Vec3 dir(u(rng), u(rng), u(rng));
      if (dir.norm() < 0.1) continue;
      // On the block: along the slot's edges (y +-1 at its floor and its
      // top) and past the block's ends.
      const Vec3 c = mesh < 2 ? Vec3(dir.normalized() * (1 + 0.05 * u(rng)))
                              : Vec3(k % 5 == 0 ? 3 + 3.05 * (u(rng) > 0 ? 1 : -1) : 3 + 2.9 * u(rng),
                                     (u(rng) > 0 ? 1 : -1) * (1 + 0.05 * u(rng)), (u(rng) > 0 ? 0.0 : -0.1) + 0.05 * u(rng));
      const double r = 0.01 + 0.02 * (u(rng) + 1), spread = 0.01;
      target.triangles_near(c, r + 2 * spread, near);
      const int n = 1 + k % 4;
      double px[4], py[4], pz[4], portable[4], dispatched[4], wide[4];
      for (int i = 0; i < n; ++i) {
        px[i] = c.x() + spread * u(rng);
        py[i] = c.y() + spread * u(rng);
        pz[i] = c.z() + spread * u(rng);
      }
      target.signed_distances_if_within_scalar(n, px, py, pz, r, near, portable);
      target.signed_distances_if_within(n, px, py, pz, r, near, dispatched);
      ASSERT_EQ(0, std::memcmp(portable, dispatched, sizeof(double) * static_cast<std::size_t>(n))) << k;
      if (__builtin_cpu_supports("avx2")) {
        target.signed_distances_if_within_avx2(n, px, py, pz, r, near, wide);
        for (int i = 0; i < n; ++i)
          ASSERT_EQ(0, std::memcmp(&portable[i], &wide[i], sizeof(double)))
              << "query " << k << ", point " << i << ": " << portable[i] << " against " << wide[i];
      }
      for (int i = 0; i < n; ++i) {
        const auto one = target.signed_distance_if_within(Vec3(px[i], py[i], pz[i]), r, near);
        ASSERT_EQ(one.has_value(), !std::isnan(portable[i]));
        if (!one) {
          ++missed;
          continue;
        }
        ASSERT_EQ(0, std::memcmp(&*one, &portable[i], sizeof(double)));
        ++found;
        inside += *one < 0;
      }
    }
  }
  EXPECT_GT(found, 15000u);
  EXPECT_GT(missed, 1000u);
  EXPECT_GT(inside, 5000u);
}

// Where every triangle near a ball lies in one plane (the slotted block's
// top, slot floor, walls), the comparison takes the plane's distance for
// the surface's within the ball: clamped to the ball's edge, they must
// agree; near an edge of the slot the triangles are not coplanar.
TEST(Compare, FlatStretchesTakeThePlaneDistance) {
  const compare::Target target(slotted_block());
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<unsigned> near;
  int planar = 0, not_planar = 0, checked = 0;
  for (int k = 0; k < 4000; ++k) {
    const Vec3 c(0.5 + 5 * u(rng), -2.2 + 4.4 * u(rng), -0.3 + 0.5 * u(rng));
    const double big = 0.01 + 0.4 * u(rng);
    target.triangles_near(c, big, near);
    const auto plane = target.common_plane(near);
    if (near.empty()) {
      ASSERT_FALSE(plane);
      continue;
    }
    if (!plane) {
      ++not_planar;
      continue;
    }
    ++planar;
    ASSERT_NEAR(plane->n.norm(), 1.0, 1e-12);
    for (int i = 0; i < 20; ++i) {
      Vec3 d(u(rng) - 0.5, u(rng) - 0.5, u(rng) - 0.5);
      const Vec3 p = c + d.normalized() * big * u(rng);
      const double rho = big - (p - c).norm();
      const double want = std::clamp(target.signed_distance(p), -rho, rho);
      const double got = std::clamp(plane->signed_distance(p), -rho, rho);
      ASSERT_NEAR(got, want, 1e-12) << "at (" << p.transpose() << "), ball (" << c.transpose() << ") " << big;
      ++checked;
    }
  }
  EXPECT_GT(planar, 500);
  EXPECT_GT(not_planar, 500);
  EXPECT_GT(checked, 10000);
}

TEST(Compare, CoarseRegionMeshesKeepTheVolumesAndCoverTheFineRegion) {
  TempDir dir;
  auto r = run_program(dir, "G0 X-2 Y0 Z1\nG1 Z-0.105 F100\nG1 X3\nG1 Z-0.1\nG1 X8\nG0 Z1\n", "flat:d=2",
                       Aabb{Vec3(0, -2, -1), Vec3(6, 2, 0)}, kH);
  const compare::Target target(slotted_block());
  const TriMesh machined = r.stock->surface_mesh();
  const compare::CompareResult fine = compare::compare(*r.stock, target, machined, {0.001});
  compare::CompareOptions coarse_opt{0.001};
  coarse_opt.region_block_budget = 1;  // every region is "large": the coarsest grid, 8 voxels
  const compare::CompareResult coarse = compare::compare(*r.stock, target, machined, coarse_opt);
  EXPECT_DOUBLE_EQ(fine.region_mesh_voxel_mm, kH);
  EXPECT_DOUBLE_EQ(coarse.region_mesh_voxel_mm, 8 * kH);
  EXPECT_EQ(coarse.overcut_volume_mm3, fine.overcut_volume_mm3);
  EXPECT_EQ(coarse.undercut_volume_mm3, fine.undercut_volume_mm3);
  EXPECT_NEAR(fine.overcut_volume_mm3, 0.005 * kFootprint, 0.05 * kH * 2 * kFootprint);
  // Drawn coarse, the region moves by less than a cell (8 voxels; 0.74 cell
  // measured): each mesh's vertices (a sample) lie near the other's, both ways.
  ASSERT_FALSE(coarse.overcut_mesh.triangles.empty());
  auto nearest = [](const Vec3& p, const TriMesh& m) {
    double best = 1e300;
    for (const Vec3& q : m.positions) best = std::min(best, (q - p).squaredNorm());
    return std::sqrt(best);
  };
  const double cell = 8 * kH;
  for (std::size_t i = 0; i < fine.overcut_mesh.positions.size(); i += 97)
    ASSERT_LT(nearest(fine.overcut_mesh.positions[i], coarse.overcut_mesh), cell) << "fine vertex " << i;
  for (std::size_t i = 0; i < coarse.overcut_mesh.positions.size(); i += 97)
    ASSERT_LT(nearest(coarse.overcut_mesh.positions[i], fine.overcut_mesh), cell) << "coarse vertex " << i;
  EXPECT_LT(coarse.overcut_mesh.positions.size(), fine.overcut_mesh.positions.size() / 4);
}

// The region meshes merged as the machined surface is (flat stretches of a
// region's faces into larger polygons): the same volumes, still closed,
// enclosing what the unmerged mesh does, each vertex on the unmerged
// surface's cells, and far fewer of them. The slot's floor 5 um (a voxel)
// too deep up to X3 and its walls make the overcut region.
TEST(Compare, MergedRegionMeshesAreClosedOnTheUnmergedSurfaceAndSmaller) {
  TempDir dir;
  auto r = run_program(dir, "G0 X-2 Y0 Z1\nG1 Z-0.105 F100\nG1 X3\nG1 Z-0.1\nG1 X4.5\nG1 Z-0.095\nG1 X8\nG0 Z1\n",
                       "flat:d=2", Aabb{Vec3(0, -2, -1), Vec3(6, 2, 0)}, kH);
  const compare::Target target(slotted_block());
  const TriMesh machined = r.stock->surface_mesh();
  compare::CompareOptions plain_opt{0.001};
  plain_opt.region_mesh_adaptivity = 0;
  const compare::CompareResult plain = compare::compare(*r.stock, target, machined, plain_opt);
  const compare::CompareResult merged = compare::compare(*r.stock, target, machined, {0.001});
  EXPECT_EQ(merged.overcut_volume_mm3, plain.overcut_volume_mm3);
  EXPECT_EQ(merged.undercut_volume_mm3, plain.undercut_volume_mm3);
  EXPECT_NEAR(plain.overcut_volume_mm3, 0.005 * kFootprint, 0.05 * kH * 2 * kFootprint);
  for (const auto& [name, a, b] : {std::tuple{"overcut", &plain.overcut_mesh, &merged.overcut_mesh},
                                   std::tuple{"undercut", &plain.undercut_mesh, &merged.undercut_mesh}}) {
    ASSERT_FALSE(a->triangles.empty()) << name;
    EXPECT_TRUE(edges_matched(*a)) << name;
    EXPECT_TRUE(edges_matched(*b)) << name;
    // (Each region's mesh lies at +h/4 around its voxels: a slab of the
    // footprint and some h thick.)
    EXPECT_GT(a->signed_volume(), 0) << name;
    EXPECT_NEAR(b->signed_volume(), a->signed_volume(), 0.01 * a->signed_volume()) << name;
    EXPECT_LT(b->positions.size(), a->positions.size() / 2) << name;
    // Every merged vertex (a sample) lies within a voxel of an unmerged one.
    double worst = 0;
    for (std::size_t i = 0; i < b->positions.size(); i += 41) {
      double best = 1e300;
      for (const Vec3& q : a->positions) best = std::min(best, (q - b->positions[i]).squaredNorm());
      worst = std::max(worst, std::sqrt(best));
    }
    EXPECT_LT(worst, kH) << name;
  }
}

// A target whose surface is nowhere near the region of interest (a block
// whose top is 0.5 mm down): every block's sign comes from one unbounded
// query and the flood, and all the stock left in the region is undercut.
TEST(Compare, TargetFarBelowTheCutMakesAllTheStockInTheRegionUndercut) {
  TempDir dir;
  auto r = run_program(dir, "G0 X-2 Y0 Z1\nG1 Z-0.1 F100\nG1 X8\nG0 Z1\n", "flat:d=2", Aabb{Vec3(0, -2, -1), Vec3(6, 2, 0)},
                       kH);
  TriMesh block;
  for (int i = 0; i < 8; ++i) block.positions.emplace_back(i & 1 ? 10 : -10, i & 2 ? 10 : -10, i & 4 ? -0.5 : -10);
  block.triangles = {{0, 2, 1}, {1, 2, 3}, {4, 5, 6}, {5, 7, 6}, {0, 1, 4}, {1, 5, 4},
                     {2, 6, 3}, {3, 6, 7}, {0, 4, 2}, {2, 4, 6}, {1, 3, 5}, {3, 7, 5}};
  if (block.signed_volume() < 0)
    for (auto& t : block.triangles) std::swap(t[1], t[2]);
  const Aabb roi = r.stock->roi();
  ASSERT_GT(roi.min.z(), -0.5 + 0.1) << "the region must stay clear of the target's top";
  const compare::Target target(std::move(block));
  const compare::CompareResult c = compare::compare(*r.stock, target, r.stock->surface_mesh(), {0.001});
  const Aabb in_stock = roi.intersected(r.stock->box());
  const double left = in_stock.volume() - 2.0 * 6.0 * 0.1;  // the region's stock less the slot through it
  EXPECT_EQ(c.overcut_volume_mm3, 0.0);
  EXPECT_NEAR(c.undercut_volume_mm3, left, 0.05 * kH * 2 * in_stock.size().x() * in_stock.size().y());
}

TEST(Compare, SlotCutTooShallowOverHalfItsLengthIsUndercutOfTheClosedForm) {
  TempDir dir;
  const SlotRun r = cut_slot(dir, 0.095);
  // The full-depth pass starts at X3 and clears the half disk behind it.
  const double exact = 0.005 * (2 * 3 - kPi / 2);
  EXPECT_NEAR(r.report["undercut_volume_mm3"].get<double>(), exact, 0.05 * kH * 2 * kFootprint);
  EXPECT_LT(r.report["overcut_volume_mm3"].get<double>(), 0.05 * kH * 2 * kFootprint);
  EXPECT_NEAR(r.report["max_undercut_mm"].get<double>(), 0.005, kH / 4);
}

TEST(Compare, TargetWithAHoleIsRefusedBeforeSimulating) {
  TempDir dir;
  TriMesh m = slotted_block();
  m.triangles.pop_back();
  const auto target = write_stl(dir, m, "holed.stl");
  const auto p = dir.write("p.nc", "G0 X0 Y0 Z1\nG1 Z-0.1 F100\n");
  std::string err;
  EXPECT_EQ(run_cli("run " + p + " --stock-box 0,-2,-1,6,2,0 --target " + target + " -o " + dir.file("out"), nullptr, &err),
            65);
  EXPECT_NE(err.find("holed.stl: error: the target mesh is not a closed"), std::string::npos) << err;
  EXPECT_NE(err.find("3 open edges"), std::string::npos) << err;
  EXPECT_TRUE(!std::filesystem::exists(dir.file("out")) || std::filesystem::is_empty(dir.file("out")));
}

TEST(Compare, TargetThatMissesTheStockIsRefusedBeforeSimulating) {
  TempDir dir;
  TriMesh m = slotted_block();
  for (auto& p : m.positions) p.x() += 100;  // placed 100 mm off
  const auto target = write_stl(dir, m, "far.stl");
  const auto p = dir.write("p.nc", "G0 X0 Y0 Z1\nG1 Z-0.1 F100\n");
  std::string err;
  EXPECT_EQ(run_cli("run " + p + " --stock-box 0,-2,-1,6,2,0 --target " + target + " -o " + dir.file("out"), nullptr, &err),
            65);
  EXPECT_NE(err.find("far.stl: error: the target (100,-2,-1,106,2,0 mm) does not overlap the stock"), std::string::npos) << err;
  EXPECT_TRUE(!std::filesystem::exists(dir.file("out")) || std::filesystem::is_empty(dir.file("out")));
}

TEST(Compare, MeshFormatsLoadTheSameSolid) {
  TempDir dir;
  const TriMesh m = slotted_block();
  const double v = m.signed_volume();
  EXPECT_NEAR(v, 6 * (4 * 1 - 2 * 0.1), 1e-12);
  EXPECT_NEAR(io::load_mesh(write_stl(dir, m, "a.stl")).signed_volume(), v, 1e-9);
  std::string obj, ply = "ply\nformat ascii 1.0\nelement vertex " + std::to_string(m.positions.size()) +
                         "\nproperty float x\nproperty float y\nproperty float z\nelement face " +
                         std::to_string(m.triangles.size()) + "\nproperty list uchar int vertex_indices\nend_header\n";
  for (const auto& p : m.positions) {
    obj += "v " + std::to_string(p.x()) + " " + std::to_string(p.y()) + " " + std::to_string(p.z()) + "\n";
    ply += std::to_string(p.x()) + " " + std::to_string(p.y()) + " " + std::to_string(p.z()) + "\n";
  }
  for (const auto& t : m.triangles) {
    obj += "f " + std::to_string(t[0] + 1) + " " + std::to_string(t[1] + 1) + " " + std::to_string(t[2] + 1) + "\n";
    ply += "3 " + std::to_string(t[0]) + " " + std::to_string(t[1]) + " " + std::to_string(t[2]) + "\n";
  }
  EXPECT_NEAR(io::load_mesh(dir.write("a.obj", obj)).signed_volume(), v, 1e-9);
  EXPECT_NEAR(io::load_mesh(dir.write("a.ply", ply)).signed_volume(), v, 1e-9);
  EXPECT_TRUE(io::find_defects(io::load_mesh(dir.file("a.obj"))).closed());
  EXPECT_THROW(io::load_mesh(dir.write("a.xyz", "1 2 3\n")), ParseError);
}

}  // namespace
}  // namespace cutsim::test

namespace cutsim::test {

// `run --save-vdb` keeps the stock; `cutsim compare` on it gives the run's
// figures without simulating, and a closed mesh can be compared too.
TEST(Compare, SavedStockComparesAgainWithoutSimulating) {
  TempDir dir;
  const auto target = write_stl(dir, slotted_block(), "target.stl");
  const auto p = dir.write("slot.nc", "G0 X-2 Y0 Z1\nG1 Z-0.105 F100\nG1 X3\nG1 Z-0.1\nG1 X8\nG0 Z1\n");
  std::string out, err;
  ASSERT_EQ(run_cli("run " + p + " --tool flat:d=2 --stock-box 0,-2,-1,6,2,0 --voxel 0.01 --target " + target +
                        " --format json --save-vdb -o " + dir.file("out"),
                    &out, &err),
            0)
      << err;
  const auto run_report = nlohmann::json::parse(out);
  EXPECT_EQ(run_report["outputs"]["vdb"], dir.file("out/slot.vdb"));
  ASSERT_EQ(run_cli("compare " + dir.file("out/slot.vdb") + " " + target + " --format json -o " + dir.file("cmp"), &out,
                    &err),
            0)
      << err;
  const auto c = nlohmann::json::parse(out);
  EXPECT_DOUBLE_EQ(c["overcut_volume_mm3"].get<double>(), run_report["overcut_volume_mm3"].get<double>());
  EXPECT_DOUBLE_EQ(c["undercut_volume_mm3"].get<double>(), run_report["undercut_volume_mm3"].get<double>());
  EXPECT_NEAR(c["max_overcut_mm"].get<double>(), run_report["max_overcut_mm"].get<double>(), 1e-9);
  EXPECT_TRUE(std::filesystem::exists(dir.file("cmp/slot.compare.glb")));
  EXPECT_TRUE(std::filesystem::exists(dir.file("cmp/slot.compare.json")));

  // The target against itself, as a mesh: nothing over or under beyond the
  // voxel accuracy (0.05 h per mm^2 of its 50 mm^2 surface).
  ASSERT_EQ(run_cli("compare " + target + " " + target + " --voxel 0.01 --format json -o " + dir.file("cmp"), &out, &err), 0)
      << err;
  const auto self = nlohmann::json::parse(out);
  EXPECT_LT(self["overcut_volume_mm3"].get<double>(), 0.05 * 0.01 * 50);
  EXPECT_LT(self["undercut_volume_mm3"].get<double>(), 0.05 * 0.01 * 50);
  EXPECT_LT(self["max_overcut_mm"].get<double>(), 1e-6);

  // Not a stock: a clear error, no output.
  const auto bogus = dir.write("bogus.vdb", "not a grid");
  EXPECT_EQ(run_cli("compare " + bogus + " " + target + " -o " + dir.file("cmp2"), &out, &err), 65);
  EXPECT_NE(err.find("bogus.vdb: error: not a cutsim stock grid"), std::string::npos) << err;
  EXPECT_FALSE(std::filesystem::exists(dir.file("cmp2/bogus.compare.glb")));
}

}  // namespace cutsim::test
