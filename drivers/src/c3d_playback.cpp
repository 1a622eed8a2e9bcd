// C3D playback source: selection, unit/axis transform and frame filling (pacing is the template
// run() in c3d_playback.hpp).
#include "tetrig/drivers/c3d_playback.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <utility>

namespace tetrig::drivers {

C3DPlayback::C3DPlayback(const C3DClip& clip, C3DPlaybackOptions options)
    : clip_(&clip), options_(std::move(options)) {
  if (!(options_.speed > 0.0) || !std::isfinite(options_.speed)) {
    throw std::invalid_argument("C3D playback: speed must be a positive number");
  }
  const PointSelection& sel = options_.selection;
  if (!sel.labels.empty()) {
    for (const std::string& label : sel.labels) {
      const int p = clip.findPoint(label);
      if (p < 0) {
        throw std::invalid_argument("C3D playback: label '" + label + "' is not in " + clip.sourceName());
      }
      points_.push_back(p);
    }
  } else {
    for (int p = 0; p < clip.pointCount(); ++p) {
      const C3DPointKind kind = clip.pointKind(p);
      if (kind == C3DPointKind::kUnlabeled && !sel.include_unlabeled) continue;
      if (kind == C3DPointKind::kModelled && !sel.include_modelled) continue;
      points_.push_back(p);
    }
  }
  truncated_ = points_.size() > static_cast<std::size_t>(kMaxMarkers);
  marker_count_ = static_cast<std::uint16_t>(std::min<std::size_t>(points_.size(), kMaxMarkers));

  const float units = options_.convert_units_to_mm ? static_cast<float>(clip.unitsToMm()) : 1.0f;
  for (std::size_t i = 0; i < 9; ++i) m_[i] = options_.axes.matrix[i] * options_.axes.scale * units;

  rate_hz_ = options_.rate_override_hz > 0.0 ? options_.rate_override_hz : clip.frameRate();
  // 1 mHz .. 1 MHz: anything else is a corrupt rate (and would overflow the ns schedule).
  if (rate_hz_ >= 1e-3 && rate_hz_ <= 1e6) {
    period_ns_ = static_cast<std::int64_t>(std::llround(1e9 / rate_hz_));
  } else if (options_.pacing == Pacing::kRealTime) {
    throw std::invalid_argument("C3D playback: " + clip.sourceName() + " has no usable frame rate (" +
                                std::to_string(rate_hz_) +
                                " Hz); set rate_override_hz or use as-fast-as-possible pacing");
  }
}

void C3DPlayback::fillFrame(std::size_t frame, std::uint64_t counter, MarkerFrame& out) const noexcept {
  out.frame_counter = counter;
  out.device_timestamp_ns = static_cast<std::int64_t>(counter) * period_ns_;
  out.receive_timestamp_ns = 0;
  out.flags = truncated_ ? kFrameTruncatedMarkers : 0u;
  out.marker_count = marker_count_;
  out.rejected_count = 0;
  const float* pos = clip_->positions(frame);
  const C3DSample* samples = clip_->samples(frame);
  for (std::size_t k = 0; k < marker_count_; ++k) {
    const int p = points_[k];
    Marker& m = out.markers[k];
    m.id = static_cast<std::uint16_t>(p);
    m.has_orientation = 0;
    m.orientation[0] = 1.0f;
    m.orientation[1] = m.orientation[2] = m.orientation[3] = 0.0f;
    const C3DSample s = samples[p];
    if (s != C3DSample::kValid) {
      m.valid = 0;
      m.position_mm[0] = m.position_mm[1] = m.position_mm[2] = 0.0f;
      if (s == C3DSample::kNonFinite) {
        ++out.rejected_count;
        out.flags |= kFrameRejectedMarkers;
      }
      continue;
    }
    const float* in = pos + static_cast<std::size_t>(p) * 3u;
    float o[3];
    for (int r = 0; r < 3; ++r) {
      o[r] = m_[static_cast<std::size_t>(3 * r)] * in[0] + m_[static_cast<std::size_t>(3 * r + 1)] * in[1] +
             m_[static_cast<std::size_t>(3 * r + 2)] * in[2];
    }
    if (!std::isfinite(o[0]) || !std::isfinite(o[1]) || !std::isfinite(o[2])) {
      m.valid = 0;
      m.position_mm[0] = m.position_mm[1] = m.position_mm[2] = 0.0f;
      ++out.rejected_count;
      out.flags |= kFrameRejectedMarkers;
      continue;
    }
    m.valid = 1;
    m.position_mm[0] = o[0];
    m.position_mm[1] = o[1];
    m.position_mm[2] = o[2];
  }
}

}  // namespace tetrig::drivers
