#pragma once
// The reference cases of CASES.md, generated: target models, NC programs,
// jobs and logs, byte for byte the same on every run (no clocks, no
// randomness, fixed number formatting).
#include <functional>
#include <string>
#include <vector>

#include "cutsim/core/geometry.h"
#include "cutsim/core/mesh.h"

namespace cutsim::cases {

/// One generated file, its path relative to the project root.
struct File {
  std::string path;
  std::string bytes;
  /// Small enough to keep in git; the others are generated at build time.
  bool committed = false;
};

struct Case {
  std::string name;
  std::string summary;
  std::function<std::vector<File>()> generate;
};

/// Every case, in CASES.md order, plus the 40,000-move raster of the speed goals.
const std::vector<Case>& all_cases();
const Case& find_case(const std::string& name);  ///< @throw UsageError for an unknown name

// --- building blocks, shared by the generators and the tests ---

/// "%.*f" with trailing zeros (and a trailing point) removed; "-0" becomes "0".
std::string num(double v, int decimals = 6);

/// A closed height-field solid over a tensor grid: top z = f(x, y) at
/// xs x ys, flat bottom at z_bottom, vertical sides. Triangles face outwards.
TriMesh height_field_solid(const std::vector<double>& xs, const std::vector<double>& ys,
                           const std::function<double(double, double)>& f, double z_bottom);

/// A job's [bench] table holding issue 7's goals (`keys`: its lines,
/// e.g. "max_wall_s = 10\n"), with the comment every such table carries.
std::string bench_table(const std::string& keys);

/// Binary little-endian PLY with double positions.
std::string ply_binary(const TriMesh& m);

/// Grid coordinates from lo to hi: step `fine` inside [fine_lo, fine_hi],
/// growing geometrically (ratio 1.5, capped at `coarse`) outside.
std::vector<double> graded_axis(double lo, double hi, double fine_lo, double fine_hi, double fine, double coarse);

// --- case geometry, exposed for tests ---

namespace snowflake {
constexpr double kCrystalRadius = 0.32;  ///< mm: 640 um across
constexpr double kCurvature = 0.040;     ///< mm: centre to edge
constexpr double kGrooveWidth = 0.005;   ///< mm; 90 deg V grooves, 2.5 um deep
constexpr double kStepDepth = 0.060;     ///< mm below the block top
constexpr double kStepRadius = 0.40;     ///< mm: floor radius; 45 deg wall outside it
constexpr double kPick = 0.008, kLayer = 0.010;
bool inside_crystal(double x, double y);
double target_z(double x, double y);  ///< top of the target, block top at z = 0
}  // namespace snowflake

namespace blade {
constexpr double kHeight = 2.25;  ///< mm, the blade above the base (z = 0)
/// Thickness across the camber at t in [0, 1] (leading to trailing): 0.4 mm
/// at its thickest (t = 0.3), 0.1 mm at the trailing end.
double thickness(double t);
/// Signed distance (mm) to the blade's section in XY: a union of discs on the camber.
double section_distance(double x, double y);
/// The section's outline from its star centre: n rays at equal angles.
struct Outline {
  Vec3 p, n;     ///< point (z = 0) and outward normal
  double angle;  ///< of the ray, radians in [0, 2 pi)
};
std::vector<Outline> outline(int n);
Vec3 star_centre();
}  // namespace blade

namespace lens {
constexpr double kRadius = 300, kHalfAperture = 9, kSpacing = 15, kNose = 0.9789, kOuter = 16.5;
/// Surface height (block top z = 0) and the piece in contact (0, 1 lenses; 2 flat) and its normal.
double z(double x, double y, int* piece = nullptr, Vec3* normal = nullptr);
/// The slow-tool-servo program: normal compensation or keep X steady, at
/// `rpm`, `per_rev` points a revolution and `feed_per_rev` mm; the lines
/// where the contact passes from one piece to another go to `edge_lines`.
std::string program(bool normal_compensation, double rpm, double feed_per_rev, int per_rev,
                    std::vector<int>* edge_lines = nullptr);
}  // namespace lens

}  // namespace cutsim::cases
