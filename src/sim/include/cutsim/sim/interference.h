#pragma once
// Contacts of the parts of a tool that must not touch the material:
// clearance faces, neck, shank, holder, and on a rapid the whole tool.
#include <atomic>
#include <functional>
#include <memory>
#include <span>
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

/// Material taken away from the stock as Stock::overlap's `removed` sees it.
struct Removal {
  std::function<double(const Vec3&, double)> removed;  ///< empty: nothing
  /// 1-Lipschitz and nowhere below `removed` over the scan (may be empty):
  /// Stock::overlap's `removed_cone`.
  std::function<double(const Vec3&, double)> cone;
};

/// Cuts held back from the stock, oldest first: a run of one vector's, then
/// of another's (a batch, then a group's moves before the one checked).
struct HeldCuts {
  std::span<const sweep::Sweep> a, b;
  HeldCuts() = default;
  HeldCuts(std::span<const sweep::Sweep> first_run, std::span<const sweep::Sweep> then = {}) : a(first_run), b(then) {}
  HeldCuts(const std::vector<sweep::Sweep>& v) : a(v) {}
  std::size_t size() const { return a.size() + b.size(); }
  const sweep::Sweep& operator[](std::size_t i) const { return i < a.size() ? a[i] : b[i - a.size()]; }
  /// The first n, and those after them.
  HeldCuts first(std::size_t n) const {
    return n <= a.size() ? HeldCuts(a.first(n)) : HeldCuts(a, b.first(n - a.size()));
  }
  HeldCuts after(std::size_t n) const {
    return n <= a.size() ? HeldCuts(a.subspan(n), b) : HeldCuts({}, b.subspan(n - a.size()));
  }
};

/// A pointed V tool planing: consecutive straight cuts at one orientation,
/// each forward along the cutting direction, all in one plane through the
/// tool axis (the snowflake's scan lines). Behind its edge the clearance
/// body is the edge's wedge shrunk by tan(clearance) per unit length back,
/// so at t behind the pose it is the wedge raised by t tan(clearance) /
/// sin(half angle). Where the path behind never rises above that line, the
/// body less any depth lies inside the groove the run has cut (the same
/// wedge along the path) or above the stock's top: after the run's cuts
/// nothing of the material is in it. The contact check then need not scan
/// that pose, nor subtract the cuts it holds back to find that out.
class PlaningRun {
public:
  /// The run as a move starts.
  struct View {
    std::shared_ptr<const std::vector<Vec3>> tips;  ///< the run's tips in order, workpiece frame
    std::size_t count = 0;                          ///< of them, those up to the move's start
    Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();  ///< the tool frame's, the run's
  };
  /// The run as move `m` (the next in the program) starts; m joins it from
  /// then on where it continues it, else starts a new one (or none: a rapid,
  /// an arc, a rotary move, another tool, a plunge, a sideways move).
  View next(const motion::Move& m, const PlannedMove& pm, const tool::Tool& t, const Planner& planner);
  /// True where the flank body `f` at `at` (a pose of the move whose view
  /// this is, its own cut from its start to there included in what removed
  /// the material), less `tol` (> 0) all round, lies in the groove the run
  /// cut or above `top` (the stock's top), the tool axis being +Z: then no
  /// voxel is deeper than `tol` in both the body and the material the
  /// run's cuts leave. False where unsure.
  static bool flank_clear(const View& v, const tool::FlankBody& f, const Pose& at, double top, double tol);
  /// Where behind the edge (t along the cutting direction, mm) the body may
  /// hold a voxel deeper than `tol` in the material the run's cuts leave:
  /// within [lo, hi] (empty: nowhere, flank_clear); unknown: anywhere.
  struct Span {
    bool known = false;
    double lo = 0, hi = 0;
    bool clear() const { return known && lo > hi; }
  };
  static Span flank_span(const View& v, const tool::FlankBody& f, const Pose& at, double top, double tol);

private:
  std::shared_ptr<std::vector<Vec3>> tips_;
  Eigen::Matrix3d rotation_ = Eigen::Matrix3d::Identity();
  const tool::Tool* tool_ = nullptr;
};

