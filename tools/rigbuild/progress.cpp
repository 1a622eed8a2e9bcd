// Progress bar / step lines on stderr.
#include "tetrig/rigbuild/progress.hpp"

#include <unistd.h>

#include <algorithm>
#include <cstdio>

namespace tetrig::rigbuild {

namespace {

// " (12.0 s, about 18 s left)" once a step has run a second and done 2 %, else " (12.0 s)".
std::string timeText(double elapsed, double fraction) {
  char buf[80];
  if (elapsed >= 1.0 && fraction >= 0.02 && fraction < 1.0) {
    std::snprintf(buf, sizeof buf, " (%.1f s, about %.0f s left)", elapsed, elapsed * (1.0 - fraction) / fraction);
  } else {
    std::snprintf(buf, sizeof buf, " (%.1f s)", elapsed);
  }
  return buf;
}

}  // namespace

Progress::Progress(std::string prefix, Mode mode, std::FILE* out) : prefix_(std::move(prefix)), mode_(mode), out_(out) {
  tty_ = mode_ == Mode::kAuto && isatty(fileno(out_)) == 1;
}

Progress::~Progress() {
  if (open_ && tty_) std::fputs("\n", out_);
}

void Progress::begin(const std::string& step) {
  if (open_) end();
  step_ = step;
  open_ = true;
  last_percent_ = -1;
  start_ = last_line_ = std::chrono::steady_clock::now();
  if (mode_ == Mode::kQuiet) return;
  if (tty_) {
    std::fprintf(out_, "\r\033[K%s: %s ...", prefix_.c_str(), step_.c_str());
  } else {
    std::fprintf(out_, "%s: %s ...\n", prefix_.c_str(), step_.c_str());
  }
  std::fflush(out_);
}

void Progress::update(double fraction) {
  if (!open_ || mode_ == Mode::kQuiet) return;
  fraction = std::clamp(fraction, 0.0, 1.0);
  const int percent = static_cast<int>(fraction * 100.0);
  const auto now = std::chrono::steady_clock::now();
  const double elapsed = std::chrono::duration<double>(now - start_).count();
  if (tty_) {
    if (percent == last_percent_) return;
    last_percent_ = percent;
    const int width = 30, filled = percent * width / 100;
    std::string bar(static_cast<std::size_t>(filled), '#');
    bar.append(static_cast<std::size_t>(width - filled), '.');
    std::fprintf(out_, "\r\033[K%s: %s [%s] %3d%%%s", prefix_.c_str(), step_.c_str(), bar.c_str(), percent,
                 timeText(elapsed, fraction).c_str());
    std::fflush(out_);
    return;
  }
  // A log: a line at every 10 % passed, and at least every 5 s.
  const int decile = percent / 10;
  const bool new_decile = decile > last_percent_ / 10 && decile > 0 && percent < 100;
  const bool overdue = std::chrono::duration<double>(now - last_line_).count() >= 5.0;
  if (!new_decile && !overdue) return;
  if (new_decile) last_percent_ = decile * 10;
  last_line_ = now;
  std::fprintf(out_, "%s: %s %d %%%s\n", prefix_.c_str(), step_.c_str(), percent, timeText(elapsed, fraction).c_str());
  std::fflush(out_);
}

void Progress::end(const std::string& detail) {
  if (!open_) return;
  open_ = false;
  if (mode_ == Mode::kQuiet) return;
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  std::fprintf(out_, "%s%s: %s%s%s (%.2f s)\n", tty_ ? "\r\033[K" : "", prefix_.c_str(), step_.c_str(), detail.empty() ? "" : ": ",
               detail.c_str(), s);
  std::fflush(out_);
}

void Progress::note(const std::string& line) {
  if (mode_ == Mode::kQuiet) return;
  std::fprintf(out_, "%s%s: %s\n", (open_ && tty_) ? "\r\033[K" : "", prefix_.c_str(), line.c_str());
}

}  // namespace tetrig::rigbuild
