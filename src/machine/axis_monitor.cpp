#include "cutsim/machine/axis_monitor.h"

#include <algorithm>
#include <cmath>

#include "cutsim/core/ranking.h"

namespace cutsim::machine {

AmplitudeLimit amplitude_limit(const Joint& j, double f) {
  AmplitudeLimit a;
  a.axis = j.axis;
  a.frequency_hz = f;
  const double w = 2 * kPi * f;
  a.amplitude_mm = (j.stroke_max - j.stroke_min) / 2;
  a.limited_by = "stroke";
  if (j.max_velocity > 0 && j.max_velocity / w < a.amplitude_mm) {
    a.amplitude_mm = j.max_velocity / w;
    a.limited_by = "velocity";
  }
  if (j.max_acceleration > 0 && j.max_acceleration / (w * w) < a.amplitude_mm) {
    a.amplitude_mm = j.max_acceleration / (w * w);
    a.limited_by = "acceleration";
  }
  return a;
}

AxisMonitor::AxisMonitor(const Machine& m, const JointValues& start)
    : m_(m), q_(start), v_(m.chain.size(), 0.0), revs_(m.chain.size(), 0.0), turn_time_(m.chain.size(), 0.0) {}

void AxisMonitor::flag(std::size_t j, int line, const std::shared_ptr<const std::string>& text, const char* what,
                       double v, double lim) {
  const Joint& jt = m_.chain[j];
  const bool rot = jt.type == JointType::rotary;
  const double k = rot ? 180 / kPi : 1.0;
  // One record per line, axis and quantity: the largest value.
  for (auto it = out_.rbegin(); it != out_.rend() && it->line == line; ++it)
    if (it->axis == jt.axis && it->quantity == what) {
      it->value = std::max(it->value, std::fabs(v) * k);
      return;
    }
  AxisViolation a;
  a.line = line;
  a.text = text;
  a.axis = jt.axis;
  a.quantity = what;
  a.value = std::fabs(v) * k;
  a.limit = lim * k;
  const std::string u = rot ? "deg" : "mm";
  a.unit = std::string(what) == "velocity" ? u + "/s" : std::string(what) == "acceleration" ? u + "/s^2" : u;
  out_.push_back(std::move(a));
}

void AxisMonitor::step(const JointValues& q, double dt, bool feed, int line, const std::shared_ptr<const std::string>& text,
                       double block_dt, bool first) {
  if (block_dt < 0) block_dt = dt;
  const double span = first ? 0.5 * (block_dt + block_dt_prev_) : 0.5 * (dt + dt_prev_);
  for (std::size_t j = 0; j < m_.chain.size(); ++j) {
    const Joint& jt = m_.chain[j];
    const std::size_t i = static_cast<std::size_t>(axis_index(jt.axis));
    const double dq = q[i] - q_[i];
    const double v = dt > 0 ? dq / dt : 0.0;
    if (q[i] < jt.stroke_min - 1e-9 || q[i] > jt.stroke_max + 1e-9)
      flag(j, line, text, "stroke", q[i], q[i] < jt.stroke_min ? jt.stroke_min : jt.stroke_max);
    if (feed && jt.max_velocity > 0 && std::fabs(v) > jt.max_velocity * (1 + 1e-9))
      flag(j, line, text, "velocity", v, jt.max_velocity);
    if (feed && moving_ && jt.max_acceleration > 0) {
      const double a = (v - v_[j]) / span;
      if (std::fabs(a) > jt.max_acceleration * (1 + 1e-9)) flag(j, line, text, "acceleration", a, jt.max_acceleration);
    }
    v_[j] = feed ? v : 0.0;
    if (jt.type == JointType::rotary && std::fabs(dq) > 0) {
      revs_[j] += std::fabs(dq) / (2 * kPi);
      turn_time_[j] += dt;
    }
  }
  q_ = q;
  dt_prev_ = dt;
  block_dt_prev_ = block_dt;
  moving_ = feed && dt > 0;
}

void AxisMonitor::rest() {
  std::fill(v_.begin(), v_.end(), 0.0);
  moving_ = false;
}

double excess(const AxisViolation& a) { return a.limit > 0 ? a.value / a.limit : a.value; }

std::vector<std::size_t> worst_violations(const std::vector<AxisViolation>& v, std::size_t n) {
  return first_n_in_order(v.size(), n, [&](std::size_t a, std::size_t b) {
    const double ea = excess(v[a]), eb = excess(v[b]);
    if (ea != eb) return ea > eb;
    return a < b;
  });
}

std::vector<ViolationKind> summarize_violations(const std::vector<AxisViolation>& v) {
  const RecordGroups g = group_records(
      v.size(), [&](std::size_t a, std::size_t b) { return v[a].axis == v[b].axis && v[a].quantity == v[b].quantity; },
      [&](std::size_t a, std::size_t b) { return excess(v[a]) > excess(v[b]); }, [&](std::size_t i) { return v[i].line; });
  std::vector<ViolationKind> kinds;
  for (const RecordGroups::Group& k : g.groups) {
    const AxisViolation& a = v[k.first];
    kinds.push_back({a.axis, a.quantity, a.unit, a.limit, k.records, k.worst, k.first_line, k.last_line});
  }
  std::sort(kinds.begin(), kinds.end(), [](const ViolationKind& a, const ViolationKind& b) {
    return a.axis != b.axis ? a.axis < b.axis : a.quantity < b.quantity;
  });
  return kinds;
}

}  // namespace cutsim::machine
