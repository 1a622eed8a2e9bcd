// One shape for every marker source: a device (tetrig marker stream over HID or USB, Razer Hydra),
// a playback (C3D clip, raw device recording) or the synthetic source. The frame loop owns a
// MarkerSource and does not care which it is:
//
//   std::unique_ptr<MarkerSource> source = ...;   // make*Source() below, or devices::openMarkerSource()
//   source->start(mailbox);                        // starts the source's driver thread
//   std::vector<std::string> labels;
//   if (!source->waitForLabels(2s, labels)) ...    // "the source never named its markers"
//   ... the solver thread takes frames from the mailbox ...
//   source->stop();                                // joins the driver thread
//
// Marker identity is the label: labels[id] is the label of every Marker whose id is `id` (ids
// that index past the table, or whose label is "", are unnamed). Playback and synthetic sources
// know their labels before start(); a device names its markers after it opens (the marker-stream
// descriptor message, docs/protocol.md; the Hydra's fixed sensor names "hydra0" and "hydra1").
//
// Threads: construct, start(), waitForLabels(), stop(), stats() and finished() from one control
// thread (stats() and finished() from any thread). Frames are produced on the source's own driver
// thread into the mailbox given to start(): that thread is the mailbox's single producer.
#pragma once

#include <chrono>
#include <cstdint>
#include <string>
#include <vector>

#include "tetrig/frame_mailbox.hpp"

namespace tetrig::drivers {

// Counters of a source (relaxed snapshots; any thread).
struct MarkerSourceStats {
  std::uint64_t frames_published = 0;  // frames committed to the mailbox
  std::uint64_t frames_lost = 0;       // frames the device/recording sent that never arrived (sequence gaps)
  std::uint64_t decode_errors = 0;     // reports/records the decoder rejected
  std::uint64_t late_frames = 0;       // paced playback: frames released more than a period late
  std::uint64_t rejected_markers = 0;  // markers invalidated for non-finite or absurd values
  bool connected = false;              // devices: a device is open now; playback: running
};

class MarkerSource {
 public:
  virtual ~MarkerSource() = default;

  // One line for logs and status: kind, what it reads, rate ("c3d:walk.c3d, 41 markers, 120 Hz").
  [[nodiscard]] virtual std::string describe() const = 0;
  // The source's nominal frame rate in Hz (the clip's rate, the device's announced rate, the
  // synthetic rate); 0 when unknown.
  [[nodiscard]] virtual double nominalRateHz() const = 0;
  // Starts the driver thread, which publishes frames into `mailbox` until stop() or the end of
  // a playback. `mailbox` must outlive the running source. Returns false (with a message in
  // lastError()) when the source cannot start. Allocates; control thread.
  virtual bool start(FrameMailbox& mailbox) = 0;
  // Waits until the source has named its markers (at once for playback), at most `timeout`.
  // Returns true and fills `labels` (indexed by marker id); false on timeout. Control thread.
  virtual bool waitForLabels(std::chrono::milliseconds timeout, std::vector<std::string>& labels) = 0;
  // Stops and joins the driver thread. Idempotent; also called by the destructor.
  virtual void stop() = 0;
  // True once a playback has published its last frame (never for live devices).
  [[nodiscard]] virtual bool finished() const noexcept = 0;
  [[nodiscard]] virtual MarkerSourceStats stats() const noexcept = 0;
  // Why start() failed, or the last trouble a device reported ("" when none).
  [[nodiscard]] virtual std::string lastError() const = 0;
};

}  // namespace tetrig::drivers
