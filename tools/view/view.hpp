// `tetrig view`: a window that follows a shared-memory segment (docs/view.md). GLFW window with
// an OpenGL 3.3 core context (libepoxy), the segment read with the C99 reader tetrig_shm.h like
// tetrig-shm-cat, the newest frame drawn with the renderer's MeshDrawer (shaded surface, floor
// grid) plus an overlay (frame id, producer rate, latency from the segment's timestamps,
// producer state) and, with --markers (M), the frame's markers as dots coloured by state (layout
// 1.1). Orbit by dragging, zoom by scrolling, R resets, F follows the figure. Waits for the producer,
// keeps the last frame when it stops, re-opens the segment when a new producer replaces it.
// --screenshot FILE.png writes the picture after N new frames and exits 0 (headless: xvfb-run).
//
// Tools only: allocates at start and when a producer (re)appears; throws std::runtime_error or
// std::invalid_argument with one line (bad arguments, no display, unusable segment, timeout).
#pragma once

#include <cstdint>
#include <string>

namespace tetrig::tools {

struct ViewOptions {
  std::string name = "tetrig";   // segment, e.g. tetrig or /tetrig (the leading '/' is added); tetrig run's default
  bool markers = false;          // marker dots coloured by state (layout 1.1) and the overlay's markers line
  bool follow = false;           // keep the camera on the newest frame's centre (F toggles it)
  std::string screenshot;        // PNG to write after `after_frames` new frames, then exit; "" = interactive
  int after_frames = 30;         // new frames (any producer instance) before the screenshot
  double timeout_s = 30.0;       // --screenshot: fail when the frames did not come within this time
  int width = 1280, height = 720;
  std::string up = "y";          // the rig's up axis: x, y or z (rigs keep their mesh's axes; y by default)
  double stale_ms = 1000.0;      // heartbeat age that counts as "not responding"
  bool quiet = false;            // no status lines on stderr
  bool dds = false;              // read NAME's DDS topics (tetrig/NAME/frame, /static) instead of the segment (docs/dds.md)
};

// The overlay's reading of a frame's flags (tetrig_shm.h TETRIG_SHM_FRAME_*): the names of the
// bits set, comma-separated ("pose held, markers predicted"), unknown bits as one hex value;
// "" for 0.
std::string frameFlagText(std::uint32_t flags);

// Runs the window until it is closed (exit 0) or, with a screenshot, until the file is written.
int runView(const ViewOptions& options);

}  // namespace tetrig::tools
