#include "cutsim/sim/interference.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <vector>

#include <tbb/enumerable_thread_specific.h>

#include "cutsim/core/ranking.h"
#include "cutsim/sweep/sweep.h"

namespace cutsim::sim {

InterferenceChecker::InterferenceChecker(const stock::Stock& stock, const Planner& planner, double tolerance_mm,
                                         double sweep_tolerance_mm)
    : stock_(stock), planner_(planner), tol_(tolerance_mm), sweep_tol_(sweep_tolerance_mm) {}

double InterferenceChecker::pose_spacing(const tool::Tool& t, double voxel_mm) {
  double s;
  if (!t.rotating()) s = 0.5 * std::min(t.body_length_mm, t.edge_height_mm);
  else if (t.kind == tool::ToolKind::flycutter) s = t.corner_radius_mm;
  else {
    s = 0.5 * std::min(t.diameter_mm, t.shank_diameter_mm);
    if (t.neck_length_mm > 0) s = std::min(s, 0.5 * std::min(t.neck_diameter_mm, t.neck_length_mm));
  }
  return std::max(s, 2 * voxel_mm);
}

namespace {
// A tool whose flank body PlaningRun can clear: a pointed edge (its
// wedge shrunk is the wedge raised), a rake face leaning back or upright
// (the body stays behind the edge's plane).
bool plans_runs(const tool::Tool& t) {
  if (t.kind != tool::ToolKind::vtool && t.kind != tool::ToolKind::nose) return false;
  return t.corner_radius_mm == 0 && t.rake_angle_deg >= 0 && t.clearance_angle_deg >= 0 &&
         t.included_angle_deg > 0 && t.included_angle_deg < 180;
}
// The rotation of a run: the tool axis +Z exactly (the stock's top is a
// height along it).
bool upright(const Eigen::Matrix3d& r) {
  return r(0, 2) == 0 && r(1, 2) == 0 && r(2, 2) == 1 && r(2, 0) == 0 && r(2, 1) == 0;
}
constexpr double kRunGap = 1e-9;  // mm: a move's start off its run's last tip, or off its plane
}  // namespace

PlaningRun::View PlaningRun::next(const motion::Move& m, const PlannedMove& pm, const tool::Tool& t,
                                  const Planner& planner) {
  const bool fits = m.kind != motion::MotionKind::rapid && m.is_straight() && plans_runs(t);
  if (!fits) {
    tips_.reset();
    return {};
  }
  const Pose p0 = planner.pose_at(m, pm, 0.0), p1 = planner.pose_at(m, pm, 1.0);
  const Eigen::Matrix3d& r = p0.linear();
  const double o = deg_to_rad(t.orientation_deg);
  const Vec3 along = r * Vec3(std::cos(o), std::sin(o), 0), across = r * Vec3(-std::sin(o), std::cos(o), 0);
  const Vec3 a = p0.translation(), b = p1.translation();
  if (!upright(r) || p1.linear() != r || (b - a).dot(along) <= 0 || std::fabs((b - a).dot(across)) > kRunGap) {
    tips_.reset();
    return {};
  }
  const bool continues = tips_ && tool_ == &t && rotation_ == r && (a - tips_->back()).norm() <= kRunGap &&
                         std::fabs((b - tips_->front()).dot(across)) <= kRunGap;
  if (!continues) {
    tips_ = std::make_shared<std::vector<Vec3>>(1, a);
    rotation_ = r;
    tool_ = &t;
  }
  View v{tips_, tips_->size(), rotation_};
  tips_->push_back(b);
  return v;
}

PlaningRun::Span PlaningRun::flank_span(const View& v, const tool::FlankBody& f, const Pose& at, double top,
                                         double tol) {
  // A voxel deeper than tol in the body lies in its flank term's region:
  // the wedge's distance d in the rake plane, at t behind the edge, has
  // d cos(clearance) + t sin(clearance) < -tol, so the wedge eroded by
  // t tan(clearance) + tol / cos(clearance): the wedge raised by that over
  // sin(half angle) (pointed). At t behind the pose the run's groove is the
  // wedge with its tip on the path: the voxel lies in it, by tol / cos(
  // clearance) at least (across its faces), where the path there is no
  // higher than k t above the pose. Upwards the body ends below the pose's
  // tip plus the edge's height, the groove at the path's plus it: above
  // that, the stock's top must be. Behind T, where the raised wedge clears
  // the top, or the body's end, nothing of it is below the top. Both tests
  // are linear in t along a segment of the path: where they hold at its
  // ends, they hold along it.
  const Span unknown;
  if (!v.tips || v.count == 0 || tol <= 0 || !(at.linear() == v.rotation)) return unknown;
  const tool::EdgeProfile& e = f.edge;
  if (e.nose_radius != 0 || f.rake < 0 || f.clearance < 0) return unknown;
  const Vec3 along = v.rotation * Vec3(e.cos_o, e.sin_o, 0), across = v.rotation * Vec3(-e.sin_o, e.cos_o, 0);
  const std::vector<Vec3>& tips = *v.tips;
  const Vec3 p = at.translation();
  if ((p - tips[v.count - 1]).dot(along) < 0 || std::fabs((p - tips.front()).dot(across)) > kRunGap) return unknown;
  const double k = std::tan(f.clearance) / std::sin(e.half_angle);
  const double cp = p.z();
  Span span{true, std::numeric_limits<double>::infinity(), -std::numeric_limits<double>::infinity()};
  if (cp >= top) return span;  // the body lies above the tip
  if (cp + e.height < top) return unknown;
  const double reach = k > 0 ? std::min(f.length, (top - cp) / k) : f.length;
  auto holds = [&](double t, double z) { return z <= k * t && cp + z + e.height >= top; };
  auto unsure = [&](double a, double b) {
    span.lo = std::min(span.lo, a);
    span.hi = std::max(span.hi, b);
  };
  double t0 = 0, z0 = 0;  // the last point checked: the pose, where both hold
  bool h0 = true;
  for (std::size_t i = v.count; i-- > 0;) {
    const double t = (p - tips[i]).dot(along), z = tips[i].z() - cp;
    if (t >= reach) {
      const double zr = t > t0 ? z0 + (z - z0) * (reach - t0) / (t - t0) : z;
      if (!h0 || !holds(reach, zr)) unsure(t0, reach);
      return span;
    }
    const bool h = holds(t, z);
    if (!h0 || !h) unsure(t0, t);
    t0 = t;
    z0 = z;
    h0 = h;
  }
  unsure(t0, reach);  // the run starts nearer than the body reaches below the top
  return span;
}

bool PlaningRun::flank_clear(const View& v, const tool::FlankBody& f, const Pose& at, double top, double tol) {
  return flank_span(v, f, at, top, tol).clear();
}

void InterferenceChecker::walk(const motion::Move& m, const PlannedMove& pm, const tool::Tool& tool,
                               const std::function<void()>& on_pose,
                               const std::function<void(const std::string& region, int pose, Scan scan)>& on_scan,
                               const PlaningRun::View* run) const {
  const bool rapid = m.kind == motion::MotionKind::rapid;
  std::vector<tool::Region> regions = tool::contact_regions(tool);
  const tool::Shape cut = tool::cutting_shape(tool);
  if (rapid && !std::holds_alternative<tool::EdgeProfile>(cut)) regions.push_back({"cutter", cut});
  if (regions.empty()) return;

  // Poses: evenly spaced along the tip's path (sampled for multi-axis moves).
  const Pose p0 = planner_.pose_at(m, pm, 0.0);
  const bool straight = m.is_straight();
  double len = 0;
  if (straight) {
    // Rotary joints held: the tip runs a straight line at a fixed
    // orientation (Planner::whole_sweep), so its chord is its length.
    len = (planner_.pose_at(m, pm, 1.0).translation() - p0.translation()).norm();
  } else {
    // Tip travel plus how far the tool's far end swings with the axis.
    Vec3 prev = p0.translation(), prev_axis = p0.linear().col(2);
    const double far = tool::shape_bounds(tool::cutting_shape(tool)).max.norm();
    for (int i = 1; i <= 16; ++i) {
      const Pose q = planner_.pose_at(m, pm, i / 16.0);
      const Vec3 axis = q.linear().col(2);
      len += (q.translation() - prev).norm() + far * std::acos(std::clamp(axis.dot(prev_axis), -1.0, 1.0));
      prev = q.translation();
      prev_axis = axis;
    }
  }
  const int n = std::clamp(static_cast<int>(std::ceil(len / pose_spacing(tool, stock_.voxel_mm()))), 1, 100000);
  const Aabb reach = stock_.roi().intersected(stock_.box().expanded(stock_.voxel_mm()));

  // Envelopes (neck, shank, holder, a rapid's cutter) are tested swept
  // from the pose before, exactly, so nothing hides between poses; the
  // flank body, at each pose (poses at most half its length apart).
  auto swept = [](const tool::Shape& sh) { return !std::holds_alternative<tool::FlankBody>(sh); };
  Pose prev = p0;
  for (int k = 1; k <= n; ++k) {
    const double s = static_cast<double>(k) / n;
    const double s_prev = static_cast<double>(k - 1) / n;
    const Pose pose = planner_.pose_at(m, pm, s);
    on_pose();
    // Skip poses whose regions all miss the material's reach, or that a
    // planing run clears.
    bool any = false;
    std::vector<Aabb> boxes;
    std::vector<Pose> at(regions.size());  // each region's frame in the workpiece
    std::vector<sweep::Sweep> sweeps(regions.size());
    for (std::size_t i = 0; i < regions.size(); ++i) {
      const tool::Region& rg = regions[i];
      at[i] = pose * rg.frame;
      const Pose before = prev * rg.frame;
      // Only the part of a V tool's body below the top of the material
      // counts; of a planing run's, only the stretch behind the edge its
      // groove may not clear.
      PlaningRun::Span span;
      const auto* flank = std::get_if<tool::FlankBody>(&rg.shape);
      if (flank && run && !rapid) {
        span = PlaningRun::flank_span(*run, *flank, at[i], stock_.box().max.z(), tol_);
        if (span.clear()) {  // (before its box: most of the snowflake's poses)
          if (regions.size() == 1) cleared_.fetch_add(1, std::memory_order_relaxed);
          boxes.push_back(Aabb());
          continue;
        }
      }
      Aabb b = sweep::world_box_within(rg.shape, at[i].linear(), at[i].translation(), reach);
      if (span.known) {
        const Vec3 along = at[i].linear() * Vec3(flank->edge.cos_o, flank->edge.sin_o, 0);
        if (along.y() == 0 && along.z() == 0 && std::fabs(along.x()) == 1) {
          // (A voxel's margin: the scan takes the voxels about the box.)
          const double x = at[i].translation().x(), hv = stock_.voxel_mm();
          const double x0 = x - along.x() * span.hi, x1 = x - along.x() * span.lo;
          b.min.x() = std::max(b.min.x(), std::min(x0, x1) - hv);
          b.max.x() = std::min(b.max.x(), std::max(x0, x1) + hv);
        }
      }
      if (swept(rg.shape)) {
        b.extend(sweep::world_box_within(rg.shape, before.linear(), before.translation(), reach));
        if (b.expanded(0.1 * b.size().norm()).overlaps(reach)) {
          sweeps[i] =
              straight ? sweep::sweep_line(before.translation(), at[i].translation(), at[i].linear(), rg.shape)
                       : sweep::sweep_poses(
                             [&](double u) { return planner_.pose_at(m, pm, s_prev + u * (s - s_prev)) * rg.frame; },
                             rg.shape, sweep_tol_, 1, &reach);
          b = sweeps[i].bounds;
        }
      }
      boxes.push_back(b);
      any |= b.overlaps(reach);
    }
    prev = pose;
    if (!any) continue;
    // What the cutting part removed from the move's start to this pose.
    auto so_far = std::make_shared<sweep::Sweep>();
    if (!rapid) *so_far = planner_.sweep_part(m, pm, tool, 0.0, s);
    // Its distance bounds whole quarters of a scan where its pieces' do.
    const bool so_far_lipschitz =
        std::all_of(so_far->prims.begin(), so_far->prims.end(), [](const auto& p) { return sweep::lipschitz(p); });
    for (std::size_t i = 0; i < regions.size(); ++i) {
      if (boxes[i].empty() || !boxes[i].overlaps(reach)) continue;
      // The scan owns what it needs: it may run after this walk.
      on_scan(regions[i].name, k, [this, so_far, so_far_lipschitz, box = boxes[i], at = at[i], shape = regions[i].shape,
                                   sw = std::move(sweeps[i])](const PendingCuts* pending) {
        // The region's distance (a flank body's with its angles' sines
        // worked out once for the pose).
        const auto* flank = std::get_if<tool::FlankBody>(&shape);
        const tool::FlankTrig trig = flank ? tool::flank_trig(*flank) : tool::FlankTrig{};
        const Pose inv = at.inverse();
        std::function<double(const Vec3&)> region;
        if (!sw.prims.empty()) region = [&](const Vec3& x) { return sw.distance(x); };
        else if (flank) region = [&](const Vec3& x) { return tool::flank_distance(*flank, trig, inv * x); };
        else region = [&](const Vec3& x) { return tool::shape_distance(shape, inv * x); };
        // What the move cut before this pose, and what the cuts held back
        // would take (both only lower the material: the least of the two).
        using Removed = std::function<double(const Vec3&, double)>;
        const Removal held = pending ? pending->removal(box, region) : Removal{};
        const Removed own =
            so_far->prims.empty() ? Removed() : Removed([&](const Vec3& x, double) { return so_far->distance(x); });
        const Removed own_cone = so_far_lipschitz ? own : Removed();
        auto least = [](const Removed& a, const Removed& b) -> Removed {
          if (!a || !b) return a ? a : b;
          return [&a, &b](const Vec3& x, double floor) {
            const double u = a(x, floor);
            return u <= floor ? u : std::min(u, b(x, floor));
          };
        };
        const Removed removed = least(own, held.removed), cone = least(own_cone, held.cone);
        if (!flank || !sw.prims.empty()) return stock_.overlap(box, region, removed, tol_, nullptr, cone);
        // Convex: its tangent plane bounds the scan's quarters.
        const Eigen::Matrix3d rot = at.linear();  // the body's gradient into the workpiece frame
        return stock_.overlap(
            box, region, removed, tol_,
            [&](const Vec3& x, Vec3* g) {
              Vec3 gl;
              const double d = tool::flank_distance(*flank, trig, inv * x, &gl);
              *g = rot * gl;
              return d;
            },
            cone);
      });
    }
  }
}

InterferenceChecker::FirstScans InterferenceChecker::first_scans(const motion::Move& m, const PlannedMove& pm,
                                                                const tool::Tool& tool, const PendingCuts* pending,
                                                                const PlaningRun::View* run) const {
  FirstScans out;
  out.held_back = pending != nullptr;
  walk(
      m, pm, tool, [&] { ++out.poses; },
      [&](const std::string& region, int pose, Scan scan) {
        FirstScans::Job job{pose, region, std::move(scan), {}};
        job.found = job.scan(nullptr);
        if (pending && job.found.depth_mm > tol_ && pending->change(job.found.where, job.found.stock_value)) {
          job.found = job.scan(pending);
          job.weighed = true;
        }
        out.jobs.push_back(std::move(job));
      },
      run);
  return out;
}

InterferenceChecker::PendingCuts InterferenceChecker::pending_cuts(std::function<HeldCuts()> held,
                                                                   const stock::Stock& stock, std::size_t n) {
  PendingCuts p;
  auto latest = [n](const HeldCuts& c) { return c.size() - std::min(c.size(), n); };
  p.change = [held, &stock](const Vec3& x, double v) { return cuts_change_voxel(held(), stock, x, v); };
  p.removal = [held, &stock, latest](const Aabb& box, const std::function<double(const Vec3&)>& region) {
    const HeldCuts c = held();
    return pending_removal(c.after(latest(c)), stock, box, region);
  };
  p.older_change = [held, &stock, latest](const Vec3& x, double v) {
    const HeldCuts c = held();
    return cuts_change_voxel(c.first(latest(c)), stock, x, v);
  };
  return p;
}

bool InterferenceChecker::check(const motion::Move& m, const PlannedMove& pm, const tool::Tool& tool,
                                const PendingCuts* pending, const FirstScans* first, const PlaningRun::View* run) {
  const bool rapid = m.kind == motion::MotionKind::rapid;
  bool touched = false;
  bool current = first && first->current;  // (until settle subtracts cuts)
  bool weighed_found = false;                // the first scan's touch was weighed against the held cuts
  auto take = [&](const std::string& region, const stock::Overlap* found, const Scan& scan) {
    // A scan made earlier stands where the stock has not changed since,
    // and where it found no touch (the stock only loses material).
    const bool stands = found && (current || found->depth_mm <= tol_);
    stock::Overlap ov = stands ? *found : scan(nullptr);
    bool weighed = stands && first->held_back && weighed_found;
    // The batch's pending cuts only take material away: without a
    // contact on the stock as it is, there is none after them either, and
    // where they leave the deepest voxel as it is, that stays the deepest
    // (and the first of its depth in the scan's order). Else the pose is
    // tested again on the stock less them, still held back: subtracting
    // them here (a batch of a few moves at each of the snowflake's 31k
    // rubbing poses) doubled the voxels the update evaluated.
    if (!(stands && first->held_back) && ov.depth_mm > tol_ && pending && pending->change(ov.where, ov.stock_value)) {
      ov = scan(pending);
      weighed = true;
    }
    if (ov.depth_mm > tol_ && pending && pending->older_change(ov.where, ov.stock_value) && pending->flush()) {
      current = false;
      vanished_ = 0;
      ov = scan(nullptr);
    } else if (weighed && pending) {
      // Where the held cuts keep taking away every touch (the lens's nose
      // tool: its flank lies in what the moves just before cut, and no
      // contact is left), each pose weighs them over all the material they
      // removed: after a few such poses in a row, subtract them instead.
      // (Real rubs, the snowflake's, keep the batch whole.)
      if (ov.depth_mm > tol_) vanished_ = 0;
      else if (++vanished_ >= kVanishedBeforeFlush && pending->flush()) {
        current = false;
        vanished_ = 0;
      }
    }
    if (ov.depth_mm <= tol_) return;
    touched = true;
    // Merge with the record of this region on this line at the pose before.
    Contact* rec = nullptr;
    for (auto it = contacts_.rbegin(); it != contacts_.rend() && it - contacts_.rbegin() < 8; ++it)
      if (it->line == m.line && it->region == region && it->rapid == rapid && it->last_pose == pose_index_ - 1) {
        rec = &*it;
        break;
      }
    if (!rec) {
      Contact c;
      c.line = m.line;
      c.text = m.text ? *m.text : std::string();
      c.region = region;
      c.rapid = rapid;
      contacts_.push_back(c);
      rec = &contacts_.back();
    }
    rec->poses += 1;
    rec->last_pose = pose_index_;
    if (ov.depth_mm > rec->depth_mm) {
      rec->depth_mm = ov.depth_mm;
      rec->where = ov.where;
      rec->at_least = ov.at_least;
    }
  };
  if (first) {
    const long base = pose_index_;
    for (const FirstScans::Job& job : first->jobs) {
      pose_index_ = base + job.pose;
      weighed_found = job.weighed;
      take(job.region, &job.found, job.scan);
    }
    pose_index_ = base + first->poses;
  } else {
    walk(
        m, pm, tool, [&] { ++pose_index_; },
        [&](const std::string& region, int, const Scan& scan) { take(region, nullptr, scan); }, run);
  }
  return touched;
}

bool cuts_change_voxel(const HeldCuts& cuts, const stock::Stock& stock, const Vec3& p, double v) {
  // The update writes -d where d < -v, evaluating a piece at the voxels of
  // every leaf its box, grown by the band, reaches: a piece whose box,
  // grown by that and a leaf, misses the voxel is never asked there.
  const double reach = stock.band_mm() + 8 * stock.voxel_mm();
  const double below = -v + 1e-6 * stock.voxel_mm();  // rounding in the voxel's position
  for (std::size_t i = 0; i < cuts.size(); ++i) {
    const sweep::Sweep& sw = cuts[i];
    if (!sw.bounds.expanded(reach).contains(p)) continue;
    for (const sweep::Primitive& piece : sw.prims)
      if (sweep::bounds(piece).expanded(reach).contains(p) && sweep::distance(piece, p) < below) return true;
  }
  return false;
}

namespace {

// The pieces whose boxes (grown by `grow`, a joint's not) reach a voxel
// centre, listed per leaf of the stock as its voxels are asked for, on
// each thread (a scan asks for the voxels of one leaf after another; the
// cuts near a region can number hundreds), with those boxes.
class NearPieces {
public:
  struct Piece {
    Aabb box;  // grown
    const sweep::Primitive* prim;
    bool inner;
  };
  NearPieces(const std::vector<const sweep::Primitive*>& pieces, const stock::Stock& stock, double grow)
      : origin_(stock.roi_lattice_origin() - Vec3::Constant(0.5 * stock.voxel_mm())), h_(stock.voxel_mm()) {
    for (const sweep::Primitive* p : pieces) {
      const bool inner = sweep::interior_only(*p);
      pieces_.push_back({sweep::bounds(*p).expanded(inner ? 0.0 : grow), p, inner});
    }
  }
  const std::vector<Piece>& at(const Vec3& x) const {
    // (The leaf's voxel centres lie h/2 .. 7.5 h into its cell.)
    const Eigen::Vector3i c = ((x - origin_) / (8 * h_)).array().floor().cast<int>();
    Cache& k = cache_.local();
    if (k.valid && k.cell == c) return k.list;
    k.valid = true;
    k.cell = c;
    const Vec3 lo = origin_ + 8 * h_ * c.cast<double>();
    const Aabb cb{lo, lo + Vec3::Constant(8 * h_)};
    k.list.clear();
    for (const Piece& p : pieces_)
      if (p.box.overlaps(cb)) k.list.push_back(p);
    return k.list;
  }

private:
  struct Cache {
    bool valid = false;
    Eigen::Vector3i cell;
    std::vector<Piece> list;
  };
  std::vector<Piece> pieces_;
  Vec3 origin_;
  double h_;
  mutable tbb::enumerable_thread_specific<Cache> cache_;
};

}  // namespace

Removal pending_removal(const HeldCuts& cuts, const stock::Stock& stock, const Aabb& box,
                        const std::function<double(const Vec3&)>& region) {
  // The update gives a voxel of value v the nearest piece's distance d
  // where -d > v (a joint's only where d < 0), stored as a float clamped to
  // the band: a piece whose box, grown by the band (a joint's: not grown),
  // misses the voxel leaves it as it is. The latest cuts first: the
  // material a region meets just behind the edge is what they took. (The
  // least of the distances does not depend on the order.)
  const double g = stock.band_mm(), h = stock.voxel_mm();
  std::vector<const sweep::Primitive*> near, joints, cone;
  for (std::size_t i = cuts.size(); i-- > 0;) {
    const sweep::Sweep* sw = &cuts[i];
    if (!sw->bounds.expanded(g).overlaps(box)) continue;
    for (auto piece = sw->prims.rbegin(); piece != sw->prims.rend(); ++piece) {
      const bool inner = sweep::interior_only(*piece);
      const Aabb reach = sweep::bounds(*piece).expanded(inner ? 0.0 : g).intersected(box);
      if (reach.empty()) continue;
      // (Outside the region no voxel counts: a piece it does not meet there
      // may be left out.)
      if (region && region(reach.center()) >= 0.5 * reach.size().norm()) continue;
      (inner ? joints : near).push_back(&*piece);
      if (!inner && sweep::lipschitz(*piece)) cone.push_back(&*piece);
    }
  }
  // Joints last: they count only inside themselves, where a prism beside
  // them mostly has the voxel already.
  near.insert(near.end(), joints.begin(), joints.end());
  if (near.empty()) return {};
  Removal r;
  auto all = std::make_shared<const NearPieces>(near, stock, g);
  r.removed = [all, g](const Vec3& x, double floor) {
    // As stored: the float nearest -d, negated back.
    auto stored = [](double d) { return -static_cast<double>(static_cast<float>(-d)); };
    double d = std::numeric_limits<double>::infinity();
    for (const NearPieces::Piece& p : all->at(x)) {
      if (!p.box.contains(x)) continue;
      if (p.inner) {
        const double lim = std::min(d, 0.0);
        if (const double dj = sweep::distance_below(*p.prim, x, lim); dj < lim) d = dj;
      } else {
        d = std::min(d, sweep::distance(*p.prim, x));
      }
      if (stored(d) <= floor) return stored(d);
    }
    return std::isfinite(d) ? stored(d) : d;
  };
  if (!cone.empty()) {
    // The stored value lies within 2^-24 |d| of d, so d + 1e-6 (|d| + h)
    // is above it (a float's rounding of the quarter's reach, 2.6 h, is
    // covered too) and stays 1-Lipschitz to 1e-6.
    auto lip = std::make_shared<const NearPieces>(cone, stock, g);
    r.cone = [lip, g, h](const Vec3& x, double lim) {
      double d = std::numeric_limits<double>::infinity();
      auto raised = [h](double v) { return v + 1e-6 * (std::abs(v) + h); };
      for (const NearPieces::Piece& p : lip->at(x)) {
        if (!p.box.contains(x)) continue;
        d = std::min(d, sweep::distance(*p.prim, x));
        if (raised(d) <= lim) break;
      }
      return raised(d);
    };
  }
  return r;
}

std::string format_contact(const Contact& c, const std::string& program) {
  const double um = c.depth_mm * 1000;
  char depth[64];
  std::snprintf(depth, sizeof depth, um < 0.1 ? "%.2f" : um < 10 ? "%.1f" : "%.0f", um);
  char where[128];
  std::snprintf(where, sizeof where, "(%.4f, %.4f, %.4f)", c.where.x(), c.where.y(), c.where.z());
  std::string s = program + ":" + std::to_string(c.line) + ": ";
  s += c.rapid ? "rapid contact (" + c.region + ")" : c.region + " contact";
  s += std::string(" ") + (c.at_least ? "at least " : "") + depth + " um deep at " + where + ": " + c.text;
  return s;
}

int contact_severity(const Contact& c) {
  if (c.rapid) return 0;
  if (c.region == "holder") return 1;
  if (c.region == "shank") return 2;
  if (c.region == "neck") return 3;
  return 4;  // the clearance face
}

std::vector<std::size_t> most_severe_contacts(const std::vector<Contact>& contacts, std::size_t n) {
  return first_n_in_order(contacts.size(), n, [&](std::size_t a, std::size_t b) {
    const int sa = contact_severity(contacts[a]), sb = contact_severity(contacts[b]);
    if (sa != sb) return sa < sb;
    if (contacts[a].depth_mm != contacts[b].depth_mm) return contacts[a].depth_mm > contacts[b].depth_mm;
    return a < b;
  });
}

std::vector<ContactKind> summarize_contacts(const std::vector<Contact>& contacts) {
  const RecordGroups g = group_records(
      contacts.size(),
      [&](std::size_t a, std::size_t b) {
        return contacts[a].region == contacts[b].region && contacts[a].rapid == contacts[b].rapid;
      },
      [&](std::size_t a, std::size_t b) { return contacts[a].depth_mm > contacts[b].depth_mm; },
      [&](std::size_t i) { return contacts[i].line; });
  std::vector<ContactKind> kinds;
  for (const RecordGroups::Group& k : g.groups)
    kinds.push_back({contacts[k.first].region, contacts[k.first].rapid, k.records, 0, k.worst, k.first_line, k.last_line});
  for (std::size_t i = 0; i < contacts.size(); ++i)
    if (contacts[i].at_least) ++kinds[g.group_of[i]].at_least;
  std::sort(kinds.begin(), kinds.end(), [&](const ContactKind& a, const ContactKind& b) {
    const int sa = contact_severity(contacts[a.deepest]), sb = contact_severity(contacts[b.deepest]);
    if (sa != sb) return sa < sb;
    return a.region < b.region;
  });
  return kinds;
}

}  // namespace cutsim::sim
