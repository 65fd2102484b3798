#pragma once
// The workpiece: a box whose region of interest (ROI) is an OpenVDB
// narrow-band level set; outside the ROI the stock stays its analytic box.
// OpenVDB stays out of this header (see grid_access.h for the grid itself).
#include <array>
#include <cstddef>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "cutsim/core/geometry.h"
#include "cutsim/core/mesh.h"
#include "cutsim/sweep/sweep.h"

namespace cutsim::stock {

struct StockOptions {
  double voxel_mm = 0.01;        ///< voxel edge length, mm
  /// Narrow band half width, voxels. Two are all anything reads: the
  /// volumes count values within half a voxel of the surface, the mesher
  /// and its normals one and a half voxels; only a contact's depth
  /// saturates at it ("at least"). Three (OpenVDB's usual width) gave the
  /// same volumes to 1e-12 for half again the active voxels (snowflake
  /// 10 %, blade at 1 um 15 %, raster40k 20 % slower).
  double half_band_voxels = 2;
  /// Refuse to build a grid whose estimated memory exceeds this, bytes;
  /// 0 = 75 % of physical memory.
  std::size_t memory_limit_bytes = 0;
  /// (leaf, piece) pairs a cut applies at a time, about 40 bytes each: a
  /// batch whose pieces reach more leaves is applied in parts (the voxels
  /// come out the same), so this bounds the update's working memory. The
  /// fewer the parts, the fewer times a voxel many pieces pass is
  /// evaluated (blade at 1 um: 2.08 G evaluations at 2^20, 1.50 G at
  /// 2^22, for some 0.1-0.5 GB more at the peak).
  std::size_t max_update_pairs = std::size_t(1) << 22;
  /// Measure StockStats::band_voxels (a bench figure; 0: off). A leaf a
  /// move's band reaches counts 512 where its distance at the leaf's
  /// centre proves every voxel within the band, else its voxels are
  /// evaluated one by one, in 1 leaf in N (picked by a hash of the leaf's
  /// place) and counted N times. At N = 1 it takes several times the
  /// update's own time (the snowflake's 8 s update: 30 s); the voxels come
  /// out the same.
  std::size_t measure_band_every = 0;
};

/// Up to 8 x 8 x 8 voxels of the region of interest (a leaf-sized block,
/// clipped to the ROI).
struct VoxelBlock {
  Vec3 first_center;   ///< world position of voxel (0, 0, 0) of the block
  int n[3] = {0, 0, 0};///< voxels along x, y, z
  int leaf[3] = {0, 0, 0};  ///< position in the ROI's block lattice (0 .. roi_block_dims() - 1)
  bool uniform = false;///< every voxel holds `value` (a tile: all material or all air)
  float value = 0;
  float values[512];   ///< level-set values, index (x * 8 + y) * 8 + z, when not uniform
};

/// The blocks of the region of interest that one 128^3-voxel node of the
/// grid holds (Stock::for_each_roi_block).
struct BlockGroup {
  std::array<int, 3> lo{}, hi{};  ///< their VoxelBlock::leaf range, [lo, hi) along each axis
  Vec3 centre;                    ///< centre of the box their voxel centres span
  double radius = 0;              ///< half that box's diagonal: every voxel centre is this near `centre`
  bool uniform = false;           ///< the stock holds `value` at every voxel of them (no leaf, one tile value)
  float value = 0;
};

/// How deep a region reaches into the material (see Stock::overlap).
struct Overlap {
  double depth_mm = 0;        ///< deepest overlap found (0: none above the threshold)
  Vec3 where = Vec3::Zero();  ///< voxel centre of the deepest overlap, workpiece frame
  bool at_least = false;      ///< the depth reached the band's half width: the true depth is at least this
  /// The stock's own value at `where` (before what `removed` takes): cuts
  /// that leave this voxel as it is leave the deepest overlap as it is.
  double stock_value = 0;
};

struct StockStats {
  std::size_t voxel_evaluations = 0;  ///< tool distances the cuts evaluated so far
  /// Voxels the moves' bands reach (StockOptions::measure_band_every; 0
  /// when not measured): summed over the moves, the voxels of the grid's
  /// leaves and material tiles nearer a move than the band's half width,
  /// the voxels a plain update (tool distance, max, write back) would
  /// visit. The 32^3 and 128^3 blocks a piece holds deeper than the band
  /// (set to air whole, their leaves never listed) count once, not once
  /// per move that reaches them: there the figure is a lower bound.
  std::size_t band_voxels = 0;
  /// Voxels set to air with no distance of their own: their 4^3 quarter
  /// lies deeper than the band inside one piece.
  std::size_t voxels_aired = 0;
  /// 32^3-voxel blocks that held material and were set to air whole, their
  /// leaves never listed: a piece held the block (or the 128^3 block around
  /// it) deeper than the band and the block's half diagonal.
  std::size_t blocks_aired = 0;
  /// Updates of the grid: one per batch, more where a batch passed
  /// StockOptions::max_update_pairs and was applied in parts.
  std::size_t grid_updates = 0;
  /// Seconds the cuts spent in each step so far: binning pieces by leaf
  /// (with the sort), classifying the leaves, changing the tree's
  /// topology, and the voxels.
  double bin_s = 0, classify_s = 0, topology_s = 0, voxels_s = 0;
  std::size_t leaf_nodes = 0;
  std::size_t active_voxels = 0;
  std::size_t memory_bytes = 0;
  std::size_t air_blocks = 0;  ///< 32^3-voxel blocks known to hold only air (passed over unprobed)
  /// Leaves with no voxel in the band: each could be a tile, 2 KB for nothing.
  std::size_t idle_leaves = 0;
};

/// Estimated grid memory (bytes) for a box stock over an ROI.
std::size_t estimate_memory_bytes(const Aabb& box, const Aabb& roi, const StockOptions& opt);

class Stock {
public:
  /// Builds the level set of `box` over `roi` (clipped to the box grown by
  /// the band). Positions are mm in the workpiece frame.
  /// @throw GeometryError when the box is empty or the ROI misses it, or when
  ///        the estimated memory exceeds the limit (naming both figures and a
  ///        voxel size that would fit).
  Stock(const Aabb& box, const Aabb& roi, const StockOptions& opt);
  ~Stock();
  Stock(Stock&&) noexcept;
  Stock& operator=(Stock&&) noexcept;