/// Checks each move against the stock before its cut is subtracted. At
/// poses spaced along the move, every region is tested against the
/// material still there at that pose: the stock before the move less what
/// the cutting part swept from the move's start to that pose (on a rapid,
/// nothing is cut first). The caller may hold cuts back to subtract them in
/// a batch (PendingCuts): a touch found on the stock without them stands
/// as found when they would leave its deepest voxel as it is (they only
/// take material away, so nowhere else can get deeper than it); else the
/// pose is tested again on the stock less the latest of them, as the
/// update would leave it (PendingCuts::removal), and what that finds stands
/// where the others leave its deepest voxel as it is; else they are all
/// subtracted and the pose tested again.
class InterferenceChecker {
public:
  /// Cuts the caller holds back from the stock.
  struct PendingCuts {
    /// Would they change the stock's voxel at `p`, whose value is `v`?
    /// (May say yes when unsure; must not say no when they would.)
    std::function<bool(const Vec3& p, double v)> change;
    /// The distance of the latest of them (or all) near `box` as the stock
    /// would hold it once they are subtracted (pending_removal).
    std::function<Removal(const Aabb& box, const std::function<double(const Vec3&)>& region)> removal;
    /// As `change`, for those `removal` leaves out.
    std::function<bool(const Vec3& p, double v)> older_change;
    /// Subtracts them; true when there were any (may be empty: first_scans).
    std::function<bool()> flush;
  };
  /// PendingCuts for the cuts `held` gives at each call, the `latest` of
  /// them weighed voxel by voxel (pending_removal); no flush.
  static PendingCuts pending_cuts(std::function<HeldCuts()> held, const stock::Stock& stock,
                                  std::size_t latest = kLatestCuts);
  /// The latest of the cuts held back that a test weighs at every voxel it
  /// asks for: a few passes of the snowflake's raster.
  static constexpr std::size_t kLatestCuts = 400;
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
      std::function<stock::Overlap(const PendingCuts*)> scan;  ///< (null: no cuts held back)
      stock::Overlap found;  ///< what it found
      bool weighed = false;  ///< found on the stock less the held cuts (its touch on the stock was theirs)
    };
    std::vector<Job> jobs;
    int poses = 0;
    /// Made on the stock less the cuts held back then, as check makes them.
    bool held_back = false;
    /// The stock has not changed since: every scan stands. Else only those
    /// that found no touch (the stock has only lost material since).
    bool current = false;
  };
  /// With `run` (the move's planing run), poses whose flank body the run
  /// clears (PlaningRun::flank_clear) are not scanned.
  FirstScans first_scans(const motion::Move& m, const PlannedMove& pm, const tool::Tool& tool,
                         const PendingCuts* pending = nullptr, const PlaningRun::View* run = nullptr) const;
  /// Returns true when this move touched. With `first` (first_scans of
  /// this move, with the same `run`), the scans that stand are not made
  /// again.
  bool check(const motion::Move& m, const PlannedMove& pm, const tool::Tool& tool,
             const PendingCuts* pending = nullptr, const FirstScans* first = nullptr,
             const PlaningRun::View* run = nullptr);
  const std::vector<Contact>& contacts() const { return contacts_; }
  /// Poses checked so far, and of them those a planing run cleared.
  long poses() const { return pose_index_; }
  long poses_cleared() const { return cleared_.load(); }
  /// Poses between tested ones along a move, mm (half the smallest region).
  static double pose_spacing(const tool::Tool& t, double voxel_mm);

private:
  /// A scan, on the stock less what `pending` holds back (null: none).
  using Scan = std::function<stock::Overlap(const PendingCuts* pending)>;
  /// Calls on_pose for each pose, and on_scan for each region a pose
  /// brings near the material, with the scan of that region at that pose
  /// (against the stock less what the move cut before it).
  void walk(const motion::Move& m, const PlannedMove& pm, const tool::Tool& tool, const std::function<void()>& on_pose,
            const std::function<void(const std::string& region, int pose, Scan scan)>& on_scan,
            const PlaningRun::View* run) const;

  const stock::Stock& stock_;
  const Planner& planner_;
  double tol_, sweep_tol_;
  long pose_index_ = 0;
  /// Poses in a row whose touch the held cuts took away when weighed, and
  /// how many make the check subtract them instead.
  int vanished_ = 0;
  static constexpr int kVanishedBeforeFlush = 4;
  mutable std::atomic<long> cleared_{0};  // (walks of one group run side by side)
  std::vector<Contact> contacts_;
};

/// Would subtracting `cuts` from `stock` change its voxel at `p`, whose
/// value is `v`? Never no where they would (what PendingCuts::change must
/// answer for cuts held back in a batch); yes only where a piece the update
/// would evaluate there comes nearer than -v.
bool cuts_change_voxel(const HeldCuts& cuts, const stock::Stock& stock, const Vec3& p, double v);

/// What subtracting `cuts` would leave at the voxel centres in `box` (and
/// inside `region`, a distance exact or a lower bound outside; empty: all), as a
/// distance r for Stock::overlap's `removed` (the material there becomes
/// max(v, -r)): the value the update would store, to the float, where the
/// cuts change a voxel, and where they do not, some r no less than -v or
/// beyond the band. A joint piece (sweep::interior_only) counts only inside
/// itself, as in the update. `removed(p, floor)` may stop once it is at
/// most the floor. The cone: the nearest of the 1-Lipschitz pieces other
/// than joints, raised by more than the float's rounding.
Removal pending_removal(const HeldCuts& cuts, const stock::Stock& stock, const Aabb& box,
                        const std::function<double(const Vec3&)>& region = nullptr);

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
