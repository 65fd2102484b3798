#include "cutsim/io/mesh_io.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstring>
#include <fstream>
#include <sstream>
#include <unordered_map>

#include <tiny_gltf.h>

#include "cutsim/core/error.h"

namespace cutsim::io {

namespace {

std::string lower_ext(const std::string& path) {
  const auto dot = path.find_last_of('.');
  std::string e = dot == std::string::npos ? "" : path.substr(dot + 1);
  for (char& c : e) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return e;
}

std::string read_all(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path, "cannot open mesh file");
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// Builds an indexed mesh, merging vertices with identical coordinates.
struct Builder {
  TriMesh m;
  // Equal coordinates (as ==: 0 and -0 are one) are one vertex, the first
  // place it was given.
  struct Key {
    double x, y, z;
    bool operator==(const Key& o) const { return x == o.x && y == o.y && z == o.z; }
  };
  struct KeyHash {
    std::size_t operator()(const Key& k) const {
      auto bits = [](double v) {
        std::uint64_t u;
        v = v == 0 ? 0.0 : v;  // -0 hashes as 0
        std::memcpy(&u, &v, 8);
        return u;
      };
      std::uint64_t h = bits(k.x) * 0x9E3779B97F4A7C15ull;
      h = (h ^ (h >> 29) ^ bits(k.y)) * 0xBF58476D1CE4E5B9ull;
      h = (h ^ (h >> 32) ^ bits(k.z)) * 0x94D049BB133111EBull;
      return static_cast<std::size_t>(h ^ (h >> 31));
    }
  };
  std::unordered_map<Key, std::uint32_t, KeyHash> index;
  std::uint32_t vertex(const Vec3& p) {
    auto [it, fresh] = index.emplace(Key{p.x(), p.y(), p.z()}, static_cast<std::uint32_t>(m.positions.size()));
    if (fresh) m.positions.push_back(p);
    return it->second;
  }
  void tri(std::uint32_t a, std::uint32_t b, std::uint32_t c) { m.triangles.push_back({a, b, c}); }
};

[[noreturn]] void bad(const std::string& file, int line, const std::string& msg) {
  throw ParseError(SourceLocation{file, line, line ? 1 : 0, {}}, msg);
}

double finite_or_fail(double v, const std::string& file, int line) {
  if (!std::isfinite(v)) bad(file, line, "coordinate is not a finite number");
  return v;
}

TriMesh load_stl(const std::string& path, const std::string& data) {
  Builder b;
  const bool ascii_head = data.compare(0, 5, "solid") == 0;
  const bool binary_size_ok = data.size() >= 84 && [&] {
    std::uint32_t n;
    std::memcpy(&n, data.data() + 80, 4);
    return data.size() == 84 + 50ull * n;
  }();
  if (binary_size_ok || !ascii_head) {
    if (data.size() < 84) bad(path, 0, "binary STL shorter than its 84-byte header");
    std::uint32_t n;
    std::memcpy(&n, data.data() + 80, 4);
    if (data.size() < 84 + 50ull * n) bad(path, 0, "binary STL: " + std::to_string(n) + " triangles announced, file too short");
    for (std::uint32_t t = 0; t < n; ++t) {
      const char* rec = data.data() + 84 + 50ull * t + 12;
      std::uint32_t ids[3];
      for (int v = 0; v < 3; ++v) {
        float f[3];
        std::memcpy(f, rec + 12 * v, 12);
        ids[v] = b.vertex(Vec3(finite_or_fail(f[0], path, 0), finite_or_fail(f[1], path, 0), finite_or_fail(f[2], path, 0)));
      }
      b.tri(ids[0], ids[1], ids[2]);
    }
    return b.m;
  }
  std::istringstream in(data);
  std::string line, word;
  int line_no = 0;
  std::vector<std::uint32_t> loop;
  while (std::getline(in, line)) {
    ++line_no;
    std::istringstream ls(line);
    if (!(ls >> word)) continue;
    if (word == "vertex") {
      double x, y, z;
      if (!(ls >> x >> y >> z)) bad(path, line_no, "vertex needs three numbers");
      loop.push_back(b.vertex(Vec3(finite_or_fail(x, path, line_no), finite_or_fail(y, path, line_no),
                                   finite_or_fail(z, path, line_no))));
    } else if (word == "endloop") {
      if (loop.size() < 3) bad(path, line_no, "a facet needs three vertices");
      for (std::size_t i = 1; i + 1 < loop.size(); ++i) b.tri(loop[0], loop[i], loop[i + 1]);
      loop.clear();
    }
  }
  return b.m;
}

TriMesh load_obj(const std::string& path, const std::string& data) {
  Builder b;
  std::vector<Vec3> verts;
  std::istringstream in(data);
  std::string line;
  int line_no = 0;
  while (std::getline(in, line)) {
    ++line_no;
    std::istringstream ls(line);
    std::string tag;
    if (!(ls >> tag)) continue;
    if (tag == "v") {
      double x, y, z;
      if (!(ls >> x >> y >> z)) bad(path, line_no, "v needs three numbers");
      verts.emplace_back(finite_or_fail(x, path, line_no), finite_or_fail(y, path, line_no), finite_or_fail(z, path, line_no));
    } else if (tag == "f") {
      std::vector<std::uint32_t> ids;
      std::string tok;
      while (ls >> tok) {
        const long i = std::strtol(tok.c_str(), nullptr, 10);  // "7/1/3": the vertex index comes first
        const long n = static_cast<long>(verts.size());
        const long idx = i > 0 ? i - 1 : n + i;
        if (i == 0 || idx < 0 || idx >= n) bad(path, line_no, "face index " + tok + " out of range");
        ids.push_back(b.vertex(verts[static_cast<std::size_t>(idx)]));
      }
      if (ids.size() < 3) bad(path, line_no, "a face needs three vertices");
      for (std::size_t k = 1; k + 1 < ids.size(); ++k) b.tri(ids[0], ids[k], ids[k + 1]);
    }
  }
  return b.m;
}

TriMesh load_ply(const std::string& path, const std::string& data) {
  std::istringstream in(data);
  std::string line;
  int line_no = 0;
  std::getline(in, line);
  ++line_no;
  if (line.rfind("ply", 0) != 0) bad(path, 1, "not a PLY file");
  std::string format;
  std::size_t nv = 0, nf = 0;
  std::string element;
  std::vector<std::pair<std::string, std::string>> vprops;  // type, name
  std::string list_count_type, list_index_type;
  while (std::getline(in, line)) {
    ++line_no;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    std::istringstream ls(line);
    std::string w;
    ls >> w;
    if (w == "format") ls >> format;
    else if (w == "element") {
      std::size_t n;
      ls >> element >> n;
      if (element == "vertex") nv = n;
      else if (element == "face") nf = n;
      else if (n) bad(path, line_no, "unsupported PLY element '" + element + "'");
    } else if (w == "property") {
      std::string t;
      ls >> t;
      if (element == "vertex") {
        std::string name;
        ls >> name;
        vprops.emplace_back(t, name);
      } else if (element == "face") {
        if (t != "list") bad(path, line_no, "face property must be a list");
        std::string name;
        ls >> list_count_type >> list_index_type >> name;
      }
    } else if (w == "end_header") {
      break;
    }
  }
  if (format != "ascii" && format != "binary_little_endian") bad(path, line_no, "PLY format '" + format + "' is not supported");
  int ix = -1, iy = -1, iz = -1;
  for (std::size_t i = 0; i < vprops.size(); ++i) {
    if (vprops[i].second == "x") ix = static_cast<int>(i);
    if (vprops[i].second == "y") iy = static_cast<int>(i);
    if (vprops[i].second == "z") iz = static_cast<int>(i);
  }
  if (ix < 0 || iy < 0 || iz < 0) bad(path, line_no, "PLY vertices need x, y and z");
  // Every vertex and face takes at least two bytes: a count beyond that is a
  // lie, refused before anything is allocated for it.
  if (nv > data.size() / 2 || nf > data.size() / 2)
    bad(path, line_no, "the header announces more vertices or faces than the file holds");
  Builder b;
  std::vector<std::uint32_t> ids(nv);
  // Each property's type, looked up once (not by name per value).
  enum class Bin { u8, i8, u16, i16, u32, i32, f32, f64 };
  auto code_of = [&](const std::string& t) -> Bin {
    if (t == "uchar" || t == "uint8") return Bin::u8;
    if (t == "char" || t == "int8") return Bin::i8;
    if (t == "ushort" || t == "uint16") return Bin::u16;
    if (t == "short" || t == "int16") return Bin::i16;
    if (t == "uint" || t == "uint32") return Bin::u32;
    if (t == "int" || t == "int32") return Bin::i32;
    if (t == "float" || t == "float32") return Bin::f32;
    if (t == "double" || t == "float64") return Bin::f64;
    bad(path, 0, "unknown PLY type '" + t + "'");
  };
  auto read_bin = [&](Bin t, std::size_t& pos) -> double {
    static constexpr std::size_t kSize[] = {1, 1, 2, 2, 4, 4, 4, 8};
    const std::size_t n = kSize[static_cast<int>(t)];
    if (pos + n > data.size()) bad(path, 0, "PLY binary data ends early");
    const char* p = data.data() + pos;
    pos += n;
    switch (t) {
      case Bin::f32: { float f; std::memcpy(&f, p, 4); return f; }
      case Bin::f64: { double d; std::memcpy(&d, p, 8); return d; }
      case Bin::u8: return static_cast<unsigned char>(*p);
      case Bin::i8: return static_cast<signed char>(*p);
      case Bin::u16: { std::uint16_t v; std::memcpy(&v, p, 2); return v; }
      case Bin::i16: { std::int16_t v; std::memcpy(&v, p, 2); return v; }
      case Bin::u32: { std::uint32_t v; std::memcpy(&v, p, 4); return v; }
      case Bin::i32: break;
    }
    std::int32_t v; std::memcpy(&v, p, 4); return v;
  };
  if (format == "ascii") {
    for (std::size_t i = 0; i < nv; ++i) {
      if (!std::getline(in, line)) bad(path, line_no, "PLY ends before its vertices");
      ++line_no;
      std::istringstream ls(line);
      std::vector<double> vals(vprops.size());
      for (double& v : vals)
        if (!(ls >> v)) bad(path, line_no, "vertex line has too few values");
      ids[i] = b.vertex(Vec3(finite_or_fail(vals[static_cast<std::size_t>(ix)], path, line_no),
                             finite_or_fail(vals[static_cast<std::size_t>(iy)], path, line_no),
                             finite_or_fail(vals[static_cast<std::size_t>(iz)], path, line_no)));
    }
    for (std::size_t f = 0; f < nf; ++f) {
      if (!std::getline(in, line)) bad(path, line_no, "PLY ends before its faces");
      ++line_no;
      std::istringstream ls(line);
      std::size_t n;
      if (!(ls >> n) || n < 3) bad(path, line_no, "a face needs three vertices");
      std::vector<std::uint32_t> poly(n);
      for (auto& v : poly) {
        long k;
        if (!(ls >> k) || k < 0 || static_cast<std::size_t>(k) >= nv) bad(path, line_no, "face index out of range");
        v = ids[static_cast<std::size_t>(k)];
      }
      for (std::size_t k = 1; k + 1 < n; ++k) b.tri(poly[0], poly[k], poly[k + 1]);
    }
  } else {
    std::size_t pos = static_cast<std::size_t>(in.tellg());
    std::vector<Bin> vtypes;
    for (const auto& pr : vprops) vtypes.push_back(code_of(pr.first));
    const Bin count_type = nf ? code_of(list_count_type) : Bin::u8, index_type = nf ? code_of(list_index_type) : Bin::u8;
    b.index.reserve(nv);
    b.m.positions.reserve(nv);
    b.m.triangles.reserve(nf);
    std::vector<double> vals(vprops.size());
    std::vector<std::uint32_t> poly;
    for (std::size_t i = 0; i < nv; ++i) {
      for (std::size_t k = 0; k < vprops.size(); ++k) vals[k] = read_bin(vtypes[k], pos);
      ids[i] = b.vertex(Vec3(finite_or_fail(vals[static_cast<std::size_t>(ix)], path, 0),
                             finite_or_fail(vals[static_cast<std::size_t>(iy)], path, 0),
                             finite_or_fail(vals[static_cast<std::size_t>(iz)], path, 0)));
    }
    for (std::size_t f = 0; f < nf; ++f) {
      const double nd = read_bin(count_type, pos);
      if (nd < 3 || nd > 1e6) bad(path, 0, "a face needs three vertices");
      const std::size_t n = static_cast<std::size_t>(nd);
      poly.resize(n);
      for (auto& v : poly) {
        const double k = read_bin(index_type, pos);
        if (k < 0 || k >= static_cast<double>(nv)) bad(path, 0, "face index out of range");
        v = ids[static_cast<std::size_t>(k)];
      }
      for (std::size_t k = 1; k + 1 < n; ++k) b.tri(poly[0], poly[k], poly[k + 1]);
    }
  }
  return b.m;
}

TriMesh load_gltf(const std::string& path, bool binary) {
  tinygltf::Model model;
  tinygltf::TinyGLTF loader;
  std::string err, warn;
  const bool ok = binary ? loader.LoadBinaryFromFile(&model, &err, &warn, path)
                         : loader.LoadASCIIFromFile(&model, &err, &warn, path);
  if (!ok) bad(path, 0, "glTF: " + (err.empty() ? std::string("cannot be read") : err));
  Builder b;
  std::function<void(int, const Eigen::Affine3d&)> visit = [&](int ni, const Eigen::Affine3d& parent) {
    if (ni < 0 || ni >= static_cast<int>(model.nodes.size())) return;
    const tinygltf::Node& n = model.nodes[static_cast<std::size_t>(ni)];
    Eigen::Affine3d local = Eigen::Affine3d::Identity();
    if (n.matrix.size() == 16) {
      Eigen::Matrix4d M;
      for (int c = 0; c < 4; ++c)
        for (int r = 0; r < 4; ++r) M(r, c) = n.matrix[static_cast<std::size_t>(4 * c + r)];
      local.matrix() = M;
    } else {
      if (n.translation.size() == 3) local.translate(Vec3(n.translation[0], n.translation[1], n.translation[2]));
      if (n.rotation.size() == 4)
        local.rotate(Eigen::Quaterniond(n.rotation[3], n.rotation[0], n.rotation[1], n.rotation[2]).normalized());
      if (n.scale.size() == 3) local.scale(Vec3(n.scale[0], n.scale[1], n.scale[2]));
    }
    const Eigen::Affine3d world = parent * local;
    if (n.mesh >= 0 && n.mesh < static_cast<int>(model.meshes.size())) {
      for (const auto& prim : model.meshes[static_cast<std::size_t>(n.mesh)].primitives) {
        if (prim.mode != TINYGLTF_MODE_TRIANGLES && prim.mode != -1) continue;
        auto it = prim.attributes.find("POSITION");
        if (it == prim.attributes.end()) continue;
        const auto& acc = model.accessors.at(static_cast<std::size_t>(it->second));
        if (acc.componentType != TINYGLTF_COMPONENT_TYPE_FLOAT || acc.type != TINYGLTF_TYPE_VEC3 || acc.bufferView < 0)
          bad(path, 0, "glTF POSITION must be float VEC3");
        const auto& view = model.bufferViews.at(static_cast<std::size_t>(acc.bufferView));
        const auto& buf = model.buffers.at(static_cast<std::size_t>(view.buffer));
        const std::size_t stride = view.byteStride ? view.byteStride : 12;
        if (view.byteOffset + acc.byteOffset + (acc.count ? (acc.count - 1) * stride + 12 : 0) > buf.data.size())
          bad(path, 0, "glTF accessor outside its buffer");
        std::vector<std::uint32_t> ids(acc.count);
        for (std::size_t i = 0; i < acc.count; ++i) {
          float f[3];
          std::memcpy(f, buf.data.data() + view.byteOffset + acc.byteOffset + i * stride, 12);
          ids[i] = b.vertex(world * Vec3(f[0], f[1], f[2]));
        }
        std::vector<std::uint32_t> idx;
        if (prim.indices >= 0) {
          const auto& ia = model.accessors.at(static_cast<std::size_t>(prim.indices));
          const auto& iv = model.bufferViews.at(static_cast<std::size_t>(ia.bufferView));
          const auto& ib = model.buffers.at(static_cast<std::size_t>(iv.buffer));
          const std::size_t cs = ia.componentType == TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT ? 4
                               : ia.componentType == TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT ? 2 : 1;
          if (iv.byteOffset + ia.byteOffset + ia.count * cs > ib.data.size()) bad(path, 0, "glTF indices outside their buffer");
          for (std::size_t i = 0; i < ia.count; ++i) {
            std::uint32_t v = 0;
            std::memcpy(&v, ib.data.data() + iv.byteOffset + ia.byteOffset + i * cs, cs);
            if (v >= acc.count) bad(path, 0, "glTF index out of range");
            idx.push_back(ids[v]);
          }
        } else {
          idx = ids;
        }
        for (std::size_t i = 0; i + 2 < idx.size(); i += 3) b.tri(idx[i], idx[i + 1], idx[i + 2]);
      }
    }
    for (int c : n.children) visit(c, world);
  };
  const int scene = model.defaultScene >= 0 ? model.defaultScene : 0;
  if (scene < static_cast<int>(model.scenes.size()))
    for (int ni : model.scenes[static_cast<std::size_t>(scene)].nodes) visit(ni, Eigen::Affine3d::Identity());
  else
    for (std::size_t ni = 0; ni < model.nodes.size(); ++ni) visit(static_cast<int>(ni), Eigen::Affine3d::Identity());
  return b.m;
}

}  // namespace

TriMesh load_mesh(const std::string& path) {
  const std::string ext = lower_ext(path);
  if (ext == "gltf" || ext == "glb") {
    std::ifstream probe(path);
    if (!probe) throw InputError(path, "cannot open mesh file");
    TriMesh m = load_gltf(path, ext == "glb");
    if (m.triangles.empty()) throw ParseError(SourceLocation{path, 0, 0, {}}, "the mesh has no triangles");
    return m;
  }
  const std::string data = read_all(path);
  TriMesh m;
  if (ext == "stl") m = load_stl(path, data);
  else if (ext == "obj") m = load_obj(path, data);
  else if (ext == "ply") m = load_ply(path, data);
  else throw ParseError(SourceLocation{path, 0, 0, {}}, "unknown mesh format '." + ext + "' (stl, obj, ply, gltf, glb)");
  if (m.triangles.empty()) throw ParseError(SourceLocation{path, 0, 0, {}}, "the mesh has no triangles");
  return m;
}

MeshDefects find_defects(const TriMesh& m) {
  MeshDefects d;
  // Each directed edge as its undirected key (min, max) and whether it runs
  // from max to min, sorted: an edge's uses are then one run.
  std::vector<std::pair<std::uint64_t, bool>> uses;
  uses.reserve(m.triangles.size() * 3);
  for (const auto& t : m.triangles) {
    if (t[0] == t[1] || t[1] == t[2] || t[0] == t[2]) {
      ++d.degenerate_triangles;
      continue;
    }
    for (int k = 0; k < 3; ++k) {
      const std::uint32_t a = t[static_cast<std::size_t>(k)], b = t[static_cast<std::size_t>((k + 1) % 3)];
      const std::uint64_t key = (static_cast<std::uint64_t>(std::min(a, b)) << 32) | std::max(a, b);
      uses.emplace_back(key, a > b);
    }
  }
  std::sort(uses.begin(), uses.end());
  for (std::size_t i = 0; i < uses.size();) {
    std::size_t j = i;
    int forward = 0, backward = 0;
    for (; j < uses.size() && uses[j].first == uses[i].first; ++j) (uses[j].second ? backward : forward)++;
    const int n = forward + backward;
    if (n == 1) ++d.open_edges;
    else if (n > 2) ++d.nonmanifold_edges;
    else if (forward != 1) ++d.flipped_edges;
    i = j;
  }
  return d;
}

void require_closed(const TriMesh& m, const std::string& file, const std::string& what) {
  const MeshDefects d = find_defects(m);
  if (!d.closed()) {
    std::string msg = what + " is not a closed, consistently oriented surface:";
    if (d.open_edges) msg += " " + std::to_string(d.open_edges) + " open edges";
    if (d.nonmanifold_edges) msg += " " + std::to_string(d.nonmanifold_edges) + " edges shared by more than two triangles";
    if (d.flipped_edges) msg += " " + std::to_string(d.flipped_edges) + " edges between triangles of opposite orientation";
    throw GeometryError(SourceLocation{file, 0, 0, {}}, msg);
  }
  if (!(m.signed_volume() > 0))
    throw GeometryError(SourceLocation{file, 0, 0, {}}, what + " encloses no volume (inside out?)");
}

}  // namespace cutsim::io
