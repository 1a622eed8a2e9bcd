// libFuzzer target for the tetrig marker-stream decoder and HID reassembler
// (docs/protocol.md, "Fuzzing"). Checks, besides memory safety (ASan/UBSan in the fuzz preset):
// a decoded frame never carries a non-finite or out-of-range valid marker, quaternions are unit,
// counters only grow, and re-encoding a decoded frame decodes to the same frame.
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>

#include "tetrig/drivers/marker_stream.hpp"

namespace {

using namespace tetrig::drivers;

void check(bool ok) {
  if (!ok) __builtin_trap();
}

void checkFrame(const tetrig::MarkerFrame& f, float limit) {
  check(f.marker_count <= tetrig::kMaxMarkers);
  check(f.rejected_count <= f.marker_count);
  for (std::size_t i = 0; i < f.marker_count; ++i) {
    const auto& m = f.markers[i];
    for (float p : m.position_mm) check(std::isfinite(p) && std::fabs(p) <= limit);
    if (m.has_orientation != 0) {
      double n2 = 0.0;
      for (float q : m.orientation) n2 += static_cast<double>(q) * q;
      check(m.valid == 1 && std::fabs(n2 - 1.0) < 1e-5);
    }
  }
}

// decode(encode(f)) must reproduce f's markers (valid ones bit-exactly).
void checkReencode(const tetrig::MarkerFrame& f, MarkerRecordFormat format) {
  static std::array<std::uint8_t, kMarkerStreamMaxFrameSize> buf;
  MarkerStreamEncodeOptions o;
  o.record_format = format;
  const std::size_t n = encodeMarkerStreamFrame(f, o, buf);
  check(n == markerStreamFrameSize(f.marker_count, format));
  MarkerStreamDecoder dec;
  auto g = std::make_unique<tetrig::MarkerFrame>();
  check(dec.decodeFrame(std::span(buf.data(), n), 0, *g) == MarkerStreamStatus::kFrame);
  check(g->marker_count == f.marker_count && g->rejected_count == 0);
  for (std::size_t i = 0; i < f.marker_count; ++i) {
    const auto& a = f.markers[i];
    const auto& b = g->markers[i];
    check(a.id == b.id && a.valid == b.valid);
    if (a.valid != 0) {
      for (int k = 0; k < 3; ++k) check(a.position_mm[k] == b.position_mm[k]);
    }
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static auto frame = std::make_unique<tetrig::MarkerFrame>();
  const std::span<const std::uint8_t> in(data, size);
  const float limit = kMarkerStreamDefaultMaxAbsCoordinateMm;

  // 1. The whole input as one bulk frame, then as a stream of frames cut by peek.
  {
    MarkerStreamDecoder dec;
    MarkerStreamHeader h;
    const MarkerStreamStatus v = validateMarkerStreamFrame(in, h);
    const MarkerStreamStatus st = dec.decodeFrame(in, 1, *frame);
    check(st == v);  // first frame: no sequence verdicts, same answer as validation
    if (st == MarkerStreamStatus::kFrame) {
      checkFrame(*frame, limit);
      checkReencode(*frame, h.record_format);
    }
    std::size_t pos = 0;
    std::uint64_t last = 0;
    bool have = false;
    while (pos < size) {
      const std::size_t len = markerStreamPeekFrameLength(in.subspan(pos));
      if (len == 0 || pos + len > size) break;
      if (dec.decodeFrame(in.subspan(pos, len), 2, *frame) == MarkerStreamStatus::kFrame) {
        checkFrame(*frame, limit);
        check(!have || frame->frame_counter > last);
        last = frame->frame_counter;
        have = true;
      }
      pos += len;
    }
  }
  // 2. The input as a sequence of HID reports (64 bytes each, last one short).
  {
    MarkerStreamDecoder dec;
    std::uint64_t last = 0;
    bool have = false;
    for (std::size_t pos = 0; pos < size; pos += kMarkerStreamHidReportSize) {
      const std::size_t len = size - pos < kMarkerStreamHidReportSize ? size - pos : kMarkerStreamHidReportSize;
      const MarkerStreamStatus st = dec.decodeHidReport(in.subspan(pos, len), 3, *frame);
      if (st == MarkerStreamStatus::kFrame) {
        checkFrame(*frame, limit);
        check(!have || frame->frame_counter > last);
        last = frame->frame_counter;
        have = true;
      }
    }
    const auto& rs = dec.reassembler().stats();
    check(rs.reports == (size + kMarkerStreamHidReportSize - 1) / kMarkerStreamHidReportSize);
  }
  // 3. Control blocks.
  {
    MarkerStreamCommand cmd{};
    std::uint16_t param = 0;
    (void)decodeMarkerStreamCommandReport(in, cmd, param);
    MarkerStreamDeviceInfo info;
    (void)decodeMarkerStreamInfo(in, info);
  }
  return 0;
}
