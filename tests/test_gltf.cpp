// The machined surface mesh and its .glb: closed, in metres, read back.
#include <cmath>

#include <tiny_gltf.h>

#include "cutsim/io/gltf_writer.h"
#include "helpers.h"

namespace cutsim::test {
namespace {

TEST(SurfaceMesh, EnclosesTheStockVolume) {
  TempDir dir;
  const double h = 0.01;
  auto r = run_program(dir, "G0 X0 Y0 Z1\nG1 Z-0.2 F100\nG1 X3\nG0 Z1\n", "ball:d=1",
                       Aabb{Vec3(-2, -2, -2), Vec3(5, 2, 0)}, h);
  const TriMesh mesh = r.stock->surface_mesh();
  // The grid part and the analytic faces meet on the ROI's planes, so the
  // mesh is closed and its divergence-theorem volume is the stock's; the
  // two estimates differ by the mesh's chords across curved voxels.
  const double cut_area = 3.41;  // mm^2, the slot's surface
  EXPECT_NEAR(mesh.signed_volume(), r.stock->volume_mm3(), 0.05 * h * cut_area);
  ASSERT_EQ(mesh.normals.size(), mesh.positions.size());
  for (const auto& n : mesh.normals) EXPECT_NEAR(n.norm(), 1.0f, 1e-5f);
  // Adaptive meshing (the default for the .glb) merges flat regions; its
  // merged polygons move the surface by up to about a tenth of a voxel.
  const TriMesh coarse = r.stock->surface_mesh(0.01);
  EXPECT_LT(coarse.triangles.size(), mesh.triangles.size() / 2);
  EXPECT_NEAR(coarse.signed_volume(), r.stock->volume_mm3(), 0.1 * h * cut_area);
  const Aabb b = mesh.bounds();
  EXPECT_NEAR(b.min.x(), -2, 1e-12);
  EXPECT_NEAR(b.max.z(), 0, 1e-6);
  EXPECT_NEAR(b.min.z(), -2, 1e-12);
}

TEST(Glb, ReadsBackInMetresYUpWithLocalOrigin) {
  TempDir dir;
  const double h = 0.01;
  auto r = run_program(dir, "G0 X20 Y30 Z1\nG1 Z-0.2 F100\nG1 X23\nG0 Z1\n", "ball:d=1",
                       Aabb{Vec3(18, 28, -2), Vec3(25, 32, 0)}, h);
  const TriMesh mesh = r.stock->surface_mesh();
  const std::string path = dir.file("m.glb");
  io::write_glb(path, {io::GltfPart{"machined_stock", &mesh}});

  tinygltf::Model model;
  tinygltf::TinyGLTF loader;
  std::string err, warn;
  ASSERT_TRUE(loader.LoadBinaryFromFile(&model, &err, &warn, path)) << err;
  ASSERT_EQ(model.scenes.size(), 1u);
  const tinygltf::Node& root = model.nodes[model.scenes[0].nodes[0]];
  ASSERT_EQ(root.rotation.size(), 4u);
  EXPECT_NEAR(root.rotation[0], -std::sqrt(0.5), 1e-12);  // -90 deg about X: Z up becomes Y up
  EXPECT_NEAR(root.rotation[3], std::sqrt(0.5), 1e-12);
  ASSERT_EQ(root.children.size(), 1u);
  const tinygltf::Node& node = model.nodes[root.children[0]];
  EXPECT_EQ(node.name, "machined_stock");
  const auto& prim = model.meshes[node.mesh].primitives[0];
  const auto& acc = model.accessors[prim.attributes.at("POSITION")];
  EXPECT_EQ(acc.count, mesh.positions.size());
  const auto& view = model.bufferViews[acc.bufferView];
  const float* p = reinterpret_cast<const float*>(model.buffers[view.buffer].data.data() + view.byteOffset + acc.byteOffset);
  // Vertices are metres relative to the node's translation.
  for (std::size_t i = 0; i < acc.count; i += 97) {
    for (int k = 0; k < 3; ++k) {
      const double mm = (node.translation[k] + p[3 * i + k]) * 1000.0;
      EXPECT_NEAR(mm, mesh.positions[i][k], 1e-6) << "vertex " << i;
    }
  }
  EXPECT_LT(std::fabs(acc.maxValues[0]), 0.01) << "local coordinates stay small";
  EXPECT_TRUE(prim.attributes.count("NORMAL"));
}

}  // namespace
}  // namespace cutsim::test
