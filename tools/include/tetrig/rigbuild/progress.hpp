// Progress reporting for long offline steps, on stderr: an in-place bar when stderr is a terminal,
// one plain line per step otherwise ("always simple"), nothing when quiet.
// Offline; one thread at a time; allocates.
#pragma once

#include <chrono>
#include <string>

namespace tetrig::rigbuild {

class Progress {
 public:
  enum class Mode { kAuto, kSimple, kQuiet };
  Progress(std::string prefix, Mode mode);  // prefix e.g. "tetrig build-rig"
  ~Progress();
  void begin(const std::string& step);      // starts a step
  void update(double fraction);             // 0..1 within the step (drawn only on a terminal)
  void end(const std::string& detail = ""); // finishes the step: "<step>: <detail> (1.23 s)"
  void note(const std::string& line);       // a plain line
  bool quiet() const { return mode_ == Mode::kQuiet; }

 private:
  std::string prefix_, step_;
  Mode mode_;
  bool tty_ = false, open_ = false;
  int last_percent_ = -1;
  std::chrono::steady_clock::time_point start_;
};

}  // namespace tetrig::rigbuild
