// Case 2 (CASES.md, seeds/001 figs. 2-3): a turbine-blade-like freeform on
// a base, roughed with 3-axis control and finished with simultaneous 5-axis
// control (tool centre point control) on the xyzbc machine; the same
// program with stated setting errors shows overcut and undercut.
#include <algorithm>
#include <cmath>
#include <sstream>

#include "cases_impl.h"
#include "cutsim/core/error.h"
#include "cutsim/machine/kinematics.h"

namespace cutsim::cases {
namespace blade {

namespace {
constexpr double kXL = -0.975, kXT = 1.05;  // camber ends; the discs' radii make the 2.2 mm width
constexpr double kCamber = 0.2;             // camber height over the chord
constexpr int kSamples = 2048;              // disc centres along the camber

double camber_y(double x) {
  const double xc = 0.5 * (kXL + kXT), hw = 0.5 * (kXT - kXL);
  const double u = (x - xc) / hw;
  return kCamber * (1 - u * u);
}

struct Discs {
  std::vector<double> x, y, h;
  Discs() {
    for (int i = 0; i <= kSamples; ++i) {
      const double t = static_cast<double>(i) / kSamples;
      x.push_back(kXL + (kXT - kXL) * t);
      y.push_back(camber_y(x.back()));
      h.push_back(0.5 * thickness(t));
    }
  }
};
const Discs& discs() {
  static const Discs d;
  return d;
}
}  // namespace

double thickness(double t) {
  if (t <= 0.3) {
    const double u = (0.3 - t) / 0.3;
    return 0.25 + 0.15 * (1 - u * u);
  }
  const double u = (t - 0.3) / 0.7;
  return 0.1 + 0.3 * (1 - u * u);
}

double section_distance(double px, double py) {
  const Discs& d = discs();
  const double step = (kXT - kXL) / kSamples;
  const int n = kSamples + 1;
  int i0 = static_cast<int>(std::lround((px - kXL) / step));
  i0 = std::clamp(i0, 0, n - 1);
  double best = std::hypot(px - d.x[i0], py - d.y[i0]) - d.h[i0];
  // Discs further than best + 0.2 (the largest radius) in x cannot be closer.
  for (int dir = -1; dir <= 1; dir += 2)
    for (int i = i0 + dir; i >= 0 && i < n; i += dir) {
      const double dx = std::abs(px - d.x[i]);
      if (dx - 0.2 > best) break;
      best = std::min(best, std::hypot(px - d.x[i], py - d.y[i]) - d.h[i]);
    }
  return best;
}

Vec3 star_centre() { return Vec3(kXL + 0.3 * (kXT - kXL), camber_y(kXL + 0.3 * (kXT - kXL)), 0); }

std::vector<Outline> outline(int n) {
  const Vec3 s = star_centre();
  std::vector<Outline> out;
  for (int i = 0; i < n; ++i) {
    const double a = 2 * kPi * i / n;
    const double cx = std::cos(a), cy = std::sin(a);
    double lo = 0, hi = 2;
    for (int k = 0; k < 50; ++k) {
      const double mid = 0.5 * (lo + hi);
      (section_distance(s.x() + mid * cx, s.y() + mid * cy) < 0 ? lo : hi) = mid;
    }
    const double r = 0.5 * (lo + hi);
    const double px = s.x() + r * cx, py = s.y() + r * cy, e = 1e-6;
    Vec3 g(section_distance(px + e, py) - section_distance(px - e, py),
           section_distance(px, py + e) - section_distance(px, py - e), 0);
    out.push_back({Vec3(px, py, 0), g.normalized(), a});
  }
  return out;
}

}  // namespace blade

namespace {

using namespace blade;

// Stock, base and the blade (mm).
constexpr double kX0 = -1.9, kX1 = 1.9, kY0 = -1.3, kY1 = 1.5, kBottom = -1.0;
constexpr double kBall = 0.5, kAllowance = 0.03, kTilt = 30;  // deg, tool axis from vertical, away from the wall

// Fanuc: every number with a decimal point.
std::string f(double v, int decimals = 6) {
  std::string s = num(v, decimals);
  if (s.find('.') == std::string::npos) s += '.';
  return s;
}

// The outline's equal-angle rays meet the wall every 0.1 um where they hit
// it square on (they must, to be 11 um apart where they graze the trailing
// edge). The mesh keeps only the points a chord cannot pass over within
// `tol`: 12,000 wall slivers had made every closest-point query near the
// wall sort through a hundred of them.
std::vector<Outline> thin_outline(const std::vector<Outline>& o, double tol) {
  auto off_chord = [](const Vec3& p, const Vec3& a, const Vec3& b) {
    const Vec3 ab = b - a;
    const double t = std::clamp((p - a).dot(ab) / std::max(ab.squaredNorm(), 1e-300), 0.0, 1.0);
    return (p - (a + t * ab)).norm();
  };
  std::vector<Outline> out;
  const std::size_t n = o.size();
  std::size_t i = 0;
  while (i < n) {
    out.push_back(o[i]);
    // The farthest j whose chord from i passes every point between within tol.
    std::size_t j = i + 1;
    while (j + 1 <= n) {
      const Vec3& b = o[(j + 1) % n].p;
      bool ok = true;
      for (std::size_t k = i + 1; k <= j && ok; ++k) ok = off_chord(o[k].p, o[i].p, b) <= tol;
      if (!ok) break;
      ++j;
    }
    i = j;
  }
  return out;
}

TriMesh target_mesh(const std::vector<Outline>& full) {
  const std::vector<Outline> o = thin_outline(full, 1e-5);
  TriMesh m;
  const auto n = static_cast<std::uint32_t>(o.size());
  const Vec3 s = star_centre();
  // 0..n-1 the outline at z = 0, n..2n-1 at the top, 2n the top's centre.
  for (const auto& p : o) m.positions.push_back(p.p);
  for (const auto& p : o) m.positions.push_back(p.p + Vec3(0, 0, kHeight));
  m.positions.push_back(s + Vec3(0, 0, kHeight));
  for (std::uint32_t i = 0; i < n; ++i) {
    const std::uint32_t j = (i + 1) % n;
    m.triangles.push_back({i, j, n + j});  // wall
    m.triangles.push_back({i, n + j, n + i});
    m.triangles.push_back({2 * n, n + i, n + j});  // top
  }
  // The base's top between the outline and the rectangle, along the same
  // rays from the star centre; the rectangle's corners go between the rays.
  auto ray_hit = [&](double a) {
    const double cx = std::cos(a), cy = std::sin(a);
    double t = 1e9;
    if (cx > 0) t = std::min(t, (kX1 - s.x()) / cx);
    if (cx < 0) t = std::min(t, (kX0 - s.x()) / cx);
    if (cy > 0) t = std::min(t, (kY1 - s.y()) / cy);
    if (cy < 0) t = std::min(t, (kY0 - s.y()) / cy);
    return Vec3(s.x() + t * cx, s.y() + t * cy, 0);
  };
  std::vector<std::pair<double, Vec3>> corners;
  for (const Vec3& c : {Vec3(kX1, kY0, 0), Vec3(kX1, kY1, 0), Vec3(kX0, kY1, 0), Vec3(kX0, kY0, 0)}) {
    double a = std::atan2(c.y() - s.y(), c.x() - s.x());
    if (a < 0) a += 2 * kPi;
    corners.emplace_back(a, c);
  }
  std::sort(corners.begin(), corners.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  std::vector<std::uint32_t> ring;        // the rectangle, counter-clockwise
  std::vector<std::size_t> ray_at(n + 1);  // ring position of outline i's ray
  for (std::uint32_t i = 0; i < n; ++i) {
    const double a0 = o[i].angle, a1 = i + 1 < n ? o[i + 1].angle : 2 * kPi;
    ray_at[i] = ring.size();
    ring.push_back(static_cast<std::uint32_t>(m.positions.size()));
    m.positions.push_back(ray_hit(a0));
    for (const auto& [a, c] : corners)
      if (a > a0 && a < a1) {
        ring.push_back(static_cast<std::uint32_t>(m.positions.size()));
        m.positions.push_back(c);
      }
  }
  ray_at[n] = ring.size();
  for (std::uint32_t i = 0; i < n; ++i) {
    const std::uint32_t j = (i + 1) % n;
    for (std::size_t k = ray_at[i]; k < ray_at[i + 1]; ++k)
      m.triangles.push_back({i, ring[k], ring[(k + 1) % ring.size()]});
    m.triangles.push_back({i, ring[ray_at[i + 1] % ring.size()], j});
  }
  // The base's sides and bottom.
  const auto nr = static_cast<std::uint32_t>(ring.size());
  const auto base = static_cast<std::uint32_t>(m.positions.size());
  for (std::uint32_t k : ring) m.positions.push_back(Vec3(m.positions[k].x(), m.positions[k].y(), kBottom));
  const auto centre = static_cast<std::uint32_t>(m.positions.size());
  m.positions.push_back(Vec3(0.5 * (kX0 + kX1), 0.5 * (kY0 + kY1), kBottom));
  for (std::uint32_t k = 0; k < nr; ++k) {
    const std::uint32_t a = ring[k], b = ring[(k + 1) % nr], a0 = base + k, b0 = base + (k + 1) % nr;
    m.triangles.push_back({a, a0, b0});
    m.triangles.push_back({a, b0, b});
    m.triangles.push_back({centre, b0, a0});
  }
  return m;
}

// Joint-space time scaling for the 5-axis finish: each block's duration is
// at least its tip path over the feed and each joint's travel over its
// velocity limit (with margin); durations then grow until the change of
// joint velocity between blocks stays within the acceleration limit, as
// cutsim's axis check estimates it (over the mean of the blocks' durations).
std::vector<double> block_times(const std::vector<machine::JointValues>& q, const std::vector<double>& path_mm,
                                double feed_mm_s, const machine::Machine& mc) {
  const std::size_t n = path_mm.size();
  std::vector<double> t(n);
  std::vector<std::pair<int, const machine::Joint*>> joints;
  for (const auto& j : mc.chain) joints.emplace_back(machine::axis_index(j.axis), &j);
  for (std::size_t i = 0; i < n; ++i) {
    t[i] = path_mm[i] / feed_mm_s;
    for (const auto& [k, j] : joints)
      if (j->max_velocity > 0) t[i] = std::max(t[i], std::abs(q[i + 1][k] - q[i][k]) / (0.8 * j->max_velocity));
    t[i] = std::max(t[i], 1e-4);
  }
  // Junction i joins block i - 1 and block i; the path starts and ends at
  // rest (a block of zero travel and duration t[0] / t[n-1] outside).
  auto velocity = [&](std::size_t b, int k) { return (q[b + 1][k] - q[b][k]) / t[b]; };
  for (int iter = 0;; ++iter) {
    bool changed = false;
    for (std::size_t i = 0; i <= n; ++i)
      for (const auto& [k, j] : joints) {
        if (j->max_acceleration <= 0) continue;
        const double a = 0.8 * j->max_acceleration;
        const double v0 = i > 0 ? velocity(i - 1, k) : 0.0, v1 = i < n ? velocity(i, k) : 0.0;
        const double span = 0.5 * ((i > 0 ? t[i - 1] : t[0]) + (i < n ? t[i] : t[n - 1]));
        if (std::abs(v1 - v0) <= a * span) continue;
        if (i > 0) t[i - 1] *= 1.03;
        if (i < n) t[i] *= 1.03;
        changed = true;
      }
    if (!changed) break;
    if (iter > 100000) throw GeometryError({}, "blade: the finishing feed does not settle within the axis limits");
  }
  return t;
}

std::string program(const std::vector<Outline>& o, bool with_comment_of_errors) {
  std::ostringstream os;
  os << "(cutsim reference case 2: turbine blade, seeds/001 figs. 2-3. Generated by cutsim-cases.)\n";
  if (with_comment_of_errors)
    os << "(the same program as blade.nc; the job states the setting errors)\n";
  os << "(ball end mill R0.5; 3-axis roughing, then simultaneous 5-axis finishing under G43.4)\n"
     << "G21 G90 G94 G17\nG0 Z2.6\n";
  // Roughing: raster along X, 0.25 mm layers, the ball kept kAllowance off the blade.
  const double safe = 2.6;
  auto allowed = [&](double x, double y, double tip_z) {
    const double cz = tip_z + kBall, d2 = section_distance(x, y);
    const double d = cz <= kHeight ? d2 : (d2 > 0 ? std::hypot(d2, cz - kHeight) : cz - kHeight);
    return d >= kBall + kAllowance;
  };
  const int layers = 9;
  for (int k = 1; k <= layers; ++k) {
    const double z = kHeight - k * (kHeight / layers);
    const double pick = k == layers ? 0.1 : 0.3;
    os << "(roughing layer " << k << ": Z" << f(z) << ", pick " << f(pick) << ")\n";
    const int lines = static_cast<int>(std::floor((kY1 - kY0) / pick));
    for (int l = 0; l <= lines; ++l) {
      const double y = kY0 + l * pick;
      const double x0 = kX0 - kBall - 0.1, x1 = kX1 + kBall + 0.1, dx = 0.005;
      const int nx = static_cast<int>(std::ceil((x1 - x0) / dx));
      double run_start = 0;
      bool in = false;
      for (int i = 0; i <= nx; ++i) {
        const double x = x0 + (x1 - x0) * i / nx;
        const bool ok = allowed(x, y, z);
        if (ok && !in) {
          run_start = x;
          in = true;
        }
        if (in && (!ok || i == nx)) {
          const double run_end = ok ? x : x0 + (x1 - x0) * (i - 1) / nx;
          // Down and up at feed below the stock's top: beside the blade the
          // layers above leave ridges of the ball's profile in the allowance
          // (a rapid down to just above the layer before met them).
          os << "G0 X" << f(run_start) << " Y" << f(y) << "\nG0 Z" << f(kHeight + 0.05) << "\nG1 Z"
             << f(z) << " F100.\nG1 X" << f(run_end) << " F600.\nG1 Z" << f(kHeight + 0.05) << "\nG0 Z" << f(safe)
             << "\n";
          in = false;
        }
      }
    }
  }
  // Finishing: one loop around the wall a level, contact height from the
  // top down to where the ball's bottom would reach the floor; the tool axis
  // tilted kTilt from vertical towards the wall's outward normal.
  const machine::Machine mc = machine::load_machine("xyzbc");
  const machine::Kinematics kin(mc);
  // The C sense: the azimuth of the tool axis in the workpiece frame at B > 0.
  auto axis_of = [&](double b, double c) {
    machine::JointValues q{};
    q[4] = b;
    q[5] = c;
    return Vec3(kin.tool_pose(q).linear().col(2));
  };
  const double beta = deg_to_rad(kTilt);
  const Vec3 a0 = axis_of(beta, 0), a1 = axis_of(beta, 0.1);
  const double az0 = std::atan2(a0.y(), a0.x());
  const double sense = std::remainder(std::atan2(a1.y(), a1.x()) - az0, 2 * kPi) > 0 ? 1 : -1;
  // Wall points: at most 20 um apart and 3 deg of normal turn.
  std::vector<const Outline*> wall;
  std::size_t start = 0;
  for (std::size_t i = 0; i < o.size(); ++i)
    if (o[i].p.x() < o[start].p.x()) start = i;
  wall.push_back(&o[start]);
  for (std::size_t k = 1; k < o.size(); ++k) {
    const Outline& p = o[(start + k) % o.size()];
    if ((p.p - wall.back()->p).norm() >= 0.02 || p.n.dot(wall.back()->n) <= std::cos(deg_to_rad(3))) wall.push_back(&p);
  }
  wall.push_back(&o[start]);  // closes the loop
  struct Pt {
    Vec3 tip;
    double b, c;
  };
  std::vector<Pt> pts;
  double c_prev = 0;
  bool first = true;
  for (double zc = kHeight - 0.05; zc >= kBall + 0.049; zc -= 0.05)
    for (std::size_t i = first ? 0 : 1; i < wall.size(); ++i) {
      const Outline& w = *wall[i];
      const Vec3 axis = (w.n * std::sin(beta) + Vec3::UnitZ() * std::cos(beta)).normalized();
      const Vec3 centre = Vec3(w.p.x(), w.p.y(), zc) + kBall * w.n;
      const double az = std::atan2(axis.y(), axis.x());
      double c = (az - az0) / sense;
      if (!first) c = c_prev + std::remainder(c - c_prev, 2 * kPi);
      first = false;
      c_prev = c;
      pts.push_back({centre - kBall * axis, beta, c});
      const Vec3 check = axis_of(beta, c);
      if ((check - axis).norm() > 1e-9) throw GeometryError({}, "blade: the B/C solve does not give the tool axis");
    }
  std::vector<machine::JointValues> q;
  std::vector<double> path;
  for (std::size_t i = 0; i < pts.size(); ++i) {
    machine::JointValues j{};
    j[4] = pts[i].b;
    j[5] = pts[i].c;
    q.push_back(kin.solve_tip(pts[i].tip, j));
    if (i) path.push_back((pts[i].tip - pts[i - 1].tip).norm());
  }
  const std::vector<double> t = block_times(q, path, 300.0 / 60, mc);
  os << "(finishing: " << pts.size() << " points, tilt " << f(kTilt) << " deg, 0.05 mm a level)\n"
     << "G0 B" << f(kTilt) << " C" << f(rad_to_deg(pts[0].c), 5) << "\nG43.4 H0\n"
     << "G0 X" << f(pts[0].tip.x()) << " Y" << f(pts[0].tip.y()) << " Z" << f(safe) << "\n"
     << "G1 Z" << f(pts[0].tip.z()) << " F100.\nG93\n";
  for (std::size_t i = 1; i < pts.size(); ++i)
    os << "G1 X" << f(pts[i].tip.x()) << " Y" << f(pts[i].tip.y()) << " Z" << f(pts[i].tip.z()) << " C"
       << f(rad_to_deg(pts[i].c), 5) << " F" << f(60.0 / t[i - 1], 3) << "\n";
  os << "G94\nG49\nG0 Z" << f(safe + 1) << "\nM30\n";
  return os.str();
}

}  // namespace

std::vector<File> blade_files() {
  const auto o = outline(12000);
  auto job = [](bool errors) {
    std::string s = std::string("# Reference case 2 (CASES.md, seeds/001): the turbine blade") +
                    (errors ? ", with setting errors" : "") +
                    ".\n# Generated by cutsim-cases; the program and the target are generated at build time.\n"
                    "[program]\ndialect = \"fanuc\"                # G43.4 tool centre point control\n\n"
                    "[stock]\nbox = [-1.9, -1.3, -1, 1.9, 1.5, 2.25]\n\n"
                    "[tool]\nspec = \"ball:d=1,l=3,shank_d=1,shank_l=20\"   # flutes over the blade's full height\n\n"
                    "[machine]\nname = \"xyzbc\"\n";
    if (errors)
      s += "workpiece_setting = \"dx=0.01,gamma=0.002\"   # 10 um off in X, turned 0.11 deg about Z\n"
           "tool_setting = \"dz=0.005\"                  # the ball 5 um longer than the controller's offset\n";
    s += "\n[simulation]\nvoxel_mm = 0.001\nstart = [0, 0, 3]\n\n"
         "[target]\nfile = \"../models/cases/blade.ply\"\ntolerance_mm = 0.002\n";
    if (!errors)
      s += bench_table("max_wall_s = 60\nmax_rss_mb = 4096\n");
    return s;
  };
  const std::string prog = program(o, false);
  return {{"ncprograms/blade.toml", job(false), true},
          {"ncprograms/blade_setting_errors.toml", job(true), true},
          {"ncprograms/blade.nc", prog, false},
          {"ncprograms/blade_setting_errors.nc", program(o, true), false},
          {"models/cases/blade.ply", ply_binary(target_mesh(o)), false}};
}

}  // namespace cutsim::cases
