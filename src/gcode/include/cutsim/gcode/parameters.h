#pragma once
// RS274NGC parameters: numbered #1..#5602, named locals #<name> (scoped to
// a subroutine call) and globals #<_name>.
#include <array>
#include <optional>
#include <string>
#include <unordered_map>
#include <vector>

namespace cutsim::gcode {

class Parameters {
public:
  static constexpr int kMaxNumbered = 5602;

  Parameters();
  /// Numbered parameters read 0 until set.
  double numbered(int n) const { return numbered_[static_cast<std::size_t>(n)]; }
  void set_numbered(int n, double v) { numbered_[static_cast<std::size_t>(n)] = v; }
  /// Named parameters (name already lower-cased, without spaces).
  std::optional<double> named(const std::string& name) const;
  void set_named(const std::string& name, double v);

  /// Subroutine call: #1..#30 and named locals are saved, #1..#30 set to args.
  void push_call(const std::vector<double>& args);
  /// Return: restores what push_call saved.
  void pop_call();
  int call_depth() const { return static_cast<int>(frames_.size()); }

private:
  std::vector<double> numbered_;
  std::unordered_map<std::string, double> globals_;
  struct Frame {
    std::array<double, 30> saved{};
    std::unordered_map<std::string, double> locals;
  };
  std::vector<Frame> frames_;
  std::unordered_map<std::string, double> main_locals_;
};

}  // namespace cutsim::gcode
