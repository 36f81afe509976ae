// Progress display: a bar with ETA on a terminal, plain lines (every few seconds)
// otherwise, so logs stay readable.
#pragma once

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>

namespace tessera {

inline std::string format_duration(double s) {
  char buf[32];
  if (!(s >= 0) || s > 1e7) return "?";
  if (s < 60)
    std::snprintf(buf, sizeof buf, "%.1fs", s);
  else
    std::snprintf(buf, sizeof buf, "%dm%02ds", int(s) / 60, int(s) % 60);
  return buf;
}

class ProgressBar {
 public:
  explicit ProgressBar(bool quiet) : quiet_(quiet), tty_(isatty(STDERR_FILENO)) {}
  // fraction in [0, 1]; `what` describes the current state ("pass 3/8", "12 tiles ...").
  void update(double fraction, const std::string& what, double seconds) {
    if (quiet_ || finished_) return;
    fraction = std::clamp(fraction, 0.0, 1.0);
    finished_ = fraction >= 1;
    const double eta = fraction > 0 ? seconds * (1 - fraction) / fraction : -1;
    if (tty_) {
      drawn_ = !finished_;
      const int width = 30, filled = int(std::lround(fraction * width));
      std::fprintf(stderr, "\r[%s%s] %5.1f%%  %s  %s elapsed  ETA %s   ", std::string(filled, '#').c_str(),
                   std::string(width - filled, '.').c_str(), 100 * fraction, what.c_str(),
                   format_duration(seconds).c_str(), format_duration(eta).c_str());
      if (finished_) std::fprintf(stderr, "\n");
    } else if (finished_ || seconds - last_ >= 5) {
      last_ = seconds;
      std::fprintf(stderr, "progress %.1f%% %s elapsed %s eta %s\n", 100 * fraction, what.c_str(),
                   format_duration(seconds).c_str(), format_duration(eta).c_str());
    }
  }
  // A line of its own to `f` (shown with -q too: not progress), below the bar where one is
  // drawn on the terminal; the next update draws the bar again under it.
  void note(std::FILE* f, const std::string& text) {
    if (drawn_ && f == stderr) std::fputc('\n', stderr);
    drawn_ = false;
    std::fprintf(f, "note: %s\n", text.c_str());
    std::fflush(f);
  }

 private:
  bool quiet_, tty_;
  bool drawn_ = false;  // the bar is on the terminal's current line
  bool finished_ = false;
  double last_ = -1e9;
};

}  // namespace tessera
