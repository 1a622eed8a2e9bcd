// C3D playback source: replays a loaded C3DClip as MarkerFrames, paced in real time from the
// clip's frame rate (sleeping on a steady clock) or as fast as possible, optionally looping, with
// unit conversion (file units -> mm), an axis conversion (3x3 matrix and scale) and a point
// selection (physical markers only by default: unlabeled "*n" points and modelled outputs listed
// in POINT:ANGLES/FORCES/MOMENTS/POWERS/... are skipped).
//
// Output convention (one documented transform, applied in this order):
//     p_out = axes.scale * axes.matrix * (unitsToMm * p_file)
// axes.matrix is row-major. With the default identity matrix and scale 1 the output is the
// file's axes in millimetres, which is MarkerFrame's contract (the runtime's marker binding maps
// to the rig's unit and axes). A scale other than 1 leaves MarkerFrame's "mm" convention: use it
// only for consumers that expect another unit.
//
// Each published frame: frame_counter = output index (0, 1, 2, ... continuing across loops);
// device_timestamp_ns = frame_counter * frame period (the clip's time line, continuing across
// loops); receive_timestamp_ns = the pacing clock right before the sink call; markers[k].id = the
// C3D point index of the k-th selected point; valid = 0 for invalid samples (position 0).
// Non-finite results are marked invalid and counted in rejected_count (kFrameRejectedMarkers);
// more than kMaxMarkers selected points sets kFrameTruncatedMarkers.
#pragma once

#include <array>
#include <atomic>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "tetrig/drivers/c3d_reader.hpp"
#include "tetrig/drivers/pacing.hpp"
#include "tetrig/marker_frame.hpp"

namespace tetrig::drivers {

// p_out = scale * matrix * p_in, matrix row-major.
struct AxisTransform {
  std::array<float, 9> matrix{1.0f, 0.0f, 0.0f, 0.0f, 1.0f, 0.0f, 0.0f, 0.0f, 1.0f};
  float scale = 1.0f;

  static AxisTransform identity() noexcept { return {}; }
  // Z-up (C3D convention: x forward, z up) to Y-up, a proper rotation of -90 degrees about x:
  // (x, y, z) -> (x, z, -y). Right-handedness is kept (det = +1).
  static AxisTransform zUpToYUp() noexcept {
    return {{1.0f, 0.0f, 0.0f, 0.0f, 0.0f, 1.0f, 0.0f, -1.0f, 0.0f}, 1.0f};
  }
};

struct PointSelection {
  bool include_unlabeled = false;  // C3DPointKind::kUnlabeled ("*0", "*1", ...)
  bool include_modelled = false;   // C3DPointKind::kModelled (angles, forces, moments, powers...)
  // When non-empty: exactly these points, in this order (matched with C3DClip::findPoint, so
  // "LFHD" finds "meinard:LFHD"); the kind filters above do not apply.
  std::vector<std::string> labels;
};

struct C3DPlaybackOptions {
  Pacing pacing = Pacing::kRealTime;
  double speed = 1.0;             // real-time only: 2.0 plays twice as fast
  bool loop = false;              // restart at frame 0 after the last frame
  std::uint64_t max_frames = 0;   // stop after this many published frames (0: no limit)
  bool convert_units_to_mm = true;
  AxisTransform axes{};
  PointSelection selection{};
  double rate_override_hz = 0.0;  // > 0: use instead of the clip's rate (e.g. a clip without one)
};

// Holds one MarkerFrame (about 9.3 KB) as its output buffer.
class C3DPlayback {
 public:
  // Builds the point selection and the combined transform. The clip must outlive the playback.
  // Throws std::invalid_argument for an unknown label, speed <= 0, or real-time pacing without a
  // frame rate. Allocates (load time); any thread.
  C3DPlayback(const C3DClip& clip, C3DPlaybackOptions options);

  [[nodiscard]] const C3DClip& clip() const noexcept { return *clip_; }
  // Selected C3D point indices, in output order (may be longer than kMaxMarkers: see header).
  [[nodiscard]] const std::vector<int>& selectedPoints() const noexcept { return points_; }
  // Number of markers per output frame (min(selectedPoints().size(), kMaxMarkers)).
  [[nodiscard]] std::uint16_t markerCount() const noexcept { return marker_count_; }
  [[nodiscard]] double frameRate() const noexcept { return rate_hz_; }
  [[nodiscard]] std::int64_t framePeriodNs() const noexcept { return period_ns_; }

  // Fills `out` from clip frame `frame` (< clip().frameCount()) with the given output counter
  // (also sets device_timestamp_ns; receive_timestamp_ns is left 0). No allocation, no
  // exception; any thread (const).
  void fillFrame(std::size_t frame, std::uint64_t counter, MarkerFrame& out) const noexcept;

  // Replays on the calling thread until the clip ends (no loop), max_frames is reached, `stop`
  // becomes true, or the sink returns false. Frames are filled into a member buffer (no
  // allocation; the sink's argument is valid during the call only). Real-time pacing sleeps on
  // `clock` until start + counter * period / speed; a late sink delays frames but none is skipped
  // (the mailbox keeps only the newest anyway). Not reentrant: one run() at a time per object.
  template <class Sink, class Clock = SteadyPacingClock>
  PacedRunStats run(Sink&& sink, const std::atomic<bool>* stop = nullptr, Clock clock = Clock{});

 private:
  const C3DClip* clip_;
  C3DPlaybackOptions options_;
  std::vector<int> points_;
  std::uint16_t marker_count_ = 0;
  bool truncated_ = false;
  std::array<float, 9> m_{};  // axes.scale * unitsToMm * axes.matrix
  double rate_hz_ = 0.0;
  std::int64_t period_ns_ = 0;
  MarkerFrame frame_{};
};

template <class Sink, class Clock>
PacedRunStats C3DPlayback::run(Sink&& sink, const std::atomic<bool>* stop, Clock clock) {
  PacedRunStats stats;
  const std::size_t frames = clip_->frameCount();
  if (frames == 0) return stats;
  const bool real_time = options_.pacing == Pacing::kRealTime;
  const double step_ns = static_cast<double>(period_ns_) / options_.speed;
  const std::int64_t start = clock.nowNs();
  std::uint64_t counter = 0;
  while (true) {
    for (std::size_t f = 0; f < frames; ++f) {
      if (detail::stopRequested(stop)) {
        stats.stopped = true;
        return stats;
      }
      if (options_.max_frames != 0 && counter >= options_.max_frames) return stats;
      if (real_time) detail::waitForItem(clock, start, counter, step_ns, stats);
      fillFrame(f, counter, frame_);
      frame_.receive_timestamp_ns = clock.nowNs();
      ++counter;
      ++stats.items;
      if (!detail::callSink(sink, frame_)) {
        stats.stopped = true;
        return stats;
      }
    }
    ++stats.loops;
    if (!options_.loop) return stats;
  }
}

}  // namespace tetrig::drivers
