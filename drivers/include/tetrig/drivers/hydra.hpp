// Razer Hydra (Sixense, USB HID 1532:0300) motion reports: pure decoder, encoder and the
// motion-mode feature report. Written from the published byte layout (docs/protocol.md, section
// "Razer Hydra"), not from other drivers' code.
//
// Interface 0 delivers 52-byte input reports (no report id) at about 250 Hz:
//   byte 7        sequence counter (u8, wraps)
//   bytes 8..29   controller 0, bytes 30..51 controller 1; each block (offsets within it):
//     +0  int16 LE position x, y, z (mm)        +6  int16 LE quaternion w, x, y, z (/ 32768)
//     +14 u8 buttons (-> Marker::buttons)        +15 int16 LE joystick x, +17 joystick y
//     +19 u8 trigger                            +20..+21 not used here
// Bytes 0..6 are not interpreted. Motion mode is switched on by a 91-byte feature report
// (report id 0) sent to interface 1: hydraMotionModeFeatureReport().
//
// Nothing here does I/O, allocates, locks or throws. HydraDecoder is a single-thread object (one
// per device, on its driver thread); the free functions may be called from any thread.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>

#include "tetrig/marker_frame.hpp"

namespace tetrig::drivers {

inline constexpr std::uint16_t kHydraVendorId = 0x1532;
inline constexpr std::uint16_t kHydraProductId = 0x0300;
inline constexpr int kHydraMotionInterface = 0;   // input reports
inline constexpr int kHydraControlInterface = 1;  // feature report (mode switch)
inline constexpr std::size_t kHydraReportSize = 52;
inline constexpr std::size_t kHydraFeatureReportSize = 91;
inline constexpr std::size_t kHydraControllerCount = 2;
inline constexpr float kHydraQuaternionScale = 1.0f / 32768.0f;
// Nominal report rate (documented ~250 Hz; the device sends no rate of its own).
inline constexpr double kHydraNominalRateHz = 250.0;
// Fixed labels of the two sensors: marker id 0 is "hydra0" (block at byte 8), id 1 "hydra1" (byte 30).
inline constexpr std::array<const char*, kHydraControllerCount> kHydraSensorLabels = {"hydra0", "hydra1"};

// One controller block exactly as on the wire (raw integers).
struct HydraRawController {
  std::int16_t position[3] = {0, 0, 0};       // mm, x y z
  std::int16_t quaternion[4] = {0, 0, 0, 0};  // w x y z, value / 32768
  std::uint8_t buttons = 0;                   // raw button bits
  std::int16_t joystick[2] = {0, 0};          // x, y
  std::uint8_t trigger = 0;                   // 0..255
};

struct HydraRawReport {
  std::uint8_t sequence = 0;
  std::array<HydraRawController, kHydraControllerCount> controllers{};
};

// Typed non-pose state for callers that want buttons and analogue inputs.
struct HydraControllerState {
  std::uint8_t buttons = 0;                   // raw bits as sent (meaning of each bit not specified here)
  std::int16_t joystick_raw[2] = {0, 0};
  float joystick[2] = {0.0f, 0.0f};           // raw / 32768, in [-1, 1)
  std::uint8_t trigger_raw = 0;
  float trigger = 0.0f;                       // raw / 255, in [0, 1]
  bool pose_valid = false;                    // false when the quaternion was rejected
};

struct HydraState {
  std::uint64_t frame_counter = 0;  // same as the MarkerFrame's
  std::array<HydraControllerState, kHydraControllerCount> controllers{};
};

enum class HydraStatus : int {
  kFrame = 0,         // decoded
  kTruncated = -1,    // fewer than 52 bytes
  kBadLength = -2,    // more than 52 bytes (not a motion report of interface 0)
  kDuplicate = -3,    // same sequence counter as the last accepted report: dropped
};

// Short stable name ("frame", "truncated", ...). Any thread; static string.
[[nodiscard]] const char* hydraStatusName(HydraStatus status) noexcept;

// Exact-size parse of a 52-byte report into raw integers (no validation of values).
// Returns kFrame, kTruncated or kBadLength; `out` is written only on kFrame. Any thread; no allocation.
[[nodiscard]] HydraStatus parseHydraReport(std::span<const std::uint8_t> bytes, HydraRawReport& out) noexcept;

struct HydraDecoderStats {
  std::uint64_t frames_decoded = 0;
  std::uint64_t frames_lost = 0;      // sum of sequence gaps (modulo 256: see docs/protocol.md)
  std::uint64_t gap_events = 0;       // frames decoded with kFrameSequenceGap
  std::uint64_t duplicates = 0;
  std::uint64_t format_errors = 0;    // kTruncated, kBadLength
  std::uint64_t rejected_markers = 0; // controllers whose quaternion was zero/non-finite/not unit
};

class HydraDecoder {
 public:
  // Decodes one 52-byte report. On kFrame `out` holds two markers (id 0 = first block, id 1 =
  // second block; their labels are kHydraSensorLabels, "hydra0" and "hydra1"): position in mm
  // (device axes), has_orientation = 1 and a normalised quaternion (w, x, y, z), and
  // Marker::buttons = the block's raw button byte (bits as sent, also when the pose is
  // rejected); a controller whose quaternion is zero, non-finite or far from unit
  // length (|q| outside [0.5, 2]) is invalidated (valid = 0, position 0, identity orientation)
  // and counted in rejected_count with kFrameRejectedMarkers. frame_counter is the 8-bit
  // sequence extended to 64 bits (first report: its sequence value); a forward step of d > 1
  // sets kFrameSequenceGap and adds d - 1 to frames_lost. device_timestamp_ns = 0 (the Hydra
  // sends none); receive_timestamp_ns = `receive_ns`. `state`, when not null, receives buttons,
  // joysticks and triggers. On any other status neither `out` nor `state` is modified.
  // Driver thread; no allocation.
  [[nodiscard]] HydraStatus decode(std::span<const std::uint8_t> bytes, std::int64_t receive_ns, MarkerFrame& out,
                                   HydraState* state = nullptr) noexcept;

