// libFuzzer target for the tetrig marker-stream decoder and HID reassembler, frames and
// descriptors (docs/protocol.md, "Fuzzing"). Checks, besides memory safety (ASan/UBSan in the fuzz
// preset): a decoded frame never carries a non-finite or out-of-range valid marker, quaternions
// are unit, counters only grow, and re-encoding a decoded frame decodes to the same frame; an
// accepted label table has strictly ascending ids and unique, valid labels of 1..31 bytes and
// re-encodes to the same table; a rejected descriptor leaves the table exactly as it was.
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
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

bool sameEntries(const MarkerLabelTable& a, const MarkerLabelTable& b) {
  if (a.count != b.count) return false;
  for (std::size_t i = 0; i < a.count; ++i) {
    const auto& x = a.entries[i];
    const auto& y = b.entries[i];
    if (x.id != y.id || x.label() != y.label()) return false;
  }
  return true;
}

// Properties of an accepted table, checked without the decoder's own label validator where a
// plain rule will do; then encode(table) must decode to the same table.
void checkTable(const MarkerLabelTable& t) {
  check(t.count <= kMarkerStreamMaxMarkers && t.generation > 0);
  for (std::size_t i = 0; i < t.count; ++i) {
    const auto& e = t.entries[i];
    check(i == 0 || e.id > t.entries[i - 1].id);
    check(e.length >= 1 && e.length <= kMarkerLabelMaxLength);
    for (std::size_t k = 0; k < e.length; ++k) {
      const auto c = static_cast<std::uint8_t>(e.text[k]);
      check(c >= 0x20 && c != 0x7F && c != 0xC0 && c != 0xC1 && c < 0xF5);
    }
    for (std::size_t k = e.length; k < kMarkerLabelMaxLength; ++k) check(e.text[k] == 0);
    check(isValidMarkerLabel(e.label()));
    check(t.find(e.id) == &e && t.label(e.id) == e.label());
    for (std::size_t j = 0; j < i; ++j) check(t.entries[j].label() != e.label());
  }
  static std::array<MarkerLabel, kMarkerStreamMaxMarkers> labels;
  for (std::size_t i = 0; i < t.count; ++i) labels[i] = {t.entries[i].id, t.entries[i].label()};
  static std::array<std::uint8_t, kMarkerStreamMaxDescriptorSize> buf;
  const std::span<const MarkerLabel> used(labels.data(), t.count);
  const std::size_t n = encodeMarkerStreamDescriptor(used, t.table_id, buf);
  check(n == markerStreamDescriptorSize(used) && n > 0);
  static auto again = std::make_unique<MarkerLabelTable>();
  *again = MarkerLabelTable{};
  check(decodeMarkerStreamDescriptor(std::span(buf.data(), n), *again) == MarkerStreamStatus::kDescriptor);
  check(sameEntries(*again, t) && again->table_id == t.table_id && again->generation == 1);
}

// Decodes one message with `dec` and checks what it did to the label table.
MarkerStreamStatus decodeChecked(MarkerStreamDecoder& dec, std::span<const std::uint8_t> msg, std::int64_t ns,
                                 tetrig::MarkerFrame& frame) {
  static auto before = std::make_unique<MarkerLabelTable>();
  *before = dec.labels();
  const MarkerStreamStatus st = dec.decodeFrame(msg, ns, frame);
  if (st == MarkerStreamStatus::kDescriptor) {
    checkTable(dec.labels());
    const bool changed = !sameEntries(*before, dec.labels()) || before->generation == 0;
    check(dec.labels().generation == before->generation + (changed ? 1u : 0u));
  } else {
    const MarkerLabelTable& after = dec.labels();
    check(after.count == before->count && after.generation == before->generation &&
          after.table_id == before->table_id &&
          std::memcmp(after.entries.data(), before->entries.data(), sizeof(after.entries)) == 0);
  }
  return st;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static auto frame = std::make_unique<tetrig::MarkerFrame>();
  const std::span<const std::uint8_t> in(data, size);
  const float limit = kMarkerStreamDefaultMaxAbsCoordinateMm;
  const bool descriptor_magic =
      size >= 4 && std::memcmp(data, kMarkerStreamDescriptorMagic.data(), kMarkerStreamDescriptorMagic.size()) == 0;

  // 1. The whole input as one bulk message, then as a stream of messages cut by peek.
  {
    MarkerStreamDecoder dec;
    MarkerStreamHeader h;
    static auto fresh = std::make_unique<MarkerLabelTable>();
    *fresh = MarkerLabelTable{};
    // First message: no sequence verdicts, same answer as the stateless validation.
    const MarkerStreamStatus v =
        descriptor_magic ? decodeMarkerStreamDescriptor(in, *fresh) : validateMarkerStreamFrame(in, h);
    const MarkerStreamStatus st = decodeChecked(dec, in, 1, *frame);
    check(st == v);
    if (st == MarkerStreamStatus::kFrame) {
      checkFrame(*frame, limit);
      checkReencode(*frame, h.record_format);
    }
    if (st == MarkerStreamStatus::kDescriptor) check(sameEntries(*fresh, dec.labels()));
    std::size_t pos = 0;
    std::uint64_t last = 0;
    bool have = false;
    while (pos < size) {
      const std::size_t len = markerStreamPeekFrameLength(in.subspan(pos));
      if (len == 0 || pos + len > size) break;
      if (decodeChecked(dec, in.subspan(pos, len), 2, *frame) == MarkerStreamStatus::kFrame) {
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
      const std::uint32_t generation = dec.labels().generation;
      const MarkerStreamStatus st = dec.decodeHidReport(in.subspan(pos, len), 3, *frame);
      if (st == MarkerStreamStatus::kDescriptor) {
        checkTable(dec.labels());
      } else {
        check(dec.labels().generation == generation);
      }
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
