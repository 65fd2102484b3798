#pragma once
// Private: the stock update's innermost loops over a quarter's voxels
// (4 x 4 x 4), each in a portable version and, where the CPU has AVX2, one
// that takes four voxels at a time to the same bits (no FMA: the AVX2
// target adds none, and the sums run in the portable version's order).
// The dispatching functions pick the AVX2 one when the CPU has it; the
// tests hold both to the same bits.
#include <cstdint>
#include <utility>

#include "cutsim/core/cpu.h"
#include "cutsim/sweep/sweep.h"

namespace cutsim::stock::detail {

/// h (i - 1.5): the offset, along one axis, of a quarter's voxel i (0-3)
/// from the quarter's centre, for voxels h apart. The update and the
/// contact scan both take their voxels' offsets from here.
inline double quarter_offset(int i, double h) { return h * (i - 1.5); }

/// A convex piece's tangent plane at a quarter's centre, c + g . y.
struct CentrePlane {
  double c, gx, gy, gz;
};

/// The voxels b < n (bits) whose nearest distance so far d[b] is above
/// `floor` and where the plane, c + (gx yx[b] + gy yy[b] + gz yz[b]) (y the
/// voxel's offset from the centre, summed as Eigen's dot does), lies below
/// min(d[b], need[b]): those the piece may lower. (n <= 64)
std::uint64_t planes_below(const double* d, const double* need, const double* yx, const double* yy, const double* yz,
                           int n, const CentrePlane& pl, double floor);
/// d[b] = min(d[b], sweep::detail::ball_line_distance(lp, (px, py, pz)[b]))
/// for the voxels b in `bits`: a ball end's line lowering the nearest
/// distance so far.
void lower_by_ball_line(const sweep::LinearPrim& lp, std::uint64_t bits, const double* px, const double* py,
                        const double* pz, double* d);

/// d[b] = min(d[b], sweep::detail::prism_distance(pp, (px, py, pz)[b])) for
/// the voxels b in `bits`: a profile prism (ProfilePrim::prism) lowering the
/// nearest distance so far.
void lower_by_prism(const sweep::ProfilePrim& pp, std::uint64_t bits, const double* px, const double* py,
                    const double* pz, double* d);
/// For the voxels b in `bits`, with lim = min(d[b], need[b], 0): d[b] = the
/// joint's distance (sweep::detail::joint_distance_below) where that is
/// below lim (a joint's inside only matters; at or above lim the voxel
/// keeps d[b]).
void lower_by_joint(const sweep::JointPrim& jp, std::uint64_t bits, const double* px, const double* py,
                    const double* pz, const double* need, double* d);

/// The voxels b < n (bits) whose nearest distance so far d[b] is not at
/// or below `floor` and that a piece's box leaves to its distance: those
/// at squared distance 0 from the box (sweep::detail::box_distance2 at
/// (px, py, pz)[b]), or with a positive limit whose square the squared
/// distance is below. The limit is min(d[b], need[b]), and for a piece
/// whose inside only matters (`inner`) at most 0. (n <= 64)
std::uint64_t boxes_reach(const double* d, const double* need, const double* px, const double* py, const double* pz,
                          int n, const Aabb& box, bool inner, double floor);

/// out[i] = sweep::detail::prism_distance(pp, (px, py, pz)[i]) for i < n:
/// a profile prism's (ProfilePrim::prism) distances at a quarter's voxels.
void prism_distances(const sweep::ProfilePrim& pp, int n, const double* px, const double* py, const double* pz,
                     double* out);

/// The voxels of a 4^3 quarter (bit q = 16 x + 4 y + z; voxel q at
/// data[first + 64 x + 8 y + z]) that hold material (a value below
/// `gamma`) and whose need (-v; `inner`: min(-v, 0)) lies above the
/// piece's bound there: key - off[q], and with `sec`, also
/// sweep::section_bound(*sec, (yx, yy, yz)[q]).
std::uint64_t quarter_reach(const float* data, int first, float gamma, double key, const double* off, bool inner,
                            const sweep::SectionPlane* sec, const double* yx, const double* yy, const double* yz);

/// The voxels of a whole 4^3 quarter (bit q = 16 x + 4 y + z; voxel q at
/// data[first + 64 x + 8 y + z]) that may overlap a region deeper than
/// `floor`: their material is (-v > floor) and, given a plane bounding the
/// region's depth (`pl`, or none), so is the plane there:
/// -(c + (gx yx + gy yy + gz yz)) > floor, at the voxel's offset from the
/// quarter's centre, y = h (x - 1.5, y - 1.5, z - 1.5).
std::uint64_t overlap_candidates(const float* data, int first, double floor, const CentrePlane* pl, double h);
/// A leaf's pieces, by field, in the order of their keys: each convex (a
/// tangent plane at the leaf's centre, key + g . r at an offset r from it)
/// and none interior-only, for the test of which of them a quarter takes
/// (quarter_pieces).
struct LeafPieces {
  const double* key;                                // bounded key at the leaf's centre, ascending
  const double *lox, *loy, *loz, *hix, *hiy, *hiz;  // the piece's box
  const double *gx, *gy, *gz;                       // its plane's gradient at the leaf's centre
  const double* g1;                                 // |g|_1, as g.cwiseAbs().sum()
  const double* clip;                               // 1 where 1-Lipschitz (sweep::lipschitz), else 0
};
/// A quarter of the leaf, for quarter_pieces.
struct QuarterAt {
  double cx, cy, cz;  // its centre
  double rx, ry, rz;  // the centre's offset from the leaf's
  double oc;          // |r|
  double need_max;    // the largest -v among its voxels
  double hd;          // its half diagonal
  double hq;          // its half width between voxel centres
};
/// The pieces k < n that a quarter takes, in key order: for each, as the
/// stock update's loop over a leaf's pieces per quarter decides (the loop
/// ends at the first whose key less oc and hd is at or above need_max;
/// passed over are a piece whose box is farther than need_max + hd, whose
/// plane at the centre, dk = key + g . r, less hq |g|_1 is at or above
/// need_max, or whose bounded key there, dk where dk > 0 or the piece is
/// 1-Lipschitz and else -inf, less hd is at or above need_max), out[i] =
/// (bounded key, k) and seed[k] = dk. Returns the count taken, and in
/// *least the place in `out` of the least (key, k) (0 if none). seed[k] of
/// pieces passed over may be written too.
int quarter_pieces(const LeafPieces& f, int n, const QuarterAt& q, double* seed, std::pair<double, std::uint32_t>* out,
                   int* least);
int quarter_pieces_scalar(const LeafPieces& f, int from, int n, const QuarterAt& q, double* seed,
                          std::pair<double, std::uint32_t>* out, int* least);
int quarter_pieces_avx2(const LeafPieces& f, int n, const QuarterAt& q, double* seed, std::pair<double, std::uint32_t>* out,
                        int* least);

/// (The dispatching functions take the AVX2 versions where use_avx2(),
/// cutsim/core/cpu.h.) The two versions, for the tests (the AVX2 ones only
/// where cpu_has_avx2(); off x86-64 they are the portable ones).
std::uint64_t planes_below_scalar(const double* d, const double* need, const double* yx, const double* yy,
                                  const double* yz, int from, int n, const CentrePlane& pl, double floor);
std::uint64_t planes_below_avx2(const double* d, const double* need, const double* yx, const double* yy,
                                const double* yz, int n, const CentrePlane& pl, double floor);
std::uint64_t boxes_reach_scalar(const double* d, const double* need, const double* px, const double* py,
                                 const double* pz, int from, int n, const Aabb& box, bool inner, double floor);
std::uint64_t boxes_reach_avx2(const double* d, const double* need, const double* px, const double* py,
                               const double* pz, int n, const Aabb& box, bool inner, double floor);
std::uint64_t quarter_reach_scalar(const float* data, int first, float gamma, double key, const double* off,
                                   bool inner, const sweep::SectionPlane* sec, const double* yx, const double* yy,
                                   const double* yz);
std::uint64_t quarter_reach_avx2(const float* data, int first, float gamma, double key, const double* off, bool inner,
                                 const sweep::SectionPlane* sec, const double* yx, const double* yy, const double* yz);
std::uint64_t overlap_candidates_scalar(const float* data, int first, double floor, const CentrePlane* pl, double h);
std::uint64_t overlap_candidates_avx2(const float* data, int first, double floor, const CentrePlane* pl, double h);
void prism_distances_scalar(const sweep::ProfilePrim& pp, int from, int n, const double* px, const double* py,
                            const double* pz, double* out);
void prism_distances_avx2(const sweep::ProfilePrim& pp, int n, const double* px, const double* py, const double* pz,
                          double* out);
void lower_by_ball_line_scalar(const sweep::LinearPrim& lp, std::uint64_t bits, const double* px, const double* py,
                               const double* pz, double* d);
void lower_by_prism_scalar(const sweep::ProfilePrim& pp, std::uint64_t bits, const double* px, const double* py,
                           const double* pz, double* d);
void lower_by_prism_avx2(const sweep::ProfilePrim& pp, std::uint64_t bits, const double* px, const double* py,
                         const double* pz, double* d);
void lower_by_joint_scalar(const sweep::JointPrim& jp, std::uint64_t bits, const double* px, const double* py,
                           const double* pz, const double* need, double* d);
void lower_by_joint_avx2(const sweep::JointPrim& jp, std::uint64_t bits, const double* px, const double* py,
                         const double* pz, const double* need, double* d);
void lower_by_ball_line_avx2(const sweep::LinearPrim& lp, std::uint64_t bits, const double* px, const double* py,
                             const double* pz, double* d);

}  // namespace cutsim::stock::detail
