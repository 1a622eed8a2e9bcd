// Synthetic marker source for demos and benchmarks. Two motions:
//   kSway: N markers at rest positions (a rig's, or a built-in 1.7 m cylinder-shaped cloud), each
//          swaying along its own axis by a sinusoid, the whole set rotating about an axis;
//   kCharacter: the 41 markers of the default character (character_performance.hpp) playing its
//          scripted performance by forward kinematics, looped (it ends where it starts);
// both with optional dropouts (gaps of 1..n frames) and Gaussian noise.
//
// Frame k is a pure function of (options, k): random numbers come from a counter-based generator
// (SplitMix64 of seed, frame, marker and stream), so the output is deterministic for a seed,
// frames can be produced in any order, and nothing is allocated per frame.
//
// Motion at time t = k / rate_hz, for marker i with rest position r_i (mm):
//     s_i(t) = r_i + sway_amplitude_mm * sin(2 pi sway_frequency_hz t + 2 pi i / N) * e_(i mod 3)
//     angle(t) = rotation_rate_deg_s * t + rotation_amplitude_deg * sin(2 pi rotation_frequency_hz t)
//     p_i(t) = R(axis, angle(t)) (s_i(t) - center) + center + noise_sigma_mm * N(0, I)
// kCharacter: p_i(t) = characterMarkersAt(t mod characterPerformanceSeconds())[i] + noise.
// A dropout starts at frame j for marker i with probability dropout_probability and lasts
// 1..dropout_max_frames frames (uniform); during it the marker is reported invalid.
#pragma once

#include <array>
#include <atomic>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "tetrig/drivers/pacing.hpp"
#include "tetrig/marker_frame.hpp"

namespace tetrig::drivers {

enum class SyntheticMotion : std::uint8_t {
  kSway,       // rest positions swaying and rotating (the sway_* and rotation_* options)
  kCharacter,  // the default character's performance (characterMarkerLabels() name its markers)
};

struct SyntheticOptions {
  SyntheticMotion motion = SyntheticMotion::kSway;
  // kSway: rest positions in mm (at most kMaxMarkers). Empty: defaultRestPositions(marker_count).
  // kCharacter: must be empty, and marker_count is ignored (the character has its 41 markers).
  std::vector<std::array<float, 3>> rest_positions_mm;
  int marker_count = 41;
  double rate_hz = 120.0;
  float sway_amplitude_mm = 20.0f;
  float sway_frequency_hz = 0.5f;
  std::array<float, 3> rotation_axis{0.0f, 0.0f, 1.0f};  // normalised at construction
  std::array<float, 3> rotation_center_mm{0.0f, 0.0f, 900.0f};
  float rotation_rate_deg_s = 0.0f;
  float rotation_amplitude_deg = 30.0f;
  float rotation_frequency_hz = 0.25f;
  float noise_sigma_mm = 0.0f;
  float dropout_probability = 0.0f;  // per marker and frame: probability that a gap starts
  int dropout_max_frames = 5;        // gap length 1..this (1..64)
  std::uint64_t seed = 1;
  // Pacing for run().
  Pacing pacing = Pacing::kRealTime;
  double speed = 1.0;
  std::uint64_t max_frames = 0;  // 0: run until stopped
};

// The options of the "synthetic:character" source: the character's performance at 120 Hz with
// 0.5 mm of Gaussian noise per axis and dropouts: a gap of 1..12 frames starts with probability
// 1/2000 per marker and frame, so across the 41 markers about 2.5 gaps begin each second and
// about 0.3 % of the samples are missing.
SyntheticOptions characterSyntheticOptions();

// Holds one MarkerFrame (about 9.3 KB) as its output buffer.
class SyntheticSource {
 public:
  // Validates and copies the options. Throws std::invalid_argument on more than kMaxMarkers or
  // fewer than 1 marker, a non-positive rate or speed, a zero rotation axis, a dropout length
  // outside 1..64, a negative or non-finite noise, a dropout probability outside 0..1, or rest
  // positions given with kCharacter. Allocates; load time.
  explicit SyntheticSource(SyntheticOptions options);

  [[nodiscard]] const SyntheticOptions& options() const noexcept { return options_; }
  [[nodiscard]] std::uint16_t markerCount() const noexcept { return static_cast<std::uint16_t>(rest_.size()); }
  [[nodiscard]] std::int64_t framePeriodNs() const noexcept { return period_ns_; }

  // Fills `out` with frame `counter` (frame_counter = counter, device_timestamp_ns = counter *
  // period, receive_timestamp_ns = 0, markers[i].id = i). Deterministic; no allocation; const,
  // any thread.
  void fillFrame(std::uint64_t counter, MarkerFrame& out) const noexcept;

  // Produces frames 0, 1, 2, ... until max_frames, `stop`, or the sink returns false; same
  // pacing contract as C3DPlayback::run(). Not reentrant.
  template <class Sink, class Clock = SteadyPacingClock>
  PacedRunStats run(Sink&& sink, const std::atomic<bool>* stop = nullptr, Clock clock = Clock{});

  // A 1.7 m tall cloud of n markers in mm, Z-up, on a 150 mm radius cylinder (golden-angle
  // spiral from z = 100 to 1700 mm). Allocates.
  static std::vector<std::array<float, 3>> defaultRestPositions(int n);

  // The labels of the kCharacter markers, in marker-id order (HDM05 names: "LFHD", ...). Allocates.
  static std::vector<std::string> characterMarkerLabels();

 private:
  SyntheticOptions options_;
  std::vector<std::array<float, 3>> rest_;
  std::array<float, 3> axis_{};
  std::int64_t period_ns_ = 0;
  MarkerFrame frame_{};
};

template <class Sink, class Clock>
PacedRunStats SyntheticSource::run(Sink&& sink, const std::atomic<bool>* stop, Clock clock) {
  PacedRunStats stats;
  const bool real_time = options_.pacing == Pacing::kRealTime;
  const double step_ns = static_cast<double>(period_ns_) / options_.speed;
  const std::int64_t start = clock.nowNs();
  for (std::uint64_t counter = 0;; ++counter) {
    if (detail::stopRequested(stop)) {
      stats.stopped = true;
      return stats;
    }
    if (options_.max_frames != 0 && counter >= options_.max_frames) return stats;
    if (real_time) detail::waitForItem(clock, start, counter, step_ns, stats);
    fillFrame(counter, frame_);
    frame_.receive_timestamp_ns = clock.nowNs();
    ++stats.items;
    if (!detail::callSink(sink, frame_)) {
      stats.stopped = true;
      return stats;
    }
  }
}

}  // namespace tetrig::drivers
