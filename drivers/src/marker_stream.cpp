// The tetrig marker-stream protocol v1.0 (docs/protocol.md): frame validation, sequence tracking,
// marker sanitising, the frame encoder, and the command / device-info blocks; the decoder hands
// descriptor messages to marker_stream_descriptor.cpp. Fragment reassembly lives in
// marker_stream_fragment.cpp.
#include "tetrig/drivers/marker_stream.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>

#include "byte_io.hpp"
#include "tetrig/drivers/crc32c.hpp"

namespace tetrig::drivers {

using detail::loadF32;
using detail::loadU16;
using detail::loadU32;
using detail::loadU64;
using detail::storeF32;
using detail::storeU16;
using detail::storeU32;
using detail::storeU64;

namespace {

// Header offsets (docs/protocol.md, table "Frame header").
constexpr std::size_t kOffMagic = 0;
constexpr std::size_t kOffVersionMajor = 4;
constexpr std::size_t kOffVersionMinor = 5;
constexpr std::size_t kOffHeaderSize = 6;
constexpr std::size_t kOffRecordFormat = 7;
constexpr std::size_t kOffFrameLength = 8;
constexpr std::size_t kOffMarkerCount = 10;
constexpr std::size_t kOffFrameCounter = 12;
constexpr std::size_t kOffDeviceTime = 16;
constexpr std::size_t kOffFrameFlags = 24;
// Record offsets.
constexpr std::size_t kRecId = 0;
constexpr std::size_t kRecFlags = 2;
constexpr std::size_t kRecPosition = 4;
constexpr std::size_t kRecQuaternion = 16;

// Command / info offsets.
constexpr std::size_t kCmdOpcode = 1;
constexpr std::size_t kCmdParam = 2;

std::size_t recordSize(MarkerRecordFormat f) noexcept {
  return f == MarkerRecordFormat::kPose ? kMarkerRecordSizePose : kMarkerRecordSizePosition;
}

bool magicMatches(const std::uint8_t* p) noexcept {
  return std::memcmp(p + kOffMagic, kMarkerStreamMagic.data(), kMarkerStreamMagic.size()) == 0;
}
bool descriptorMagicMatches(const std::uint8_t* p) noexcept {
  return std::memcmp(p + kOffMagic, kMarkerStreamDescriptorMagic.data(), kMarkerStreamDescriptorMagic.size()) == 0;
}

void clearMarker(Marker& m) noexcept {
  m.position_mm[0] = m.position_mm[1] = m.position_mm[2] = 0.0f;
  m.orientation[0] = 1.0f;
  m.orientation[1] = m.orientation[2] = m.orientation[3] = 0.0f;
  m.has_orientation = 0;
  m.valid = 0;
}

bool isKnownCommand(std::uint8_t op) noexcept {
  return op >= static_cast<std::uint8_t>(MarkerStreamCommand::kStart) &&
         op <= static_cast<std::uint8_t>(MarkerStreamCommand::kGetDescriptor);
}

}  // namespace

const char* markerStreamStatusName(MarkerStreamStatus status) noexcept {
  switch (status) {
    case MarkerStreamStatus::kFrame: return "frame";
    case MarkerStreamStatus::kNeedMore: return "need more";
    case MarkerStreamStatus::kDescriptor: return "descriptor";
    case MarkerStreamStatus::kTruncated: return "truncated";
    case MarkerStreamStatus::kBadMagic: return "bad magic";
    case MarkerStreamStatus::kUnsupportedVersion: return "unsupported version";
    case MarkerStreamStatus::kBadHeader: return "bad header";
    case MarkerStreamStatus::kBadLength: return "bad length";
    case MarkerStreamStatus::kBadCrc: return "bad crc";
    case MarkerStreamStatus::kDuplicate: return "duplicate";
    case MarkerStreamStatus::kOutOfOrder: return "out of order";
    case MarkerStreamStatus::kBadReport: return "bad report";
    case MarkerStreamStatus::kBadFragment: return "bad fragment";
    case MarkerStreamStatus::kFragmentLost: return "fragment lost";
    case MarkerStreamStatus::kBadDescriptor: return "bad descriptor";
  }
  return "unknown status";
}

MarkerStreamStatus validateMarkerStreamFrame(std::span<const std::uint8_t> bytes, MarkerStreamHeader& h) noexcept {
  const std::uint8_t* p = bytes.data();
  const std::size_t n = bytes.size();
  if (n < kMarkerStreamMagic.size()) return MarkerStreamStatus::kTruncated;
  if (!magicMatches(p)) return MarkerStreamStatus::kBadMagic;
  if (n <= kOffVersionMajor) return MarkerStreamStatus::kTruncated;
  // An unknown major version may lay out everything after byte 4 differently: look no further.
  if (p[kOffVersionMajor] != kMarkerStreamVersionMajor) return MarkerStreamStatus::kUnsupportedVersion;
  if (n < kMarkerStreamHeaderSize) return MarkerStreamStatus::kTruncated;

  h.version_major = p[kOffVersionMajor];
  h.version_minor = p[kOffVersionMinor];
  h.header_size = p[kOffHeaderSize];
  const std::uint8_t format = p[kOffRecordFormat];
  h.frame_length = loadU16(p + kOffFrameLength);
  h.marker_count = loadU16(p + kOffMarkerCount);
  h.frame_counter = loadU32(p + kOffFrameCounter);
  h.device_time_ns = static_cast<std::int64_t>(loadU64(p + kOffDeviceTime));
  h.frame_flags = loadU16(p + kOffFrameFlags);

  if (h.header_size < kMarkerStreamHeaderSize || h.header_size > kMarkerStreamMaxHeaderSize ||
      h.header_size % 4 != 0 || format > static_cast<std::uint8_t>(MarkerRecordFormat::kPose) ||
      h.marker_count > kMarkerStreamMaxMarkers) {
    return MarkerStreamStatus::kBadHeader;
  }
  h.record_format = static_cast<MarkerRecordFormat>(format);
  const std::size_t expected = h.header_size + h.marker_count * recordSize(h.record_format) + kMarkerStreamCrcSize;
  if (h.frame_length != expected) return MarkerStreamStatus::kBadLength;
  if (n < expected) return MarkerStreamStatus::kTruncated;
  if (n > expected) return MarkerStreamStatus::kBadLength;
  const std::size_t body = expected - kMarkerStreamCrcSize;
  if (crc32c(bytes.first(body)) != loadU32(p + body)) return MarkerStreamStatus::kBadCrc;
  return MarkerStreamStatus::kFrame;
}

std::size_t markerStreamPeekFrameLength(std::span<const std::uint8_t> bytes) noexcept {
  if (bytes.size() < kOffMarkerCount + 2) return 0;
  const std::uint8_t* p = bytes.data();
  // Both message kinds keep magic, major version and length at the same offsets (0, 4, 8).
  const std::size_t len = loadU16(p + kOffFrameLength);
  if (magicMatches(p)) {
    if (p[kOffVersionMajor] != kMarkerStreamVersionMajor) return 0;
    if (len < kMarkerStreamHeaderSize + kMarkerStreamCrcSize || len > kMarkerStreamMaxFrameSize) return 0;
    return len;
  }
  if (descriptorMagicMatches(p)) {
    if (p[kOffVersionMajor] != kMarkerStreamDescriptorVersionMajor) return 0;
    if (len < kMarkerStreamDescriptorHeaderSize + kMarkerStreamCrcSize || len > kMarkerStreamMaxDescriptorSize) return 0;
    return len;
  }
  return 0;
}

// ---------------------------------------------------------------------------------------------

void MarkerStreamDecoder::reset() noexcept {
  have_last_ = false;
  consecutive_out_of_order_ = 0;
  reassembler_.reset();
}

MarkerStreamStatus MarkerStreamDecoder::decodeFrame(std::span<const std::uint8_t> bytes, std::int64_t receive_ns,
                                                    MarkerFrame& out) noexcept {
  if (bytes.size() >= kMarkerStreamDescriptorMagic.size() && descriptorMagicMatches(bytes.data())) {
    // A descriptor: labels only; the frame, its sequence state and `out` are left alone.
    const MarkerStreamStatus ds = decodeMarkerStreamDescriptor(bytes, labels_);
    switch (ds) {
      case MarkerStreamStatus::kDescriptor: ++stats_.descriptors_accepted; return ds;
      case MarkerStreamStatus::kBadCrc: ++stats_.crc_errors; break;
      case MarkerStreamStatus::kUnsupportedVersion: ++stats_.version_errors; break;
      case MarkerStreamStatus::kBadDescriptor: break;
      default: ++stats_.format_errors; break;
    }
    ++stats_.descriptors_rejected;
    return ds;
  }
  MarkerStreamHeader h;
  const MarkerStreamStatus st = validateMarkerStreamFrame(bytes, h);
  switch (st) {
    case MarkerStreamStatus::kFrame: break;
    case MarkerStreamStatus::kBadCrc: ++stats_.crc_errors; return st;
    case MarkerStreamStatus::kUnsupportedVersion: ++stats_.version_errors; return st;
    default: ++stats_.format_errors; return st;
  }

  // Sequence: serial-number arithmetic on the 32-bit counter (RFC 1982 style).
  std::uint32_t flags = 0;
  std::uint64_t extended = 0;
  const bool stream_start = (h.frame_flags & kStreamFlagStreamStart) != 0;
  if (!have_last_) {
    extended = h.frame_counter;
  } else if (stream_start) {
    ++stats_.resyncs;  // deliberate restart: no frames are known to be lost
    extended = last_extended_ + 1;
  } else {
    const auto delta = static_cast<std::int32_t>(h.frame_counter - last_counter_);
    if (delta == 0) {
      ++stats_.duplicates;
      return MarkerStreamStatus::kDuplicate;
    }
    if (delta < 0) {
      ++stats_.out_of_order;
      if (++consecutive_out_of_order_ < options_.resync_after_out_of_order) {
        return MarkerStreamStatus::kOutOfOrder;
      }
      // The device restarted its counter without saying so: follow it, losses unknown.
      ++stats_.resyncs;
      extended = last_extended_ + 1;
      flags |= kFrameSequenceGap;
    } else {
      const auto step = static_cast<std::uint64_t>(delta);
      extended = last_extended_ + step;
      if (step > 1) {
        flags |= kFrameSequenceGap;
        stats_.frames_lost += step - 1;
      }
    }
  }
  if ((flags & kFrameSequenceGap) != 0) ++stats_.gap_events;
  have_last_ = true;
  last_counter_ = h.frame_counter;
  last_extended_ = extended;
  consecutive_out_of_order_ = 0;

  if ((h.frame_flags & kStreamFlagDeviceOverflow) != 0) flags |= kFrameTruncatedMarkers;

  // Markers.
  const float limit = options_.max_abs_coordinate_mm;
  const std::size_t rec = recordSize(h.record_format);
  const std::uint8_t* r = bytes.data() + h.header_size;
  std::uint16_t rejected = 0;
  for (std::size_t i = 0; i < h.marker_count; ++i, r += rec) {
    Marker& m = out.markers[i];
    m.id = loadU16(r + kRecId);
    m.buttons = 0;
    const std::uint8_t mflags = r[kRecFlags];
    if ((mflags & kMarkerFlagValid) == 0) {
      clearMarker(m);
      continue;
    }
    const float x = loadF32(r + kRecPosition);
    const float y = loadF32(r + kRecPosition + 4);
    const float z = loadF32(r + kRecPosition + 8);
    // NaN fails every comparison, so "!(|v| <= limit)" rejects NaN, +-inf and absurd values.
    bool ok = std::fabs(x) <= limit && std::fabs(y) <= limit && std::fabs(z) <= limit;
    float q[4] = {1.0f, 0.0f, 0.0f, 0.0f};
    const bool has_q = h.record_format == MarkerRecordFormat::kPose && (mflags & kMarkerFlagHasOrientation) != 0;
    if (ok && has_q) {
      for (std::size_t k = 0; k < 4; ++k) q[k] = loadF32(r + kRecQuaternion + 4 * k);
      const double n2 = static_cast<double>(q[0]) * q[0] + static_cast<double>(q[1]) * q[1] +
                        static_cast<double>(q[2]) * q[2] + static_cast<double>(q[3]) * q[3];
      // A unit quaternion from the device; anything far from unit length (zero, NaN, inf) is not a rotation.
      ok = n2 >= 0.25 && n2 <= 4.0;
      if (ok) {
        const double inv = 1.0 / std::sqrt(n2);
        for (float& c : q) c = static_cast<float>(c * inv);
      }
    }
    if (!ok) {
      clearMarker(m);
      ++rejected;
      continue;
    }
    m.position_mm[0] = x;
    m.position_mm[1] = y;
    m.position_mm[2] = z;
    for (std::size_t k = 0; k < 4; ++k) m.orientation[k] = q[k];
    m.has_orientation = has_q ? 1 : 0;
    m.valid = 1;
  }
  if (rejected > 0) {
    flags |= kFrameRejectedMarkers;
    stats_.rejected_markers += rejected;
  }
  out.frame_counter = extended;
  out.device_timestamp_ns = h.device_time_ns;
  out.receive_timestamp_ns = receive_ns;
  out.flags = flags;
  out.marker_count = h.marker_count;
  out.rejected_count = rejected;
  ++stats_.frames_decoded;
  return MarkerStreamStatus::kFrame;
}

MarkerStreamStatus MarkerStreamDecoder::decodeHidReport(std::span<const std::uint8_t> report, std::int64_t receive_ns,
                                                        MarkerFrame& out) noexcept {
  const MarkerStreamStatus st = reassembler_.push(report);
  if (st == MarkerStreamStatus::kNeedMore) return st;
  if (st != MarkerStreamStatus::kFrame) {
    ++stats_.fragment_errors;
    return st;
  }
  const std::span<const std::uint8_t> frame = reassembler_.frame();
  // The tag is the low half of the u32 at offset 12 of either message kind (a frame's
  // frame_counter, a descriptor's table_id). A message too short to hold it is judged by
  // decodeFrame (truncated) instead.
  if (frame.size() >= kOffFrameCounter + 4 && (magicMatches(frame.data()) || descriptorMagicMatches(frame.data())) &&
      static_cast<std::uint16_t>(loadU32(frame.data() + kOffFrameCounter)) != reassembler_.frameTag()) {
    ++stats_.fragment_errors;
    if (descriptorMagicMatches(frame.data())) ++stats_.descriptors_rejected;
    return MarkerStreamStatus::kBadFragment;
  }
  return decodeFrame(frame, receive_ns, out);
}

// ---------------------------------------------------------------------------------------------

std::size_t encodeMarkerStreamFrame(const MarkerFrame& frame, const MarkerStreamEncodeOptions& options,
                                    std::span<std::uint8_t> out) noexcept {
  if (frame.marker_count > kMarkerStreamMaxMarkers) return 0;
  const std::size_t size = markerStreamFrameSize(frame.marker_count, options.record_format);
  if (out.size() < size) return 0;
  std::uint8_t* p = out.data();
  std::memcpy(p + kOffMagic, kMarkerStreamMagic.data(), kMarkerStreamMagic.size());
  p[kOffVersionMajor] = kMarkerStreamVersionMajor;
  p[kOffVersionMinor] = kMarkerStreamVersionMinor;
  p[kOffHeaderSize] = static_cast<std::uint8_t>(kMarkerStreamHeaderSize);
  p[kOffRecordFormat] = static_cast<std::uint8_t>(options.record_format);
  storeU16(p + kOffFrameLength, static_cast<std::uint16_t>(size));
  storeU16(p + kOffMarkerCount, frame.marker_count);
  storeU32(p + kOffFrameCounter, static_cast<std::uint32_t>(frame.frame_counter));
  storeU64(p + kOffDeviceTime, static_cast<std::uint64_t>(frame.device_timestamp_ns));
  storeU16(p + kOffFrameFlags, options.frame_flags);
  storeU16(p + kOffFrameFlags + 2, 0);
  const bool pose = options.record_format == MarkerRecordFormat::kPose;
  const std::size_t rec = recordSize(options.record_format);
  std::uint8_t* r = p + kMarkerStreamHeaderSize;
  for (std::size_t i = 0; i < frame.marker_count; ++i, r += rec) {
    const Marker& m = frame.markers[i];
    storeU16(r + kRecId, m.id);
    std::uint8_t f = m.valid != 0 ? kMarkerFlagValid : 0;
    if (pose && m.has_orientation != 0) f |= kMarkerFlagHasOrientation;
    r[kRecFlags] = f;
    r[kRecFlags + 1] = 0;
    for (std::size_t k = 0; k < 3; ++k) storeF32(r + kRecPosition + 4 * k, m.position_mm[k]);
    if (pose) {
      for (std::size_t k = 0; k < 4; ++k) storeF32(r + kRecQuaternion + 4 * k, m.orientation[k]);
    }
  }
  const std::size_t body = size - kMarkerStreamCrcSize;
  storeU32(p + body, crc32c(out.first(body)));
  return size;
}

std::size_t encodeMarkerStreamFragment(std::span<const std::uint8_t> frame_bytes, std::size_t index,
                                       std::span<std::uint8_t> report) noexcept {
  const std::size_t count = markerStreamFragmentCount(frame_bytes.size());
  if (frame_bytes.size() < kOffFrameCounter + 4 || count == 0 || index >= count ||
      report.size() < kMarkerStreamHidReportSize) {
    return 0;
  }
  const std::size_t offset = index * kMarkerStreamFragmentPayload;
  const std::size_t len = std::min(kMarkerStreamFragmentPayload, frame_bytes.size() - offset);
  std::uint8_t* p = report.data();
  std::memset(p, 0, kMarkerStreamHidReportSize);
  p[0] = kMarkerStreamHidInputReportId;
  storeU16(p + 1, static_cast<std::uint16_t>(loadU32(frame_bytes.data() + kOffFrameCounter)));
  p[3] = static_cast<std::uint8_t>(index);
  p[4] = static_cast<std::uint8_t>(count);
  p[5] = static_cast<std::uint8_t>(len);
  std::memcpy(p + kMarkerStreamFragmentHeaderSize, frame_bytes.data() + offset, len);
  return kMarkerStreamHidReportSize;
}

// ---------------------------------------------------------------------------------------------

std::size_t encodeMarkerStreamCommandReport(MarkerStreamCommand command, std::uint16_t param,
                                            std::span<std::uint8_t> report) noexcept {
  if (report.size() < kMarkerStreamHidReportSize) return 0;
  std::memset(report.data(), 0, kMarkerStreamHidReportSize);
  report[0] = kMarkerStreamHidOutputReportId;
  report[kCmdOpcode] = static_cast<std::uint8_t>(command);
  storeU16(report.data() + kCmdParam, param);
  return kMarkerStreamHidReportSize;
}

bool decodeMarkerStreamCommandReport(std::span<const std::uint8_t> report, MarkerStreamCommand& command,
                                     std::uint16_t& param) noexcept {
  if (report.size() < kCmdParam + 2 || report[0] != kMarkerStreamHidOutputReportId ||
      !isKnownCommand(report[kCmdOpcode])) {
    return false;
  }
  command = static_cast<MarkerStreamCommand>(report[kCmdOpcode]);
  param = loadU16(report.data() + kCmdParam);
  return true;
}

UsbControlSetup markerStreamControlSetup(MarkerStreamCommand command, std::uint16_t param,
                                         std::uint16_t interface_number) noexcept {
  UsbControlSetup s;
  s.request = static_cast<std::uint8_t>(command);
  s.index = interface_number;
  if (command == MarkerStreamCommand::kGetInfo) {
    s.request_type = 0xC1;  // device-to-host | vendor | interface
    s.length = static_cast<std::uint16_t>(kMarkerStreamInfoSize);
  } else {
    s.request_type = 0x41;  // host-to-device | vendor | interface
    s.value = param;
  }
  return s;
}

std::size_t encodeMarkerStreamInfo(const MarkerStreamDeviceInfo& info, std::span<std::uint8_t> out) noexcept {
  if (out.size() < kMarkerStreamInfoSize) return 0;
  std::uint8_t* p = out.data();
  std::memset(p, 0, kMarkerStreamInfoSize);
  p[0] = info.version_major;
  p[1] = info.version_minor;
  p[2] = info.streaming;
  p[3] = static_cast<std::uint8_t>(info.record_format);
  storeU16(p + 4, info.max_markers);
  storeU16(p + 6, info.rate_hz);
  storeU16(p + 8, info.min_rate_hz);
  storeU16(p + 10, info.max_rate_hz);
  return kMarkerStreamInfoSize;
}

bool decodeMarkerStreamInfo(std::span<const std::uint8_t> bytes, MarkerStreamDeviceInfo& info) noexcept {
  if (bytes.size() < kMarkerStreamInfoSize || bytes[3] > static_cast<std::uint8_t>(MarkerRecordFormat::kPose)) {
    return false;
  }
  const std::uint8_t* p = bytes.data();
  info.version_major = p[0];
  info.version_minor = p[1];
  info.streaming = p[2];
  info.record_format = static_cast<MarkerRecordFormat>(p[3]);
  info.max_markers = loadU16(p + 4);
  info.rate_hz = loadU16(p + 6);
  info.min_rate_hz = loadU16(p + 8);
  info.max_rate_hz = loadU16(p + 10);
  return true;
}

}  // namespace tetrig::drivers
