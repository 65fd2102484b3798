#include "cutsim/gcode/parameters.h"

namespace cutsim::gcode {

Parameters::Parameters() : numbered_(kMaxNumbered + 1, 0.0) {}

std::optional<double> Parameters::named(const std::string& name) const {
  if (!name.empty() && name[0] == '_') {
    auto it = globals_.find(name);
    if (it == globals_.end()) return std::nullopt;
    return it->second;
  }
  const auto& locals = frames_.empty() ? main_locals_ : frames_.back().locals;
  auto it = locals.find(name);
  if (it == locals.end()) return std::nullopt;
  return it->second;
}

void Parameters::set_named(const std::string& name, double v) {
  if (!name.empty() && name[0] == '_') globals_[name] = v;
  else (frames_.empty() ? main_locals_ : frames_.back().locals)[name] = v;
}

void Parameters::push_call(const std::vector<double>& args) {
  Frame f;
  for (int i = 0; i < 30; ++i) f.saved[static_cast<std::size_t>(i)] = numbered_[static_cast<std::size_t>(i + 1)];
  frames_.push_back(std::move(f));
  for (int i = 0; i < 30; ++i)
    numbered_[static_cast<std::size_t>(i + 1)] = i < static_cast<int>(args.size()) ? args[static_cast<std::size_t>(i)] : 0.0;
}

void Parameters::pop_call() {
  if (frames_.empty()) return;
  for (int i = 0; i < 30; ++i) numbered_[static_cast<std::size_t>(i + 1)] = frames_.back().saved[static_cast<std::size_t>(i)];
  frames_.pop_back();
}

}  // namespace cutsim::gcode