  /// Removes the swept region from the stock. Material outside the ROI is
  /// never touched: the ROI must cover every cut (the caller sizes it).
  void subtract(const sweep::Sweep& sweep);
  /// Removes several sweeps at once (the order does not matter: the union
  /// is removed). Each leaf is visited once for the whole batch.
  void subtract(const std::vector<sweep::Sweep>& batch);
  /// Frees the working memory cuts keep between calls (up to some 40 bytes
  /// per StockOptions::max_update_pairs): call after the last cut.
  void release_scratch();

  /// Stock volume now, mm^3: the analytic box minus what the grid lost.
  double volume_mm3() const;
  /// Volume of the box before any cut, mm^3 (exact).
  double initial_volume_mm3() const;
  /// Volume removed so far, mm^3, integrated on the grid (voxel coverage).
  double removed_volume_mm3() const;

  /// Height of the machined surface along +Z at (x, y): the highest zero
  /// crossing of the level set below `z_from`, by linear interpolation.
  /// Returns NaN when no crossing is found inside the ROI.
  double surface_height(double x, double y, double z_from) const;
  /// Calls `fn` for every block of the region of interest, in parallel;
  /// `fn` must be safe to call from several threads at once.
  /// With `values` false, only the block's place and size are filled in.
  /// With `group`, the blocks come by groups (those of one 128^3-voxel node
  /// of the grid), and a group's are visited only where `group` returns
  /// true for it (called once per group, also in parallel).
  void for_each_roi_block(const std::function<void(const VoxelBlock&)>& fn, bool values = true,
                          const std::function<bool(const BlockGroup&)>& group = {}) const;
  /// Blocks of the region of interest along x, y, z (VoxelBlock::leaf).
  std::array<int, 3> roi_block_dims() const;
  /// World centre of the first voxel of block lattice cell (0, 0, 0): a
  /// block's voxel (x, y, z) lies at this + h * (8 * leaf + offset + (x, y, z)).
  Vec3 roi_lattice_origin() const;
  /// The deepest overlap of a region with the material at the voxel centres
  /// inside `bounds`: depth(p) = min(-region(p), -material(p)), where the
  /// material is the stock less what `removed` (a signed distance, may be
  /// empty) covers. `region` must be exact or a lower bound outside (it
  /// culls blocks). `removed(p, floor)` may stop and return any value at
  /// most `floor` once it knows the distance is no more than that (such a
  /// voxel cannot count). Only depths above `min_depth_mm` count. The
  /// stock's values are clamped to the band, so depths stop at its half width.
  /// `region_plane` (may be empty) is for a convex region: it returns
  /// region(x) and sets a subgradient g, so region(y) >= region(x) + g . (y -
  /// x) everywhere; each 4^3 quarter's voxels are then bounded by that plane
  /// at its centre (the same result, fewer evaluations of `region`).
  /// `removed_cone` (may be empty): 1-Lipschitz over the ROI and nowhere
  /// below `removed` (`removed` itself where that is 1-Lipschitz, a sweep of
  /// pieces that are, sweep::lipschitz; else a part of what it takes the
  /// least of), called as `removed` is: a 4^3 quarter whose centre lies
  /// deeper in it than the quarter's reach is passed over, as all its voxels
  /// would be (the same result, fewer evaluations of `region` and `removed`).
  Overlap overlap(const Aabb& bounds, const std::function<double(const Vec3&)>& region,
                  const std::function<double(const Vec3&, double)>& removed, double min_depth_mm,
                  const std::function<double(const Vec3&, Vec3*)>& region_plane = nullptr,
                  const std::function<double(const Vec3&, double)>& removed_cone = nullptr) const;

