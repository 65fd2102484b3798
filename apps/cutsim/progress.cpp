#include <cstdio>
#include <unistd.h>

#include "commands.h"

namespace cutsim::app {

ProgressBar::ProgressBar() : tty_(::isatty(STDERR_FILENO) == 1) {}
ProgressBar::~ProgressBar() { finish(); }

void ProgressBar::update(double fraction, int line) {
  if (!tty_) return;
  const int pct = static_cast<int>(fraction * 100);
  if (pct == last_percent_) return;
  last_percent_ = pct;
  char bar[41];
  const int filled = pct * 40 / 100;
  for (int i = 0; i < 40; ++i) bar[i] = i < filled ? '#' : '.';
  bar[40] = 0;
  std::fprintf(stderr, "\r[%s] %3d%%  line %d ", bar, pct, line);
  std::fflush(stderr);
}

void ProgressBar::finish() {
  if (tty_ && last_percent_ >= 0) {
    std::fprintf(stderr, "\r%60s\r", "");
    std::fflush(stderr);
    last_percent_ = -1;
  }
}

}  // namespace cutsim::app
