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
  /// The first scan of each pose and region `check` makes for this move,
  /// on the stock as it is, in check's order, with what it needs to be
  /// made again. Changes nothing: the moves of a group can be scanned side
  /// by side, then checked in order.
  struct FirstScans {
    struct Job {
      int pose = 0;  ///< 1-based, of `poses`
      std::string region;
      std::function<stock::Overlap()> scan;
      stock::Overlap found;  ///< what it found
    };
    std::vector<Job> jobs;
    int poses = 0;
    /// The stock has not changed since: every scan stands. Else only those
    /// that found no touch (the stock has only lost material since).
    bool current = false;
  };
  FirstScans first_scans(const motion::Move& m, const PlannedMove& pm, const tool::Tool& tool) const;
  /// Returns true when this move touched. With `first` (first_scans of
  /// this move), the scans that stand are not made again.
  bool check(const motion::Move& m, const PlannedMove& pm, const tool::Tool& tool,
             const PendingCuts* pending = nullptr, const FirstScans* first = nullptr);
  const std::vector<Contact>& contacts() const { return contacts_; }
  /// Poses between tested ones along a move, mm (half the smallest region).
  static double pose_spacing(const tool::Tool& t, double voxel_mm);

private:
  using Scan = std::function<stock::Overlap()>;
  /// Calls on_pose for each pose, and on_scan for each region a pose
  /// brings near the material, with the scan of that region at that pose
  /// (against the stock less what the move cut before it).
  void walk(const motion::Move& m, const PlannedMove& pm, const tool::Tool& tool, const std::function<void()>& on_pose,
            const std::function<void(const std::string& region, int pose, Scan scan)>& on_scan) const;

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

/// What a contact risks, the most first (0): a rapid into material (a
/// crash), then the holder, the shank and the neck touching (collisions),
/// then the clearance face (rubbing).
int contact_severity(const Contact& c);

/// The indices of the `n` contacts that matter most, in program order: by
/// severity, deeper first within one, then the earlier. (A long program's
/// many rubs of the clearance face must not hide a crash behind them.)
std::vector<std::size_t> most_severe_contacts(const std::vector<Contact>& contacts, std::size_t n);

/// The contacts of one kind (region, and whether on a rapid).
struct ContactKind {
  std::string region;
  bool rapid = false;
  std::size_t records = 0;   ///< contacts (one per line, region and motion)
  std::size_t at_least = 0;  ///< of them, as deep as the stock's band shows ("at least")
  std::size_t deepest = 0;   ///< index of the deepest (the first of equal depths)
  int first_line = 0, last_line = 0;
};

/// One entry per kind present, the most severe kind first.
std::vector<ContactKind> summarize_contacts(const std::vector<Contact>& contacts);

}  // namespace cutsim::sim
