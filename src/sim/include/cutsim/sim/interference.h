#pragma once
// Contacts of the parts of a tool that must not touch the material:
// clearance faces, neck, shank, holder, and on a rapid the whole tool.
#include <functional>
#include <string>
#include <vector>

#include "cutsim/motion/move.h"
#include "cutsim/sim/planner.h"
#include "cutsim/stock/stock.h"
#include "cutsim/tool/tool.h"

namespace cutsim::sim {

/// One contact: consecutive touching poses of one region on one NC line.
struct Contact {
  int line = 0;              ///< NC line
  std::string text;          ///< the line as written
  std::string region;        ///< "clearance-face", "neck", "shank", "holder", "cutter"
  bool rapid = false;        ///< on a G0: every region counts
  Vec3 where = Vec3::Zero(); ///< deepest point, workpiece frame, mm
  double depth_mm = 0;       ///< deepest overlap with the material
  bool at_least = false;     ///< the depth reached the stock's band: at least this deep
  int poses = 0;             ///< sampled poses that touched
  long last_pose = -1;       ///< (internal) index of the last pose that touched
};

/// Checks each move against the stock before its cut is subtracted. At
/// poses spaced along the move, every region is tested against the
/// material still there at that pose: the stock before the move less what
/// the cutting part swept from the move's start to that pose (on a rapid,
/// nothing is cut first). The caller may hold cuts back to subtract them in
/// a batch (PendingCuts): a touch found on the stock without them stands
/// as found when they would leave its deepest voxel as it is (they only
/// take material away, so nowhere else can get deeper than it); else they
/// are subtracted and the pose is tested again.
class InterferenceChecker {
public:
  /// Cuts the caller holds back from the stock.
  struct PendingCuts {
    /// Would they change the stock's voxel at `p`, whose value is `v`?
    /// (May say yes when unsure; must not say no when they would.)
    std::function<bool(const Vec3& p, double v)> change;
    /// Subtracts them; true when there were any.
    std::function<bool()> flush;
  };
  InterferenceChecker(const stock::Stock& stock, const Planner& planner, double tolerance_mm,
                      double sweep_tolerance_mm);
  /// Returns true when this move touched.
  bool check(const motion::Move& m, const PlannedMove& pm, const tool::Tool& tool,
             const PendingCuts* pending = nullptr);
  const std::vector<Contact>& contacts() const { return contacts_; }
  /// Poses between tested ones along a move, mm (half the smallest region).
  static double pose_spacing(const tool::Tool& t, double voxel_mm);

private:
  const stock::Stock& stock_;
  const Planner& planner_;
  double tol_, sweep_tol_;
  long pose_index_ = 0;
  std::vector<Contact> contacts_;
};

/// Would subtracting `cuts` from `stock` change its voxel at `p`, whose
/// value is `v`? Never no where they would (what PendingCuts::change must
/// answer for cuts held back in a batch); yes only where a piece the update
/// would evaluate there comes nearer than -v.
bool cuts_change_voxel(const std::vector<sweep::Sweep>& cuts, const stock::Stock& stock, const Vec3& p, double v);

/// `prog.nc:1234: clearance-face contact 0.8 um deep at (x, y, z): G1 X...`
std::string format_contact(const Contact& c, const std::string& program);

}  // namespace cutsim::sim
