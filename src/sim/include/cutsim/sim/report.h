#pragma once
// The run report (JSON) and its console summary.
#include <string>
#include <utility>
#include <vector>

#include "cutsim/sim/simulate.h"

namespace cutsim::sim {

struct ReportOutputs {
  std::string glb;     ///< path written, empty if none
  std::string report;  ///< path of the report itself
  std::string vdb;     ///< stock grid (--save-vdb), empty if none
};

/// The report as JSON text. Fields: program, blocks, lines, moves,
/// cutting_moves, tool, stock_box_mm, roi_mm, voxel_size_mm,
/// stock_volume_before_mm3, stock_volume_after_mm3, removed_volume_mm3,
/// active_voxels, leaf_nodes, warnings, defaults, outputs, timing_s
/// {parse, simulate, export, total}, peak_rss_mb.
std::string report_json(const SimResult& r, const ReportOutputs& out);

/// The comparison's figures as report fields, in report order:
/// overcut/undercut volumes (mm^3 and um^3), max overcut/undercut,
/// tolerance_mm, fraction_in_tolerance. Shared by run and compare.
std::vector<std::pair<std::string, double>> comparison_fields(const compare::CompareResult& c);
/// The comparison's one-line summary (`target: overcut ...`), with newline.
std::string comparison_text(const compare::CompareResult& c);

/// A short human summary (several lines).
std::string report_text(const SimResult& r, const ReportOutputs& out);

/// One axis and quantity's records in a line (`X acceleration: 398 on lines
/// 205-39806, the most 2222 mm/s^2 at line 16005 (limit 2000)`), no newline;
/// `v` the records `k` was made from. Shared by run and check.
std::string format_violation_kind(const machine::ViolationKind& k, const std::vector<machine::AxisViolation>& v);

}  // namespace cutsim::sim
