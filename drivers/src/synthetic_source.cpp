// Synthetic marker source: scripted sinusoid + rotation motion (Rodrigues' rotation formula) or the
// default character's performance (character_performance.cpp), dropouts and Gaussian noise
// (Box-Muller) from a counter-based SplitMix64 generator.
#include "tetrig/drivers/synthetic_source.hpp"

#include "tetrig/drivers/character_performance.hpp"

#include <numbers>
#include <stdexcept>
#include <utility>

namespace tetrig::drivers {

namespace {

std::uint64_t splitMix64(std::uint64_t x) noexcept {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

enum Stream : std::uint64_t { kDropStart = 1, kDropLength = 2, kNoise = 3 };

// Uniform in [0, 1) from (seed, frame, marker, stream).
double uniform(std::uint64_t seed, std::uint64_t frame, std::uint64_t marker, std::uint64_t stream) noexcept {
  std::uint64_t h = splitMix64(seed ^ splitMix64(frame ^ splitMix64(marker * 8 + stream)));
  return static_cast<double>(h >> 11) * (1.0 / 9007199254740992.0);
}

}  // namespace

SyntheticSource::SyntheticSource(SyntheticOptions options) : options_(std::move(options)) {
  if (options_.motion == SyntheticMotion::kCharacter) {
    if (!options_.rest_positions_mm.empty()) {
      throw std::invalid_argument("synthetic source: the character motion has its own markers; rest positions cannot be given");
    }
    for (const CharacterMarker& m : characterMarkers()) {
      rest_.push_back({static_cast<float>(m.tpose[0]), static_cast<float>(m.tpose[1]), static_cast<float>(m.tpose[2])});
    }
    options_.marker_count = static_cast<int>(rest_.size());
  } else {
    rest_ = options_.rest_positions_mm.empty() ? defaultRestPositions(options_.marker_count) : options_.rest_positions_mm;
  }
  if (rest_.empty() || rest_.size() > static_cast<std::size_t>(kMaxMarkers)) {
    throw std::invalid_argument("synthetic source: marker count must be 1.." + std::to_string(kMaxMarkers));
  }
  if (!(options_.rate_hz >= 1e-3 && options_.rate_hz <= 1e6)) {
    throw std::invalid_argument("synthetic source: rate_hz must be within 0.001 .. 1e6");
  }
  if (!(options_.speed > 0.0) || !std::isfinite(options_.speed)) {
    throw std::invalid_argument("synthetic source: speed must be positive");
  }
  if (options_.dropout_max_frames < 1 || options_.dropout_max_frames > 64) {
    throw std::invalid_argument("synthetic source: dropout_max_frames must be 1..64");
  }
  if (!(options_.noise_sigma_mm >= 0.0f) || !std::isfinite(options_.noise_sigma_mm)) {
    throw std::invalid_argument("synthetic source: noise_sigma_mm must be a finite number >= 0");
  }
  if (!(options_.dropout_probability >= 0.0f && options_.dropout_probability <= 1.0f)) {
    throw std::invalid_argument("synthetic source: dropout_probability must be within 0..1");
  }
  const auto& a = options_.rotation_axis;
  const float len = std::sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
  if (!(len > 0.0f) || !std::isfinite(len)) throw std::invalid_argument("synthetic source: rotation axis is zero");
  axis_ = {a[0] / len, a[1] / len, a[2] / len};
  period_ns_ = static_cast<std::int64_t>(std::llround(1e9 / options_.rate_hz));
}

std::vector<std::array<float, 3>> SyntheticSource::defaultRestPositions(int n) {
  std::vector<std::array<float, 3>> out;
  if (n <= 0) return out;
  const double golden = std::numbers::pi * (3.0 - std::sqrt(5.0));
  for (int i = 0; i < n; ++i) {
    const double a = golden * i;
    const double z = n == 1 ? 900.0 : 100.0 + 1600.0 * i / (n - 1);
    out.push_back({static_cast<float>(150.0 * std::cos(a)), static_cast<float>(150.0 * std::sin(a)),
                   static_cast<float>(z)});
  }
  return out;
}

SyntheticOptions characterSyntheticOptions() {
  SyntheticOptions o;
  o.motion = SyntheticMotion::kCharacter;
  o.rate_hz = 120.0;
  o.noise_sigma_mm = 0.5f;
  o.dropout_probability = 1.0f / 2000.0f;
  o.dropout_max_frames = 12;
  return o;
}

std::vector<std::string> SyntheticSource::characterMarkerLabels() {
  std::vector<std::string> labels;
  for (const CharacterMarker& m : characterMarkers()) labels.emplace_back(m.label);
  return labels;
}

void SyntheticSource::fillFrame(std::uint64_t counter, MarkerFrame& out) const noexcept {
  const SyntheticOptions& o = options_;
  const double t = static_cast<double>(counter) / o.rate_hz;
  const double two_pi = 2.0 * std::numbers::pi;
  const double angle = (o.rotation_rate_deg_s * t + o.rotation_amplitude_deg * std::sin(two_pi * o.rotation_frequency_hz * t)) *
                       std::numbers::pi / 180.0;
  const double c = std::cos(angle);
  const double s = std::sin(angle);
  const double kx = axis_[0], ky = axis_[1], kz = axis_[2];
  // Rodrigues: R = c I + s [k]x + (1 - c) k k^T.
  const double r[9] = {c + (1 - c) * kx * kx,      (1 - c) * kx * ky - s * kz, (1 - c) * kx * kz + s * ky,
                       (1 - c) * ky * kx + s * kz, c + (1 - c) * ky * ky,      (1 - c) * ky * kz - s * kx,
                       (1 - c) * kz * kx - s * ky, (1 - c) * kz * ky + s * kx, c + (1 - c) * kz * kz};
  const std::size_t n = rest_.size();
  const bool character = o.motion == SyntheticMotion::kCharacter;
  std::array<CharacterVec3, kCharacterMarkerCount> body;
  if (character) characterMarkersAt(std::fmod(t, characterPerformanceSeconds()), body);
  out.frame_counter = counter;
  out.device_timestamp_ns = static_cast<std::int64_t>(counter) * period_ns_;
  out.receive_timestamp_ns = 0;
  out.flags = 0;
  out.marker_count = static_cast<std::uint16_t>(n);
  out.rejected_count = 0;
  const auto max_gap = static_cast<std::uint64_t>(o.dropout_max_frames);
  for (std::size_t i = 0; i < n; ++i) {
    Marker& m = out.markers[i];
    m.id = static_cast<std::uint16_t>(i);
    m.has_orientation = 0;
    m.orientation[0] = 1.0f;
    m.orientation[1] = m.orientation[2] = m.orientation[3] = 0.0f;
    bool dropped = false;
    if (o.dropout_probability > 0.0f) {
      for (std::uint64_t back = 0; back < max_gap && back <= counter && !dropped; ++back) {
        const std::uint64_t j = counter - back;
        if (uniform(o.seed, j, i, kDropStart) < static_cast<double>(o.dropout_probability)) {
          const auto length = 1 + static_cast<std::uint64_t>(uniform(o.seed, j, i, kDropLength) * static_cast<double>(max_gap));
          dropped = back < length;
        }
      }
    }
    if (dropped) {
      m.valid = 0;
      m.position_mm[0] = m.position_mm[1] = m.position_mm[2] = 0.0f;
      continue;
    }
    double q[3];
    if (character) {
      for (int k = 0; k < 3; ++k) q[k] = body[i][static_cast<std::size_t>(k)];
    } else {
      double p[3] = {rest_[i][0], rest_[i][1], rest_[i][2]};
      const double sway = o.sway_amplitude_mm * std::sin(two_pi * o.sway_frequency_hz * t +
                                                          two_pi * static_cast<double>(i) / static_cast<double>(n));
      p[i % 3] += sway;
      for (int k = 0; k < 3; ++k) p[k] -= o.rotation_center_mm[static_cast<std::size_t>(k)];
      for (int row = 0; row < 3; ++row) q[row] = r[3 * row] * p[0] + r[3 * row + 1] * p[1] + r[3 * row + 2] * p[2];
      for (int k = 0; k < 3; ++k) q[k] += o.rotation_center_mm[static_cast<std::size_t>(k)];
    }
    if (o.noise_sigma_mm > 0.0f) {
      // Box-Muller: two Gaussians per pair of uniforms; three axes use two pairs.
      for (int k = 0; k < 3; k += 2) {
        const double u1 = 1.0 - uniform(o.seed, counter, i, kNoise + 8u * static_cast<std::uint64_t>(k));
        const double u2 = uniform(o.seed, counter, i, kNoise + 8u * static_cast<std::uint64_t>(k) + 4u);
        const double radius = std::sqrt(-2.0 * std::log(u1)) * o.noise_sigma_mm;
        q[k] += radius * std::cos(two_pi * u2);
        if (k + 1 < 3) q[k + 1] += radius * std::sin(two_pi * u2);
      }
    }
    m.valid = 1;
    for (int k = 0; k < 3; ++k) m.position_mm[k] = static_cast<float>(q[k]);
  }
}

}  // namespace tetrig::drivers