  // Forgets the sequence state (next report starts a new stream), e.g. after a reconnect.
  void reset() noexcept { have_last_ = false; }
  [[nodiscard]] const HydraDecoderStats& stats() const noexcept { return stats_; }

 private:
  HydraDecoderStats stats_;
  bool have_last_ = false;
  std::uint8_t last_sequence_ = 0;
  std::uint64_t last_extended_ = 0;
};

// The 91-byte feature report that switches the Hydra into motion mode, as passed to
// hid_send_feature_report() on interface 1: byte 0 is the report id (0), bytes 6, 8, 9 and 89 are
// 0x01, 0x04, 0x03 and 0x06, every other byte 0. Any thread; constant.
[[nodiscard]] std::array<std::uint8_t, kHydraFeatureReportSize> hydraMotionModeFeatureReport() noexcept;

// Writes `report` as a 52-byte motion report into `out` (mock devices, tests). Bytes 0..6 and
// the two unused bytes of each block are written as 0. Returns 52, or 0 if `out` is too small.
// Any thread; no allocation.
[[nodiscard]] std::size_t encodeHydraReport(const HydraRawReport& report, std::span<std::uint8_t> out) noexcept;

// Quantises a pose to wire integers: position rounded to whole mm and clamped to int16, the
// quaternion normalised (identity if zero or non-finite) and scaled by 32768, clamped to
// [-32768, 32767]. Buttons, joystick and trigger are left 0. Any thread; no allocation.
[[nodiscard]] HydraRawController hydraControllerFromPose(const float position_mm[3], const float quaternion_wxyz[4]) noexcept;

}  // namespace tetrig::drivers
