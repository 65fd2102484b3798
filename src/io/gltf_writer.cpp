// The .glb is written as it is produced: the JSON (which only needs the
// byte sizes) first, then each part's arrays converted to floats a slice at
// a time, so a mesh of millions of vertices costs no copy of itself.
#include "cutsim/io/gltf_writer.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <functional>

#include <nlohmann/json.hpp>

#include "cutsim/core/error.h"
#include "cutsim/io/atomic_file.h"

namespace cutsim::io {

namespace {

constexpr double kMetresPerMm = 1e-3;
constexpr int kArrayBuffer = 34962, kElementArrayBuffer = 34963;
constexpr int kFloat = 5126, kUnsignedInt = 5125;
constexpr std::size_t kSlice = 1 << 14;  // vertices converted per write

using Sink = std::function<void(const void*, std::size_t)>;
using json = nlohmann::ordered_json;

struct Layout {
  const GltfPart* part;
  Vec3 local;
  bool normals, colors, deviation;
};

bool has_normals(const TriMesh& m) { return m.normals.size() == m.positions.size(); }
bool has_colors(const GltfPart& p) { return p.colors && p.colors->size() == p.mesh->positions.size(); }
bool has_deviation(const GltfPart& p) { return p.deviation_mm && p.deviation_mm->size() == p.mesh->positions.size(); }

json extras_of(const std::vector<std::pair<std::string, std::string>>& text,
               const std::vector<std::pair<std::string, double>>& number) {
  json ex = json::object();
  for (const auto& [k, v] : text) ex[k] = v;
  for (const auto& [k, v] : number) ex[k] = v;
  return ex;
}

// Converts `n` items a slice at a time with `fill(i, out)` writing `per`
// floats (or uint32s) for item i.
template <typename T, typename Fill>
void stream(const Sink& out, std::size_t n, int per, Fill fill) {
  std::vector<T> buf;
  buf.reserve(kSlice * static_cast<std::size_t>(per));
  for (std::size_t start = 0; start < n; start += kSlice) {
    const std::size_t end = std::min(n, start + kSlice);
    buf.clear();
    for (std::size_t i = start; i < end; ++i) fill(i, buf);
    out(buf.data(), buf.size() * sizeof(T));
  }
}

void write_glb_to(const std::vector<GltfPart>& parts, const GltfOptions& opt, const Sink& out) {
  json j;
  json asset = {{"generator", opt.generator}, {"version", "2.0"}};
  json units = {{"length_unit", "metre"}, {"source_frame", "machine workpiece frame, Z up, mm"},
                {"display_scale", opt.scale}};
  for (const auto& [k, v] : opt.extras_text) units[k] = v;
  for (const auto& [k, v] : opt.extras_number) units[k] = v;
  asset["extras"] = units;
  j["asset"] = asset;
  j["scene"] = 0;
  j["scenes"] = json::array({{{"name", "cutsim"}, {"nodes", {0}}}});

  json root = {{"name", "cutsim_root (Z-up mm machine frame to Y-up metres)"},
               {"rotation", {-std::sqrt(0.5), 0.0, 0.0, std::sqrt(0.5)}}};  // -90 deg about X
  if (opt.scale != 1.0) root["scale"] = {opt.scale, opt.scale, opt.scale};
  json nodes = json::array(), meshes = json::array(), materials = json::array(), accessors = json::array(),
       views = json::array(), children = json::array();
  std::size_t offset = 0;
  auto add = [&](std::size_t count, const char* type, int component, std::size_t bytes, int target) {
    views.push_back({{"buffer", 0}, {"byteOffset", offset}, {"byteLength", bytes}, {"target", target}});
    offset += bytes;  // every array is 4-byte items: no padding between views
    accessors.push_back({{"bufferView", views.size() - 1}, {"componentType", component}, {"count", count}, {"type", type}});
    return accessors.size() - 1;
  };

  std::vector<Layout> layout;
  for (const GltfPart& part : parts) {
    if (!part.mesh || part.mesh->triangles.empty()) continue;
    const TriMesh& mesh = *part.mesh;
    Layout l{&part, mesh.bounds().center(), has_normals(mesh), has_colors(part), has_deviation(part)};
    const std::size_t nv = mesh.positions.size();
    json prim = {{"mode", 4}};
    {
      double lo[3] = {1e300, 1e300, 1e300}, hi[3] = {-1e300, -1e300, -1e300};
      for (const Vec3& p : mesh.positions)
        for (int k = 0; k < 3; ++k) {
          const double f = static_cast<float>((p[k] - l.local[k]) * kMetresPerMm);
          lo[k] = std::min(lo[k], f);
          hi[k] = std::max(hi[k], f);
        }
      const auto a = add(nv, "VEC3", kFloat, nv * 12, kArrayBuffer);
      accessors[a]["min"] = {lo[0], lo[1], lo[2]};
      accessors[a]["max"] = {hi[0], hi[1], hi[2]};
      prim["attributes"]["POSITION"] = a;
    }
    if (l.normals) prim["attributes"]["NORMAL"] = add(nv, "VEC3", kFloat, nv * 12, kArrayBuffer);
    if (l.colors) prim["attributes"]["COLOR_0"] = add(nv, "VEC4", kFloat, nv * 16, kArrayBuffer);
    if (l.deviation) prim["attributes"]["_DEVIATION"] = add(nv, "SCALAR", kFloat, nv * 4, kArrayBuffer);
    const std::size_t ni = 3 * mesh.triangles.size();
    prim["indices"] = add(ni, "SCALAR", kUnsignedInt, ni * 4, kElementArrayBuffer);

    json pbr = {{"baseColorFactor", l.colors ? std::array<float, 4>{1, 1, 1, 1} : part.base_color},  // COLOR_0 carries the colour
                {"metallicFactor", 0.3}, {"roughnessFactor", 0.5}};
    materials.push_back({{"name", part.name}, {"pbrMetallicRoughness", pbr}});
    prim["material"] = materials.size() - 1;
    meshes.push_back({{"name", part.name}, {"primitives", json::array({prim})}});
    json node = {{"mesh", meshes.size() - 1}, {"name", part.name},
                 {"translation", {l.local.x() * kMetresPerMm, l.local.y() * kMetresPerMm, l.local.z() * kMetresPerMm}}};
    if (!part.extras_text.empty() || !part.extras_number.empty())
      node["extras"] = extras_of(part.extras_text, part.extras_number);
    nodes.push_back(node);
    children.push_back(nodes.size());  // the root is node 0
    layout.push_back(l);
  }
  if (!children.empty()) root["children"] = children;
  nodes.insert(nodes.begin(), root);
  j["nodes"] = nodes;
  if (!meshes.empty()) {
    j["meshes"] = meshes;
    j["materials"] = materials;
    j["accessors"] = accessors;
    j["bufferViews"] = views;
    j["buffers"] = json::array({{{"byteLength", offset}}});
  }

  std::string text = j.dump();
  while (text.size() % 4) text.push_back(' ');
  const bool bin = offset > 0;
  const auto u32 = [](std::size_t v) {
    if (v > UINT32_MAX) throw OutputError("<glb>", "the model is larger than a .glb can hold (4 GB)");
    return static_cast<std::uint32_t>(v);
  };
  const std::uint32_t header[3] = {0x46546C67u, 2u, u32(12 + 8 + text.size() + (bin ? 8 + offset : 0))};
  out(header, sizeof header);
  const std::uint32_t json_chunk[2] = {u32(text.size()), 0x4E4F534Au};
  out(json_chunk, sizeof json_chunk);
  out(text.data(), text.size());
  if (!bin) return;
  const std::uint32_t bin_chunk[2] = {u32(offset), 0x004E4942u};
  out(bin_chunk, sizeof bin_chunk);
  for (const Layout& l : layout) {
    const TriMesh& mesh = *l.part->mesh;
    const std::size_t nv = mesh.positions.size();
    stream<float>(out, nv, 3, [&](std::size_t i, std::vector<float>& b) {
      for (int k = 0; k < 3; ++k) b.push_back(static_cast<float>((mesh.positions[i][k] - l.local[k]) * kMetresPerMm));
    });
    if (l.normals)
      stream<float>(out, nv, 3, [&](std::size_t i, std::vector<float>& b) {
        const Eigen::Vector3f& n = mesh.normals[i];
        const Eigen::Vector3f u = n.norm() > 0 ? Eigen::Vector3f(n.normalized()) : Eigen::Vector3f(0, 0, 1);
        b.insert(b.end(), {u.x(), u.y(), u.z()});
      });
    if (l.colors)
      stream<float>(out, nv, 4, [&](std::size_t i, std::vector<float>& b) {
        const auto& c = (*l.part->colors)[i];
        b.insert(b.end(), c.begin(), c.end());
      });
    if (l.deviation) out(l.part->deviation_mm->data(), nv * sizeof(float));
    stream<std::uint32_t>(out, mesh.triangles.size(), 3, [&](std::size_t i, std::vector<std::uint32_t>& b) {
      const auto& t = mesh.triangles[i];
      b.insert(b.end(), {t[0], t[1], t[2]});
    });
  }
}

}  // namespace

std::string glb_bytes(const std::vector<GltfPart>& parts, const GltfOptions& opt) {
  std::string s;
  write_glb_to(parts, opt, [&](const void* p, std::size_t n) { s.append(static_cast<const char*>(p), n); });
  return s;
}

void write_glb(const std::string& path, const std::vector<GltfPart>& parts, const GltfOptions& opt) {
  AtomicFile f(path);
  write_glb_to(parts, opt, [&](const void* p, std::size_t n) { f.write(p, n); });
  f.commit();
}

}  // namespace cutsim::io
