// One frame of labelled 3-D markers: what every driver produces and the solver consumes.
//
// Fixed capacity (kMaxMarkers), trivially copyable, no heap: a frame can be copied through the
// lock-free mailbox and decoded into without allocation. Positions are in millimetres in the
// device's (or file's) own axes; conversion to the rig's unit and axes happens in the runtime's
// marker binding, not in drivers.
#pragma once

#include <array>
#include <cstdint>
#include <type_traits>

namespace tetrig {

inline constexpr int kMaxMarkers = 256;

struct Marker {
  float position_mm[3] = {0.0f, 0.0f, 0.0f};
  std::uint16_t id = 0;  // label index in the source's label table (C3D point index, protocol id)
  std::uint8_t valid = 0;  // 1: measured this frame; 0: occluded/invalid (position meaningless)
  std::uint8_t buttons = 0;  // pose sensors (e.g. Razer Hydra): the controller's button bits; 0 otherwise
  // Optional orientation (unit quaternion w, x, y, z) for pose sensors such as the Razer Hydra.
  float orientation[4] = {1.0f, 0.0f, 0.0f, 0.0f};
  std::uint8_t has_orientation = 0;
  std::uint8_t pad[3] = {0, 0, 0};
};

// Flags a driver sets on a frame.
enum MarkerFrameFlags : std::uint32_t {
  kFrameSequenceGap = 1u << 0,        // frame counter jumped: frames were lost before this one
  kFrameRejectedMarkers = 1u << 1,    // some markers were non-finite or absurd and marked invalid
  kFrameTruncatedMarkers = 1u << 2,   // the source had more than kMaxMarkers markers
  kFrameDuplicate = 1u << 3,          // same counter as the previous frame (dropped by consumers)
};

struct MarkerFrame {
  std::uint64_t frame_counter = 0;        // device/file frame number (monotonic per stream)
  std::int64_t device_timestamp_ns = 0;   // device capture time, device clock (0 if unknown)
  std::int64_t receive_timestamp_ns = 0;  // host CLOCK_MONOTONIC when the last byte arrived
  std::uint32_t flags = 0;                // MarkerFrameFlags
  std::uint16_t marker_count = 0;         // markers[0 .. marker_count) are meaningful
  std::uint16_t rejected_count = 0;       // markers invalidated for non-finite/absurd values
  std::array<Marker, kMaxMarkers> markers{};
};

static_assert(std::is_trivially_copyable_v<MarkerFrame>);

}  // namespace tetrig
