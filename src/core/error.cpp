#include "cutsim/core/error.h"
#include "cutsim/core/interrupt.h"

namespace cutsim {

std::atomic<int>& interrupt_signal() {
  static std::atomic<int> sig{0};
  return sig;
}

namespace {
std::string compose(const SourceLocation& w, const std::string& message) {
  std::string s;
  if (!w.file.empty()) {
    s.append(w.file);
    if (w.line > 0) {
      s.append(":").append(std::to_string(w.line));
      if (w.column > 0) s.append(":").append(std::to_string(w.column));
    }
    s.append(": ");
  }
  s.append("error: ").append(message);
  return s;
}
}  // namespace

Error::Error(ExitCode code, SourceLocation where, const std::string& message)
    : std::runtime_error(compose(where, message)),
      code_(code),
      where_(std::move(where)),
      message_(message) {}

std::string Error::format() const {
  std::string s = what();
  if (where_.line > 0 && !where_.source_line.empty()) {
    std::string line = where_.source_line;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    s += "\n  " + line;
    if (where_.column > 0) {
      s += "\n  ";
      // Keep tabs so the caret lines up under the offending column.
      for (int i = 1; i < where_.column && i <= static_cast<int>(line.size()); ++i)
        s += (line[static_cast<std::size_t>(i - 1)] == '\t') ? '\t' : ' ';
      s += '^';
    }
  }
  return s;
}

}  // namespace cutsim