  /// Level-set value at a world point (trilinear), mm.
  double sample(const Vec3& p) const;

  /// The stock's surface: the grid's zero level set clipped to the ROI,
  /// plus the analytic box faces outside the ROI. Normals from the grid.
  /// `adaptivity` in [0, 1] is OpenVDB's: 0 keeps one quad per surface
  /// voxel; larger values merge flat regions (the top face) into fewer,
  /// larger polygons without cracks.
  TriMesh surface_mesh(double adaptivity = 0.0) const;

  /// Writes the grid with what rebuilds the stock (box, ROI, voxel) to an
  /// OpenVDB file, atomically. @throw OutputError.
  void save_vdb(const std::string& path) const;
  /// Reads a stock written by save_vdb.
  /// @throw InputError (unreadable), ParseError (not a cutsim stock).
  static Stock load_vdb(const std::string& path);
  /// A stock whose material is a closed mesh, as a level set at `voxel_mm`
  /// (to compare a machined mesh from elsewhere with a target).
  static Stock from_mesh(const TriMesh& mesh, double voxel_mm);

  const Aabb& box() const;
  const Aabb& roi() const;  ///< snapped to voxel cells
  double voxel_mm() const;
  double band_mm() const;   ///< the narrow band's half width: values are clamped to +-this
  StockStats stats() const;

  struct Impl;
  Impl& impl() { return *impl_; }
  const Impl& impl() const { return *impl_; }

private:
  Stock();
  // owner[i]: the move (sweep) piece i belongs to, non-decreasing.
  void subtract_prims(const std::vector<const sweep::Primitive*>& prims, const std::vector<std::uint32_t>& owner);
  std::unique_ptr<Impl> impl_;
};

}  // namespace cutsim::stock
