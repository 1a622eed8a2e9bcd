// Progress reporting for long offline steps, on stderr: an in-place bar with the time left when
// stderr is a terminal; otherwise (a log, CI, or kSimple) plain lines: one when a step begins and
// ends, and within a step one at every 10 % and at least every 5 s, with the time left
// ("tetrig export: solving 3990 frames 40 % (12.0 s, about 18 s left)"); nothing when quiet.
// Offline; one thread at a time; allocates.
#pragma once

#include <chrono>
#include <cstdio>
#include <string>

namespace tetrig::rigbuild {

class Progress {
 public:
  enum class Mode { kAuto, kSimple, kQuiet };
  Progress(std::string prefix, Mode mode, std::FILE* out = stderr);  // prefix e.g. "tetrig build-rig"
  ~Progress();
  void begin(const std::string& step);      // starts a step
  void update(double fraction);             // 0..1 within the step
  void end(const std::string& detail = ""); // finishes the step: "<step>: <detail> (1.23 s)"
  void note(const std::string& line);       // a plain line
  bool quiet() const { return mode_ == Mode::kQuiet; }

 private:
  std::string prefix_, step_;
  Mode mode_;
  std::FILE* out_;
  bool tty_ = false, open_ = false;
  int last_percent_ = -1;
  std::chrono::steady_clock::time_point start_, last_line_;
};

}  // namespace tetrig::rigbuild
