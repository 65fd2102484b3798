#include "cutsim/io/gltf_writer.h"

#include <cstring>
#include <sstream>

#include <tiny_gltf.h>

#include "cutsim/core/error.h"
#include "cutsim/io/atomic_file.h"

namespace cutsim::io {

namespace {

constexpr double kMetresPerMm = 1e-3;

std::size_t append(std::vector<unsigned char>& buf, const void* data, std::size_t n) {
  while (buf.size() % 4) buf.push_back(0);
  const std::size_t off = buf.size();
  buf.resize(off + n);
  std::memcpy(buf.data() + off, data, n);
  return off;
}

int add_view(tinygltf::Model& m, std::size_t off, std::size_t len, int target) {
  tinygltf::BufferView v;
  v.buffer = 0;
  v.byteOffset = off;
  v.byteLength = len;
  v.target = target;
  m.bufferViews.push_back(v);
  return static_cast<int>(m.bufferViews.size() - 1);
}

}  // namespace

std::string glb_bytes(const std::vector<GltfPart>& parts, const GltfOptions& opt) {
  tinygltf::Model model;
  model.asset.version = "2.0";
  model.asset.generator = opt.generator;
  std::vector<unsigned char> buf;

  tinygltf::Node root;
  root.name = "cutsim_root (Z-up mm machine frame to Y-up metres)";
  root.rotation = {-std::sqrt(0.5), 0.0, 0.0, std::sqrt(0.5)};  // -90 deg about X
  if (opt.scale != 1.0) root.scale = {opt.scale, opt.scale, opt.scale};
  model.nodes.push_back(root);

  for (const GltfPart& part : parts) {
    if (!part.mesh || part.mesh->triangles.empty()) continue;
    const TriMesh& mesh = *part.mesh;
    const Aabb bb = mesh.bounds();
    const Vec3 local = bb.center();
    std::vector<float> pos;
    pos.reserve(mesh.positions.size() * 3);
    std::vector<double> lo(3, 1e300), hi(3, -1e300);
    for (const Vec3& p : mesh.positions)
      for (int k = 0; k < 3; ++k) {
        const float f = static_cast<float>((p[k] - local[k]) * kMetresPerMm);
        pos.push_back(f);
        lo[k] = std::min(lo[k], double(f));
        hi[k] = std::max(hi[k], double(f));
      }
    std::vector<float> nrm;
    const bool has_normals = mesh.normals.size() == mesh.positions.size();
    if (has_normals)
      for (const auto& n : mesh.normals) {
        Eigen::Vector3f u = n.norm() > 0 ? Eigen::Vector3f(n.normalized()) : Eigen::Vector3f(0, 0, 1);
        nrm.insert(nrm.end(), {u.x(), u.y(), u.z()});
      }
    std::vector<std::uint32_t> idx;
    idx.reserve(mesh.triangles.size() * 3);
    for (const auto& t : mesh.triangles) idx.insert(idx.end(), {t[0], t[1], t[2]});

    tinygltf::Primitive prim;
    prim.mode = TINYGLTF_MODE_TRIANGLES;
    {
      const std::size_t off = append(buf, pos.data(), pos.size() * sizeof(float));
      tinygltf::Accessor a;
      a.bufferView = add_view(model, off, pos.size() * sizeof(float), TINYGLTF_TARGET_ARRAY_BUFFER);
      a.componentType = TINYGLTF_COMPONENT_TYPE_FLOAT;
      a.count = mesh.positions.size();
      a.type = TINYGLTF_TYPE_VEC3;
      a.minValues = lo;
      a.maxValues = hi;
      model.accessors.push_back(a);
      prim.attributes["POSITION"] = static_cast<int>(model.accessors.size() - 1);
    }
    if (has_normals) {
      const std::size_t off = append(buf, nrm.data(), nrm.size() * sizeof(float));
      tinygltf::Accessor a;
      a.bufferView = add_view(model, off, nrm.size() * sizeof(float), TINYGLTF_TARGET_ARRAY_BUFFER);
      a.componentType = TINYGLTF_COMPONENT_TYPE_FLOAT;
      a.count = mesh.normals.size();
      a.type = TINYGLTF_TYPE_VEC3;
      model.accessors.push_back(a);
      prim.attributes["NORMAL"] = static_cast<int>(model.accessors.size() - 1);
    }
    auto add_attribute = [&](const std::string& name, const std::vector<float>& data, int type, std::size_t count) {
      const std::size_t off = append(buf, data.data(), data.size() * sizeof(float));
      tinygltf::Accessor a;
      a.bufferView = add_view(model, off, data.size() * sizeof(float), TINYGLTF_TARGET_ARRAY_BUFFER);
      a.componentType = TINYGLTF_COMPONENT_TYPE_FLOAT;
      a.count = count;
      a.type = type;
      model.accessors.push_back(a);
      prim.attributes[name] = static_cast<int>(model.accessors.size() - 1);
    };
    if (part.colors && part.colors->size() == mesh.positions.size()) {
      std::vector<float> c;
      c.reserve(4 * part.colors->size());
      for (const auto& v : *part.colors) c.insert(c.end(), v.begin(), v.end());
      add_attribute("COLOR_0", c, TINYGLTF_TYPE_VEC4, part.colors->size());
    }
    if (part.deviation_mm && part.deviation_mm->size() == mesh.positions.size())
      add_attribute("_DEVIATION", *part.deviation_mm, TINYGLTF_TYPE_SCALAR, part.deviation_mm->size());
    {
      const std::size_t off = append(buf, idx.data(), idx.size() * sizeof(std::uint32_t));
      tinygltf::Accessor a;
      a.bufferView = add_view(model, off, idx.size() * sizeof(std::uint32_t), TINYGLTF_TARGET_ELEMENT_ARRAY_BUFFER);
      a.componentType = TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT;
      a.count = idx.size();
      a.type = TINYGLTF_TYPE_SCALAR;
      model.accessors.push_back(a);
      prim.indices = static_cast<int>(model.accessors.size() - 1);
    }
    tinygltf::Material mat;
    mat.name = part.name;
    mat.pbrMetallicRoughness.baseColorFactor = {part.base_color[0], part.base_color[1],
                                                part.base_color[2], part.base_color[3]};
    if (part.colors) mat.pbrMetallicRoughness.baseColorFactor = {1, 1, 1, 1};  // COLOR_0 carries the colour
    mat.pbrMetallicRoughness.metallicFactor = 0.3;
    mat.pbrMetallicRoughness.roughnessFactor = 0.5;
    model.materials.push_back(mat);
    prim.material = static_cast<int>(model.materials.size() - 1);

    tinygltf::Mesh gm;
    gm.name = part.name;
    gm.primitives.push_back(prim);
    model.meshes.push_back(gm);

    tinygltf::Node node;
    node.name = part.name;
    node.mesh = static_cast<int>(model.meshes.size() - 1);
    node.translation = {local.x() * kMetresPerMm, local.y() * kMetresPerMm, local.z() * kMetresPerMm};
    if (!part.extras_text.empty() || !part.extras_number.empty()) {
      tinygltf::Value::Object ex;
      for (const auto& [k, v] : part.extras_text) ex[k] = tinygltf::Value(v);
      for (const auto& [k, v] : part.extras_number) ex[k] = tinygltf::Value(v);
      node.extras = tinygltf::Value(ex);
    }
    model.nodes.push_back(node);
    model.nodes[0].children.push_back(static_cast<int>(model.nodes.size() - 1));
  }
  while (buf.size() % 4) buf.push_back(0);
  tinygltf::Buffer b;
  b.data = std::move(buf);
  model.buffers.push_back(std::move(b));
  tinygltf::Value::Object units;
  units["length_unit"] = tinygltf::Value(std::string("metre"));
  units["source_frame"] = tinygltf::Value(std::string("machine workpiece frame, Z up, mm"));
  units["display_scale"] = tinygltf::Value(opt.scale);
  for (const auto& [k, v] : opt.extras_text) units[k] = tinygltf::Value(v);
  for (const auto& [k, v] : opt.extras_number) units[k] = tinygltf::Value(v);
  model.asset.extras = tinygltf::Value(units);

  tinygltf::Scene scene;
  scene.name = "cutsim";
  scene.nodes = {0};
  model.scenes.push_back(scene);
  model.defaultScene = 0;

  std::ostringstream os;
  tinygltf::TinyGLTF writer;
  if (!writer.WriteGltfSceneToStream(&model, os, false, true))
    throw OutputError("<glb>", "tinygltf could not serialise the model");
  return os.str();
}

void write_glb(const std::string& path, const std::vector<GltfPart>& parts, const GltfOptions& opt) {
  write_file_atomic(path, glb_bytes(parts, opt));
}

}  // namespace cutsim::io
