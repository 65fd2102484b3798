#pragma once
// The air around a laser scale: Edlen's refractive index (seeds/000 eq. 2),
// an environment log over time, and the length error it makes (eqs. 4-5).
#include <string>
#include <vector>

namespace cutsim::machine {

/// Edlen's formula as given in seeds/000 eq. 2: T in degC, H in % relative
/// humidity, P in hPa.
double edlen_refractive_index(double temperature_c, double humidity_pct, double pressure_hpa);

struct EnvironmentSample {
  double time_s = 0;
  double temperature_c = 20;
  double humidity_pct = 50;
  double pressure_hpa = 1013.25;
};

/// A log of the air, linearly interpolated in time (held at its ends).
class EnvironmentLog {
public:
  EnvironmentLog() = default;
  explicit EnvironmentLog(std::vector<EnvironmentSample> samples);
  /// CSV with a header line naming the columns time_s, temperature_c,
  /// humidity_pct, pressure_hpa (any order; extra columns ignored).
  /// @throw InputError / ParseError (file:line:col) for bad files.
  static EnvironmentLog load_csv(const std::string& path);

  bool empty() const { return samples_.empty(); }
  EnvironmentSample at(double time_s) const;
  double refractive_index(double time_s) const;
  const std::vector<EnvironmentSample>& samples() const { return samples_; }

private:
  std::vector<EnvironmentSample> samples_;
};

/// Position error of a laser-fed axis (seeds/000 eq. 4 with the dead path of
/// eq. 5): the controller holds its count, so with the index changed from
/// `n_ref` (when the counter was reset) to `n_now`, the real position is off
/// by ((n_ref - n_now) / n_now) * (dead_path + distance from the counter's origin).
double laser_position_error_mm(double n_ref, double n_now, double dead_path_mm, double distance_from_origin_mm);

}  // namespace cutsim::machine
