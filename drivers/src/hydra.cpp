// Razer Hydra (USB HID 1532:0300) 52-byte motion report and 91-byte motion-mode feature report,
// decoded from the published byte layout (docs/protocol.md, section "Razer Hydra").
#include "tetrig/drivers/hydra.hpp"

#include <cmath>
#include <cstring>

#include "byte_io.hpp"

namespace tetrig::drivers {

using detail::loadI16;
using detail::storeI16;

namespace {

constexpr std::size_t kOffSequence = 7;
constexpr std::size_t kBlockOffsets[kHydraControllerCount] = {8, 30};
constexpr std::size_t kBlkPosition = 0;
constexpr std::size_t kBlkQuaternion = 6;
constexpr std::size_t kBlkButtons = 14;
constexpr std::size_t kBlkJoystick = 15;
constexpr std::size_t kBlkTrigger = 19;

std::int16_t clampToI16(double v) noexcept {
  if (!(v >= -32768.0)) return v != v ? 0 : -32768;  // NaN -> 0, -inf/too small -> min
  if (v > 32767.0) return 32767;
  return static_cast<std::int16_t>(std::lround(v));
}

}  // namespace

const char* hydraStatusName(HydraStatus status) noexcept {
  switch (status) {
    case HydraStatus::kFrame: return "frame";
    case HydraStatus::kTruncated: return "truncated";
    case HydraStatus::kBadLength: return "bad length";
    case HydraStatus::kDuplicate: return "duplicate";
  }
  return "unknown status";
}

HydraStatus parseHydraReport(std::span<const std::uint8_t> bytes, HydraRawReport& out) noexcept {
  if (bytes.size() < kHydraReportSize) return HydraStatus::kTruncated;
  if (bytes.size() > kHydraReportSize) return HydraStatus::kBadLength;
  const std::uint8_t* p = bytes.data();
  out.sequence = p[kOffSequence];
  for (std::size_t c = 0; c < kHydraControllerCount; ++c) {
    const std::uint8_t* b = p + kBlockOffsets[c];
    HydraRawController& rc = out.controllers[c];
    for (std::size_t k = 0; k < 3; ++k) rc.position[k] = loadI16(b + kBlkPosition + 2 * k);
    for (std::size_t k = 0; k < 4; ++k) rc.quaternion[k] = loadI16(b + kBlkQuaternion + 2 * k);
    rc.buttons = b[kBlkButtons];
    rc.joystick[0] = loadI16(b + kBlkJoystick);
    rc.joystick[1] = loadI16(b + kBlkJoystick + 2);
    rc.trigger = b[kBlkTrigger];
  }
  return HydraStatus::kFrame;
}

HydraStatus HydraDecoder::decode(std::span<const std::uint8_t> bytes, std::int64_t receive_ns, MarkerFrame& out,
                                 HydraState* state) noexcept {
  HydraRawReport raw;
  const HydraStatus st = parseHydraReport(bytes, raw);
  if (st != HydraStatus::kFrame) {
    ++stats_.format_errors;
    return st;
  }
  // 8-bit sequence: a USB interrupt pipe never reorders, so every non-zero step is forward
  // (1..255); a loss of 256 or more reports aliases (docs/protocol.md).
  std::uint32_t flags = 0;
  std::uint64_t extended = raw.sequence;
  if (have_last_) {
    const auto step = static_cast<std::uint8_t>(raw.sequence - last_sequence_);
    if (step == 0) {
      ++stats_.duplicates;
      return HydraStatus::kDuplicate;
    }
    extended = last_extended_ + step;
    if (step > 1) {
      flags |= kFrameSequenceGap;
      stats_.frames_lost += static_cast<std::uint64_t>(step - 1);
      ++stats_.gap_events;
    }
  }
  have_last_ = true;
  last_sequence_ = raw.sequence;
  last_extended_ = extended;

  std::uint16_t rejected = 0;
  for (std::size_t c = 0; c < kHydraControllerCount; ++c) {
    const HydraRawController& rc = raw.controllers[c];
    Marker& m = out.markers[c];
    m.id = static_cast<std::uint16_t>(c);
    m.buttons = rc.buttons;  // raw bits, also when the pose is rejected (a press is still a press)
    float q[4];
    double n2 = 0.0;
    for (std::size_t k = 0; k < 4; ++k) {
      q[k] = static_cast<float>(rc.quaternion[k]) * kHydraQuaternionScale;
      n2 += static_cast<double>(q[k]) * q[k];
    }
    // Wire values are int16, so q is finite; the check also guards against zero (sensor off,
    // not in motion mode) and values far from unit length (corruption).
    const bool ok = std::isfinite(n2) && n2 >= 0.25 && n2 <= 4.0;
    if (ok) {
      const double inv = 1.0 / std::sqrt(n2);
      for (std::size_t k = 0; k < 3; ++k) m.position_mm[k] = static_cast<float>(rc.position[k]);
      for (std::size_t k = 0; k < 4; ++k) m.orientation[k] = static_cast<float>(q[k] * inv);
      m.valid = 1;
      m.has_orientation = 1;
    } else {
      m.position_mm[0] = m.position_mm[1] = m.position_mm[2] = 0.0f;
      m.orientation[0] = 1.0f;
      m.orientation[1] = m.orientation[2] = m.orientation[3] = 0.0f;
      m.valid = 0;
      m.has_orientation = 0;
      ++rejected;
    }
    if (state != nullptr) {
      HydraControllerState& cs = state->controllers[c];
      cs.buttons = rc.buttons;
      cs.joystick_raw[0] = rc.joystick[0];
      cs.joystick_raw[1] = rc.joystick[1];
      cs.joystick[0] = static_cast<float>(rc.joystick[0]) / 32768.0f;
      cs.joystick[1] = static_cast<float>(rc.joystick[1]) / 32768.0f;
      cs.trigger_raw = rc.trigger;
      cs.trigger = static_cast<float>(rc.trigger) / 255.0f;
      cs.pose_valid = ok;
    }
  }
  if (rejected > 0) {
    flags |= kFrameRejectedMarkers;
    stats_.rejected_markers += rejected;
  }
  if (state != nullptr) state->frame_counter = extended;
  out.frame_counter = extended;
  out.device_timestamp_ns = 0;
  out.receive_timestamp_ns = receive_ns;
  out.flags = flags;
  out.marker_count = static_cast<std::uint16_t>(kHydraControllerCount);
  out.rejected_count = rejected;
  ++stats_.frames_decoded;
  return HydraStatus::kFrame;
}

std::array<std::uint8_t, kHydraFeatureReportSize> hydraMotionModeFeatureReport() noexcept {
  std::array<std::uint8_t, kHydraFeatureReportSize> r{};
  r[6] = 0x01;
  r[8] = 0x04;
  r[9] = 0x03;
  r[89] = 0x06;
  return r;
}

std::size_t encodeHydraReport(const HydraRawReport& report, std::span<std::uint8_t> out) noexcept {
  if (out.size() < kHydraReportSize) return 0;
  std::uint8_t* p = out.data();
  std::memset(p, 0, kHydraReportSize);
  p[kOffSequence] = report.sequence;
  for (std::size_t c = 0; c < kHydraControllerCount; ++c) {
    std::uint8_t* b = p + kBlockOffsets[c];
    const HydraRawController& rc = report.controllers[c];
    for (std::size_t k = 0; k < 3; ++k) storeI16(b + kBlkPosition + 2 * k, rc.position[k]);
    for (std::size_t k = 0; k < 4; ++k) storeI16(b + kBlkQuaternion + 2 * k, rc.quaternion[k]);
    b[kBlkButtons] = rc.buttons;
    storeI16(b + kBlkJoystick, rc.joystick[0]);
    storeI16(b + kBlkJoystick + 2, rc.joystick[1]);
    b[kBlkTrigger] = rc.trigger;
  }
  return kHydraReportSize;
}

HydraRawController hydraControllerFromPose(const float position_mm[3], const float quaternion_wxyz[4]) noexcept {
  HydraRawController rc;
  for (std::size_t k = 0; k < 3; ++k) rc.position[k] = clampToI16(static_cast<double>(position_mm[k]));
  double n2 = 0.0;
  for (std::size_t k = 0; k < 4; ++k) n2 += static_cast<double>(quaternion_wxyz[k]) * quaternion_wxyz[k];
  if (!std::isfinite(n2) || n2 <= 0.0) {
    rc.quaternion[0] = 32767;
    return rc;
  }
  const double inv = 1.0 / std::sqrt(n2);
  for (std::size_t k = 0; k < 4; ++k) rc.quaternion[k] = clampToI16(quaternion_wxyz[k] * inv * 32768.0);
  return rc;
}

}  // namespace tetrig::drivers
