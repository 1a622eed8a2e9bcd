// Progress bar / step lines on stderr.
#include "tetrig/rigbuild/progress.hpp"

#include <unistd.h>

#include <algorithm>
#include <cstdio>

namespace tetrig::rigbuild {

Progress::Progress(std::string prefix, Mode mode) : prefix_(std::move(prefix)), mode_(mode) {
  tty_ = mode_ == Mode::kAuto && isatty(STDERR_FILENO) == 1;
}

Progress::~Progress() {
  if (open_ && tty_) std::fputs("\n", stderr);
}

void Progress::begin(const std::string& step) {
  if (open_) end();
  step_ = step;
  open_ = true;
  last_percent_ = -1;
  start_ = std::chrono::steady_clock::now();
  if (mode_ == Mode::kQuiet) return;
  if (tty_) {
    std::fprintf(stderr, "\r\033[K%s: %s ...", prefix_.c_str(), step_.c_str());
  } else {
    std::fprintf(stderr, "%s: %s ...\n", prefix_.c_str(), step_.c_str());
  }
  std::fflush(stderr);
}

void Progress::update(double fraction) {
  if (!open_ || !tty_) return;
  const int percent = static_cast<int>(std::clamp(fraction, 0.0, 1.0) * 100.0);
  if (percent == last_percent_) return;
  last_percent_ = percent;
  const int width = 30, filled = percent * width / 100;
  std::string bar(static_cast<std::size_t>(filled), '#');
  bar.append(static_cast<std::size_t>(width - filled), '.');
  std::fprintf(stderr, "\r\033[K%s: %s [%s] %3d%%", prefix_.c_str(), step_.c_str(), bar.c_str(), percent);
  std::fflush(stderr);
}

void Progress::end(const std::string& detail) {
  if (!open_) return;
  open_ = false;
  if (mode_ == Mode::kQuiet) return;
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  std::fprintf(stderr, "%s%s: %s%s%s (%.2f s)\n", tty_ ? "\r\033[K" : "", prefix_.c_str(), step_.c_str(), detail.empty() ? "" : ": ",
               detail.c_str(), s);
  std::fflush(stderr);
}

void Progress::note(const std::string& line) {
  if (mode_ == Mode::kQuiet) return;
  std::fprintf(stderr, "%s%s: %s\n", (open_ && tty_) ? "\r\033[K" : "", prefix_.c_str(), line.c_str());
}

}  // namespace tetrig::rigbuild
