// Saving and loading the stock as an OpenVDB file, and stocks from meshes.
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <unistd.h>

#include <openvdb/tools/MeshToVolume.h>

#include "cutsim/core/error.h"
#include "stock_impl.h"

namespace cutsim::stock {

namespace {
constexpr const char* kFormat = "cutsim-stock-1";

openvdb::Vec3d to_vdb(const Vec3& v) { return openvdb::Vec3d(v.x(), v.y(), v.z()); }
Vec3 from_vdb(const openvdb::Vec3d& v) { return Vec3(v.x(), v.y(), v.z()); }
openvdb::Vec3i to_vdb(const openvdb::Coord& c) { return openvdb::Vec3i(c.x(), c.y(), c.z()); }
openvdb::Coord coord(const openvdb::Vec3i& v) { return openvdb::Coord(v.x(), v.y(), v.z()); }

std::once_flag g_init_io;
}  // namespace

Stock::Stock() : impl_(std::make_unique<Impl>()) { std::call_once(g_init_io, [] { openvdb::initialize(); }); }

void Stock::save_vdb(const std::string& path) const {
  const Impl& m = *impl_;
  openvdb::FloatGrid::Ptr g = m.grid->deepCopy();
  g->insertMeta("cutsim_format", openvdb::StringMetadata(kFormat));
  g->insertMeta("cutsim_box_min", openvdb::Vec3DMetadata(to_vdb(m.box.min)));
  g->insertMeta("cutsim_box_max", openvdb::Vec3DMetadata(to_vdb(m.box.max)));
  g->insertMeta("cutsim_origin", openvdb::Vec3DMetadata(to_vdb(m.origin)));
  g->insertMeta("cutsim_roi_index_min", openvdb::Vec3IMetadata(to_vdb(m.roi_index.min())));
  g->insertMeta("cutsim_roi_index_max", openvdb::Vec3IMetadata(to_vdb(m.roi_index.max())));
  g->insertMeta("cutsim_grid_index_min", openvdb::Vec3IMetadata(to_vdb(m.grid_index.min())));
  g->insertMeta("cutsim_grid_index_max", openvdb::Vec3IMetadata(to_vdb(m.grid_index.max())));
  g->insertMeta("cutsim_voxel_mm", openvdb::DoubleMetadata(m.h));
  g->insertMeta("cutsim_half_band_mm", openvdb::DoubleMetadata(m.gamma));
  g->insertMeta("cutsim_initial_grid_volume", openvdb::DoubleMetadata(m.initial_grid_volume));
  const std::string tmp = path + ".tmp-" + std::to_string(::getpid());
  try {
    openvdb::io::File file(tmp);
    file.write({g});
    file.close();
  } catch (const std::exception& e) {
    std::error_code ec;
    std::filesystem::remove(tmp, ec);
    throw OutputError(path, std::string("cannot write the stock grid: ") + e.what());
  }
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) {
    std::filesystem::remove(tmp, ec);
    throw OutputError(path, "cannot write the stock grid: " + ec.message());
  }
}

