// Tetrig marker-stream protocol v1.0 (docs/protocol.md, section 3.2 "HID"): in-order
// reassembly of one message (a frame or a descriptor) from 64-byte HID input reports into a
// fixed buffer.
//
// Fragment report: [0] report id 0x01, [1..2] tag = low 16 bits (LE) of the message's u32 at
// offset 12 (a frame's frame_counter, a descriptor's table_id), [3] index, [4] count (1..152),
// [5] payload length (1..58; exactly 58 for every fragment but the last), [6..] payload.
#include <cstring>

#include "byte_io.hpp"
#include "tetrig/drivers/marker_stream.hpp"

namespace tetrig::drivers {

void MarkerStreamReassembler::dropPartial() noexcept {
  if (active_) {
    ++stats_.partial_frames_dropped;
  }
  active_ = false;
  filled_ = 0;
}

void MarkerStreamReassembler::reset() noexcept {
  active_ = false;
  filled_ = 0;
  frame_size_ = 0;
}

MarkerStreamStatus MarkerStreamReassembler::push(std::span<const std::uint8_t> report) noexcept {
  ++stats_.reports;
  frame_size_ = 0;
  if (report.size() < kMarkerStreamFragmentHeaderSize) {
    ++stats_.bad_reports;
    dropPartial();
    return MarkerStreamStatus::kTruncated;
  }
  const std::uint8_t* p = report.data();
  if (p[0] != kMarkerStreamHidInputReportId) {
    // Another report of the device (not part of the stream): leaves a frame in progress alone.
    ++stats_.bad_reports;
    return MarkerStreamStatus::kBadReport;
  }
  const std::uint16_t tag = detail::loadU16(p + 1);
  const std::uint8_t index = p[3];
  const std::uint8_t count = p[4];
  const std::uint8_t len = p[5];
  const bool last = count > 0 && index == count - 1;
  if (count == 0 || count > kMarkerStreamMaxFragments || index >= count || len == 0 ||
      len > kMarkerStreamFragmentPayload || (!last && len != kMarkerStreamFragmentPayload)) {
    ++stats_.bad_reports;
    dropPartial();
    return MarkerStreamStatus::kBadFragment;
  }
  if (report.size() < kMarkerStreamFragmentHeaderSize + len) {
    ++stats_.bad_reports;
    dropPartial();
    return MarkerStreamStatus::kTruncated;
  }
  if (index == 0) {
    dropPartial();  // a new frame starts: an unfinished one is lost
    active_ = true;
    tag_ = tag;
    count_ = count;
    next_index_ = 0;
  } else if (!active_) {
    ++stats_.orphan_fragments;
    return MarkerStreamStatus::kFragmentLost;
  } else if (tag != tag_ || count != count_ || index != next_index_) {
    dropPartial();
    return MarkerStreamStatus::kFragmentLost;
  }
  // index * 58 + len <= count * 58 <= buffer size: the copy is in bounds.
  std::memcpy(buffer_.data() + filled_, p + kMarkerStreamFragmentHeaderSize, len);
  filled_ += len;
  next_index_ = static_cast<std::uint8_t>(index + 1);
  if (!last) {
    return MarkerStreamStatus::kNeedMore;
  }
  active_ = false;
  frame_size_ = filled_;
  filled_ = 0;
  ++stats_.frames;
  return MarkerStreamStatus::kFrame;
}

}  // namespace tetrig::drivers
