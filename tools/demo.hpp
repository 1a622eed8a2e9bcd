// `tetrig demo`: the main job on the project's own default data (owned by the deformation core).
#pragma once

#include <string>

namespace tetrig::tools {

struct DemoOptions {
  int frames = 240;                 // frames to run
  int iterations = 3;               // iterations per frame (also bounded by the deadline)
  double frame_budget_ms = 4.0;     // per-frame deadline
  std::string out_obj;              // write the final deformed surface here (optional)
  bool quiet = false;
};

// Runs the demo, prints a summary; returns a process exit code.
int runDemo(const DemoOptions& options);

}  // namespace tetrig::tools
