#include "cutsim/machine/environment.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <sstream>

#include "cutsim/core/error.h"

namespace cutsim::machine {

double edlen_refractive_index(double T, double H, double P) {
  const double p_torr = 0.75 * P;
  const double dry = 3.83639e-7 * p_torr * ((1 + p_torr * (0.817 - 0.0133 * T) * 1e-6) / (1 + 0.003661 * T));
  const double wet = 5.607943e-10 * H * (4.07859739 + 0.44301857 * T + 0.00232093 * T * T + 0.00045785 * T * T * T);
  return 1 + dry - wet;
}

double laser_position_error_mm(double n_ref, double n_now, double dead_path_mm, double distance_from_origin_mm) {
  return (n_ref - n_now) / n_now * (dead_path_mm + distance_from_origin_mm);
}

EnvironmentLog::EnvironmentLog(std::vector<EnvironmentSample> samples) : samples_(std::move(samples)) {
  std::stable_sort(samples_.begin(), samples_.end(),
                   [](const EnvironmentSample& a, const EnvironmentSample& b) { return a.time_s < b.time_s; });
}

EnvironmentSample EnvironmentLog::at(double t) const {
  if (samples_.empty()) return {};
  if (t <= samples_.front().time_s) return samples_.front();
  if (t >= samples_.back().time_s) return samples_.back();
  auto hi = std::upper_bound(samples_.begin(), samples_.end(), t,
                             [](double v, const EnvironmentSample& s) { return v < s.time_s; });
  auto lo = hi - 1;
  const double f = (t - lo->time_s) / (hi->time_s - lo->time_s);
  EnvironmentSample s;
  s.time_s = t;
  s.temperature_c = lo->temperature_c + f * (hi->temperature_c - lo->temperature_c);
  s.humidity_pct = lo->humidity_pct + f * (hi->humidity_pct - lo->humidity_pct);
  s.pressure_hpa = lo->pressure_hpa + f * (hi->pressure_hpa - lo->pressure_hpa);
  return s;
}

double EnvironmentLog::refractive_index(double t) const {
  const EnvironmentSample s = at(t);
  return edlen_refractive_index(s.temperature_c, s.humidity_pct, s.pressure_hpa);
}

EnvironmentLog EnvironmentLog::load_csv(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw InputError(path, "cannot open environment log");
  std::string line;
  int line_no = 0;
  int col[4] = {-1, -1, -1, -1};
  static const char* kNames[4] = {"time_s", "temperature_c", "humidity_pct", "pressure_hpa"};
  std::vector<EnvironmentSample> out;
  while (std::getline(in, line)) {
    ++line_no;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.empty() || line[0] == '#') continue;
    std::vector<std::string> cells;
    std::vector<int> starts;
    std::size_t pos = 0;
    for (;;) {
      const std::size_t comma = line.find(',', pos);
      starts.push_back(static_cast<int>(pos) + 1);
      std::string c = line.substr(pos, comma == std::string::npos ? std::string::npos : comma - pos);
      c.erase(0, c.find_first_not_of(" \t"));
      c.erase(c.find_last_not_of(" \t") + 1);
      cells.push_back(c);
      if (comma == std::string::npos) break;
      pos = comma + 1;
    }
    if (col[0] < 0) {
      for (std::size_t i = 0; i < cells.size(); ++i)
        for (int k = 0; k < 4; ++k)
          if (cells[i] == kNames[k]) col[k] = static_cast<int>(i);
      for (int k = 0; k < 4; ++k)
        if (col[k] < 0)
          throw ParseError(SourceLocation{path, line_no, 1, line},
                           std::string("the header needs a column '") + kNames[k] + "'");
      continue;
    }
    EnvironmentSample s;
    double* dst[4] = {&s.time_s, &s.temperature_c, &s.humidity_pct, &s.pressure_hpa};
    for (int k = 0; k < 4; ++k) {
      const std::size_t i = static_cast<std::size_t>(col[k]);
      if (i >= cells.size())
        throw ParseError(SourceLocation{path, line_no, static_cast<int>(line.size()) + 1, line},
                         std::string("missing value for ") + kNames[k]);
      char* end = nullptr;
      const double v = std::strtod(cells[i].c_str(), &end);
      if (cells[i].empty() || *end != '\0' || !std::isfinite(v))
        throw ParseError(SourceLocation{path, line_no, starts[i], line},
                         std::string("'") + cells[i] + "' is not a number (" + kNames[k] + ")");
      *dst[k] = v;
    }
    if (s.humidity_pct < 0 || s.humidity_pct > 100 || s.pressure_hpa <= 0 || s.temperature_c < -50 || s.temperature_c > 100)
      throw ParseError(SourceLocation{path, line_no, 1, line}, "environment value out of physical range");
    out.push_back(s);
  }
  if (out.empty()) throw ParseError(SourceLocation{path, line_no, 0, {}}, "the environment log has no samples");
  return EnvironmentLog(std::move(out));
}

}  // namespace cutsim::machine