Stock Stock::load_vdb(const std::string& path) {
  Stock s;
  if (!std::filesystem::is_regular_file(path)) throw InputError(path, "no such file");
  openvdb::GridBase::Ptr base;
  try {
    openvdb::io::File file(path);
    file.open();
    base = file.readGrid("stock");
    file.close();
  } catch (const std::exception& e) {
    throw ParseError(SourceLocation{path, 0, 0, {}}, std::string("not a cutsim stock grid (.vdb): ") + e.what());
  }
  Impl& m = *s.impl_;
  m.grid = openvdb::gridPtrCast<openvdb::FloatGrid>(base);
  if (!m.grid) throw ParseError(SourceLocation{path, 0, 0, {}}, "the grid 'stock' is not a float grid");
  auto meta = [&](const char* key) {
    if (!(*m.grid)[key]) throw ParseError(SourceLocation{path, 0, 0, {}}, std::string("not a cutsim stock: no ") + key);
  };
  for (const char* k : {"cutsim_format", "cutsim_box_min", "cutsim_box_max", "cutsim_origin", "cutsim_roi_index_min",
                        "cutsim_roi_index_max", "cutsim_grid_index_min", "cutsim_grid_index_max", "cutsim_voxel_mm",
                        "cutsim_half_band_mm", "cutsim_initial_grid_volume"})
    meta(k);
  try {
    if (m.grid->metaValue<std::string>("cutsim_format") != kFormat)
      throw ParseError(SourceLocation{path, 0, 0, {}}, "unknown stock format '" +
                                                           m.grid->metaValue<std::string>("cutsim_format") + "'");
    m.box = Aabb{from_vdb(m.grid->metaValue<openvdb::Vec3d>("cutsim_box_min")),
                 from_vdb(m.grid->metaValue<openvdb::Vec3d>("cutsim_box_max"))};
    m.origin = from_vdb(m.grid->metaValue<openvdb::Vec3d>("cutsim_origin"));
    m.roi_index = openvdb::CoordBBox(coord(m.grid->metaValue<openvdb::Vec3i>("cutsim_roi_index_min")),
                                     coord(m.grid->metaValue<openvdb::Vec3i>("cutsim_roi_index_max")));
    m.grid_index = openvdb::CoordBBox(coord(m.grid->metaValue<openvdb::Vec3i>("cutsim_grid_index_min")),
                                      coord(m.grid->metaValue<openvdb::Vec3i>("cutsim_grid_index_max")));
    m.h = m.grid->metaValue<double>("cutsim_voxel_mm");
    m.gamma = static_cast<float>(m.grid->metaValue<double>("cutsim_half_band_mm"));
    m.initial_grid_volume = m.grid->metaValue<double>("cutsim_initial_grid_volume");
  } catch (const openvdb::Exception& e) {
    throw ParseError(SourceLocation{path, 0, 0, {}}, std::string("not a cutsim stock: ") + e.what());
  }
  if (!(m.h > 0) || !(m.gamma > 0) || m.box.empty() || m.roi_index.empty())
    throw ParseError(SourceLocation{path, 0, 0, {}}, "not a cutsim stock: inconsistent box, ROI or voxel size");
  const auto& r = m.roi_index;
  m.roi = Aabb{m.origin + m.h * (Vec3(r.min().x(), r.min().y(), r.min().z()).array() - 0.5).matrix(),
               m.origin + m.h * (Vec3(r.max().x(), r.max().y(), r.max().z()).array() + 0.5).matrix()};
  m.rebuild_occupancy();
  return s;
}

Stock Stock::from_mesh(const TriMesh& mesh, double voxel_mm) {
  if (!(voxel_mm > 0)) throw GeometryError({}, "voxel size must be positive");
  if (mesh.triangles.empty()) throw GeometryError({}, "the mesh has no triangles");
  Stock s;
  Impl& m = *s.impl_;
  m.h = voxel_mm;
  m.gamma = static_cast<float>(3 * voxel_mm);
  m.box = mesh.bounds();
  // Index space centred on the mesh, as for a simulated stock.
  m.origin = (m.box.center() / m.h).array().round() * m.h;
  std::vector<openvdb::Vec3s> pts;
  pts.reserve(mesh.positions.size());
  for (const Vec3& p : mesh.positions) {
    const Vec3 q = (p - m.origin) / m.h;
    pts.emplace_back(static_cast<float>(q.x()), static_cast<float>(q.y()), static_cast<float>(q.z()));
  }
  std::vector<openvdb::Vec3I> tris;
  tris.reserve(mesh.triangles.size());
  for (const auto& t : mesh.triangles) tris.emplace_back(t[0], t[1], t[2]);
  const auto xf = openvdb::math::Transform::createLinearTransform(m.h);
  m.grid = openvdb::tools::meshToVolume<openvdb::FloatGrid>(
      openvdb::tools::QuadAndTriangleDataAdapter<openvdb::Vec3s, openvdb::Vec3I>(pts, tris), *xf, 3.0f, 3.0f);
  // Values in mm, as the simulated stock keeps them.
  m.grid->setGridClass(openvdb::GRID_LEVEL_SET);
  m.grid->setName("stock");
  const auto lo = ((m.box.min - m.origin) / m.h).array().floor() - 4;
  const auto hi = ((m.box.max - m.origin) / m.h).array().ceil() + 4;
  m.roi_index = openvdb::CoordBBox(openvdb::Coord(int(lo.x()), int(lo.y()), int(lo.z())),
                                   openvdb::Coord(int(hi.x()), int(hi.y()), int(hi.z())));
  m.grid_index = m.roi_index.expandBy(8);
  const auto& r = m.roi_index;
  m.roi = Aabb{m.origin + m.h * (Vec3(r.min().x(), r.min().y(), r.min().z()).array() - 0.5).matrix(),
               m.origin + m.h * (Vec3(r.max().x(), r.max().y(), r.max().z()).array() + 0.5).matrix()};
  m.box = m.roi;  // the material is all inside the grid
  m.initial_grid_volume = m.grid_volume();
  m.rebuild_occupancy();
  return s;
}

}  // namespace cutsim::stock
