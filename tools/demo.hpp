// `tetrig demo`: the main job. It runs the whole live path - a marker source on its driver thread
// -> mailbox -> solver thread (deformation + pose transfer into shared memory) -> a consumer
// process reading the segment (tetrig-shm-cat) - either on the project's own default data (the
// default character, driven by the synthetic source's performance) or, with --mesh and
// --c3d, on real data (the rig is built once and cached). Then it writes a report folder
// (tools/demo_report.hpp, docs/demo.md): summary.json, a picture sheet and a latency plot.
#pragma once

#include "tetrig/solver_settings.hpp"

#include <cstdint>
#include <string>

namespace tetrig::tools {

struct DemoOptions {
  std::uint64_t frames = 0;         // frames to solve; 0: one pass of the default performance, or the whole clip with --c3d
  int iterations = 3;               // iterations per frame (also bounded by the budget)
  SolverSettings solver;            // the solver (tools/solver_flags.hpp: the flags of `tetrig run`)
  double frame_budget_ms = 0;       // receive -> published deadline; 0: from the source rate
  std::string out_obj;              // write the final deformed surface here (optional)
  std::string mesh, c3d;            // real data: build (or reuse) a rig from these and play the clip
  double max_marker_distance = 0;   // real data: the rig builder's limit (0: its default)
  std::string publish;              // segment name (default: tetrig-demo-<pid>)
  bool quiet = false;
  std::string report = "tetrig-demo-report";  // the report folder (tools/demo_report.hpp)
  bool no_report = false;
  int sheet_frames = 12;            // frames on the picture sheet (4 per row)
};

// Runs the demo, prints a summary, writes the report and says where; returns a process exit code.
// Throws (one line) on bad input and when a part of the report cannot be made.
int runDemo(const DemoOptions& options);

}  // namespace tetrig::tools
