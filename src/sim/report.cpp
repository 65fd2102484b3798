#include "cutsim/sim/report.h"

#include <cctype>
#include <cmath>
#include <cstdio>
#include <sstream>

#include <nlohmann/json.hpp>

#include "cutsim/sim/interference.h"

namespace cutsim::sim {

namespace {

// `on line 7` or `on lines 7-12`.
std::string line_span(int first, int last) {
  return first == last ? "on line " + std::to_string(first)
                       : "on lines " + std::to_string(first) + "-" + std::to_string(last);
}
nlohmann::json box_json(const Aabb& b) {
  return {b.min.x(), b.min.y(), b.min.z(), b.max.x(), b.max.y(), b.max.z()};
}
}  // namespace

std::vector<std::pair<std::string, double>> comparison_fields(const compare::CompareResult& c) {
  return {{"overcut_volume_mm3", c.overcut_volume_mm3},   {"undercut_volume_mm3", c.undercut_volume_mm3},
          {"overcut_volume_um3", c.overcut_volume_mm3 * 1e9}, {"undercut_volume_um3", c.undercut_volume_mm3 * 1e9},
          {"max_overcut_mm", c.max_overcut_mm},           {"max_undercut_mm", c.max_undercut_mm},
          {"tolerance_mm", c.tolerance_mm},               {"fraction_in_tolerance", c.fraction_in_tolerance},
          {"region_mesh_voxel_mm", c.region_mesh_voxel_mm}};
}

std::string comparison_text(const compare::CompareResult& c) {
  char buf[512];
  std::snprintf(buf, sizeof buf,
                "target: overcut %.6g mm3 (%.4g um3), undercut %.6g mm3 (%.4g um3); max overcut %.3g um, max undercut "
                "%.3g um; %.1f %% of the surface within +-%.3g um\n",
                c.overcut_volume_mm3, c.overcut_volume_mm3 * 1e9, c.undercut_volume_mm3, c.undercut_volume_mm3 * 1e9,
                c.max_overcut_mm * 1e3, c.max_undercut_mm * 1e3, 100 * c.fraction_in_tolerance, c.tolerance_mm * 1e3);
  return buf;
}

std::string report_json(const SimResult& r, const ReportOutputs& out) {
  nlohmann::ordered_json j;
  const auto st = r.stock->stats();
  j["program"] = r.program;
  if (r.interrupted) {
    j["partial"] = true;
    j["stopped_after_line"] = r.last_line_cut;
    j["interrupted"] = r.interrupt_message;
  }
  j["blocks"] = r.blocks;
  j["lines"] = r.lines;
  j["moves"] = r.moves;
  j["cutting_moves"] = r.cutting_moves;
  j["tool"] = {{"spec", r.tool.name}, {"diameter_mm", r.tool.diameter_mm},
               {"corner_radius_mm", r.tool.corner_radius_mm}, {"flute_length_mm", r.tool.flute_length_mm},
               {"control_point", "tool tip on the axis"}};
  if (!r.tool_library.empty()) j["tool_library"] = r.tool_library;
  nlohmann::ordered_json tu = nlohmann::ordered_json::array();
  for (const auto& t : r.tools_used)
    tu.push_back({{"number", t.number}, {"name", t.name}, {"kind", tool::kind_name(t.kind)}});
  j["tools_used"] = tu;
  j["stock_box_mm"] = box_json(r.stock_box);
  j["roi_mm"] = box_json(r.stock->roi());
  j["voxel_size_mm"] = r.voxel_mm;
  j["stock_volume_before_mm3"] = r.stock->initial_volume_mm3();
  j["stock_volume_after_mm3"] = r.stock->volume_mm3();
  j["removed_volume_mm3"] = r.stock->removed_volume_mm3();
  j["machine"] = r.machine;
  j["program_time_s"] = r.program_time_s;
  nlohmann::ordered_json v = nlohmann::ordered_json::array();
  for (const auto& a : r.axis_limit_violations)
    v.push_back({{"line", a.line}, {"text", a.text ? *a.text : ""}, {"axis", std::string(1, a.axis)},
                 {"quantity", a.quantity}, {"value", a.value}, {"limit", a.limit}, {"unit", a.unit}});
  j["axis_limit_violations"] = v;
  nlohmann::ordered_json vk = nlohmann::ordered_json::array();
  for (const machine::ViolationKind& k : machine::summarize_violations(r.axis_limit_violations)) {
    const machine::AxisViolation& w = r.axis_limit_violations[k.worst];
    vk.push_back({{"axis", std::string(1, k.axis)}, {"quantity", k.quantity}, {"unit", k.unit}, {"limit", k.limit},
                  {"records", k.records}, {"first_line", k.first_line}, {"last_line", k.last_line},
                  {"worst_line", w.line}, {"worst_value", w.value}});
  }
  j["axis_limit_summary"] = vk;
  nlohmann::ordered_json al = nlohmann::ordered_json::array();
  for (const auto& a : r.amplitude_limits)
    al.push_back({{"axis", std::string(1, a.axis)}, {"frequency_hz", a.frequency_hz},
                  {"amplitude_mm", a.amplitude_mm}, {"limited_by", a.limited_by}});
  j["amplitude_limits"] = al;
  j["laser_scale"] = {{"applied", r.laser_error_applied}, {"max_error_um", r.max_laser_error_mm * 1000}};
  if (r.profile) {
    const Profile& p = *r.profile;
    nlohmann::ordered_json h = nlohmann::ordered_json::array();
    for (double z : p.height_mm) h.push_back(std::isfinite(z) ? nlohmann::ordered_json(z) : nlohmann::ordered_json());
    j["profile"] = {{"along", std::string(1, p.spec.along)}, {"at_mm", p.spec.at}, {"from_mm", p.spec.from},
                    {"to_mm", p.spec.to}, {"step_mm", p.spec.step}, {"pv_um", p.pv_mm * 1000},
                    {"pv_detrended_um", p.pv_detrended_mm * 1000}, {"height_mm", h}};
  }
  if (r.comparison)
    for (const auto& [k, v] : comparison_fields(*r.comparison)) j[k] = v;
  j["contact_tolerance_mm"] = r.contact_tolerance_mm;
  if (r.stopped_at_contact) j["stopped_at_contact"] = true;
  nlohmann::ordered_json cs = nlohmann::ordered_json::array();
  for (const auto& c : r.contacts)
    cs.push_back({{"line", c.line}, {"text", c.text}, {"region", c.region}, {"rapid", c.rapid},
                  {"position_mm", {c.where.x(), c.where.y(), c.where.z()}}, {"depth_mm", c.depth_mm},
                  {"depth_at_least", c.at_least}, {"poses", c.poses}});
  j["contacts"] = cs;
  nlohmann::ordered_json ks = nlohmann::ordered_json::array();
  for (const ContactKind& k : summarize_contacts(r.contacts)) {
    const Contact& d = r.contacts[k.deepest];
    ks.push_back({{"region", k.region}, {"rapid", k.rapid}, {"records", k.records}, {"depth_at_least", k.at_least},
                  {"first_line", k.first_line}, {"last_line", k.last_line}, {"deepest_line", d.line},
                  {"deepest_mm", d.depth_mm}, {"deepest_at_least", d.at_least}});
  }
  j["contact_summary"] = ks;
  j["contact_poses"] = r.contact_poses;
  j["contact_poses_cleared_by_runs"] = r.poses_cleared_by_runs;
  j["active_voxels"] = st.active_voxels;
  j["voxel_evaluations"] = st.voxel_evaluations;
  if (st.band_voxels) j["band_voxels"] = st.band_voxels;
  j["voxels_aired_by_quarter"] = st.voxels_aired;
  j["blocks_aired_whole"] = st.blocks_aired;
  j["stock_update_batches"] = st.grid_updates;
  j["leaf_nodes"] = st.leaf_nodes;
  j["idle_leaves"] = st.idle_leaves;
  j["grid_memory_mb"] = static_cast<double>(st.memory_bytes) / 1048576.0;
  nlohmann::ordered_json w = nlohmann::ordered_json::array();
  for (const auto& x : r.warnings) w.push_back({{"line", x.line}, {"column", x.column}, {"message", x.message}});
  j["warnings"] = w;
  j["defaults"] = r.defaults.notes;
  j["outputs"] = {{"glb", out.glb}, {"report", out.report}};
  if (!out.vdb.empty()) j["outputs"]["vdb"] = out.vdb;
  j["timing_s"] = {{"parse", r.timing.parse_s}, {"simulate", r.timing.simulate_s},
                   {"export", r.timing.export_s}, {"total", r.timing.total_s},
                   {"stock_build", r.timing.stock_build_s}, {"plan_and_sweep", r.timing.plan_sweep_s},
                   {"stock_update", r.timing.stock_update_s}, {"contact_check", r.timing.contact_check_s},
                   {"mesh", r.timing.mesh_s}, {"compare", r.timing.compare_s}, {"write", r.timing.write_s},
                   {"stock_update_steps", {{"bin", st.bin_s}, {"classify", st.classify_s},
                                           {"topology", st.topology_s}, {"voxels", st.voxels_s}}}};
  j["stock_page_kb"] = r.stock_page_kb;
  j["peak_rss_simulate_mb"] = r.timing.peak_rss_simulate_mb;
  j["peak_rss_mb"] = peak_rss_mb();
  return j.dump(2) + "\n";
}

std::string format_violation_kind(const machine::ViolationKind& k, const std::vector<machine::AxisViolation>& v) {
  const machine::AxisViolation& w = v[k.worst];
  char buf[256];
  std::snprintf(buf, sizeof buf, "%c %s: %zu %s, the most %.4g %s at line %d (limit %.4g)", k.axis, k.quantity.c_str(),
                k.records, line_span(k.first_line, k.last_line).c_str(), w.value, k.unit.c_str(), w.line, k.limit);
  return buf;
}

std::string report_text(const SimResult& r, const ReportOutputs& out) {
  std::ostringstream os;
  char buf[512];
  for (const auto& n : r.defaults.notes) os << "note: " << n << "\n";
  std::snprintf(buf, sizeof buf, "%s: %d blocks, %d moves (%d cutting), machine %s, tool %s, voxel %g mm, program time %.1f s\n",
                r.program.c_str(), r.blocks, r.moves, r.cutting_moves, r.machine.c_str(), r.tool.name.c_str(),
                r.voxel_mm, r.program_time_s);
  os << buf;
  std::snprintf(buf, sizeof buf, "stock %.6f mm3 -> %.6f mm3, removed %.6f mm3\n",
                r.stock->initial_volume_mm3(), r.stock->volume_mm3(), r.stock->removed_volume_mm3());
  os << buf;
  for (const auto& x : r.warnings) os << r.program << ":" << x.line << ": warning: " << x.message << "\n";
  if (r.comparison) os << comparison_text(*r.comparison);
  if (r.profile) {
    const Profile& p = *r.profile;
    std::snprintf(buf, sizeof buf, "profile along %c at %c = %g mm: form error PV %.1f nm (%.1f nm without the tilt), %zu samples\n",
                  std::toupper(p.spec.along), p.spec.along == 'x' ? 'Y' : 'X', p.spec.at, p.pv_mm * 1e6,
                  p.pv_detrended_mm * 1e6, p.height_mm.size());
    os << buf;
  }
  // Many records (of either kind): a line per kind first, then the 20 that
  // matter most, in program order, then a count of the rest.
  constexpr std::size_t kShown = 20;
  if (r.axis_limit_violations.size() > kShown) {
    os << r.axis_limit_violations.size() << " axis-limit violations:\n";
    for (const machine::ViolationKind& k : machine::summarize_violations(r.axis_limit_violations))
      os << "  " << format_violation_kind(k, r.axis_limit_violations) << "\n";
    os << "the " << kShown << " furthest over their limits, in program order:\n";
  }
  for (const std::size_t i : machine::worst_violations(r.axis_limit_violations, kShown)) {
    const auto& a = r.axis_limit_violations[i];
    std::snprintf(buf, sizeof buf, "%s:%d: %c %s %.4g %s over the limit %.4g: %s\n", r.program.c_str(), a.line, a.axis,
                  a.quantity.c_str(), a.value, a.unit.c_str(), a.limit, a.text ? a.text->c_str() : "");
    os << buf;
  }
  if (r.axis_limit_violations.size() > kShown)
    os << "... and " << r.axis_limit_violations.size() - kShown << " more axis-limit violations (see the report)\n";
  if (r.contacts.size() > kShown) {
    os << r.contacts.size() << " contacts:\n";
    for (const ContactKind& k : summarize_contacts(r.contacts)) {
      const Contact& d = r.contacts[k.deepest];
      const std::string kind = k.rapid ? "rapid (" + k.region + ")" : k.region;
      std::snprintf(buf, sizeof buf, "  %s: %zu %s, deepest %s%.3g um at line %d", kind.c_str(), k.records,
                    line_span(k.first_line, k.last_line).c_str(),
                    d.at_least ? "at least " : "", d.depth_mm * 1000, d.line);
      os << buf;
      // (A depth that reached the band is the band's: the deepest then is one.)
      if (k.at_least) {
        std::snprintf(buf, sizeof buf, "; %zu of them at least %.3g um (the stock's band)", k.at_least, d.depth_mm * 1000);
        os << buf;
      }
      os << "\n";
    }
    os << "the " << kShown
       << " that matter most (rapids, then holder, shank and neck, then the deepest), in program order:\n";
  }
  for (const std::size_t i : most_severe_contacts(r.contacts, kShown))
    os << format_contact(r.contacts[i], r.program) << "\n";
  if (r.contacts.size() > kShown)
    os << "... and " << r.contacts.size() - kShown << " more contacts (see the report)\n";
  if (r.stopped_at_contact) os << "stopped at the first contact (stop_at_first_contact)\n";
  for (const auto& a : r.amplitude_limits) {
    std::snprintf(buf, sizeof buf, "amplitude limit %c at %.3g Hz: %.4g mm (%s)\n", a.axis, a.frequency_hz,
                  a.amplitude_mm, a.limited_by.c_str());
    os << buf;
  }
  std::snprintf(buf, sizeof buf,
                "time: parse %.2f s, simulate %.2f s (stock update %.2f, contact check %.2f), export %.2f s (mesh %.2f, "
                "compare %.2f, write %.2f), total %.2f s; peak RSS %.0f MB (%.0f MB when the simulation ended)\n",
                r.timing.parse_s, r.timing.simulate_s, r.timing.stock_update_s, r.timing.contact_check_s,
                r.timing.export_s, r.timing.mesh_s, r.timing.compare_s, r.timing.write_s, r.timing.total_s,
                peak_rss_mb(), r.timing.peak_rss_simulate_mb);
  os << buf;
  if (!out.glb.empty()) os << "wrote " << out.glb << "\n";
  if (!out.vdb.empty()) os << "wrote " << out.vdb << "\n";
  if (!out.report.empty()) os << "wrote " << out.report << "\n";
  return os.str();
}

}  // namespace cutsim::sim
