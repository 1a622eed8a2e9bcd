// The tetrig marker-stream descriptor message, version 1.0 (docs/protocol.md, section 2a
// "Descriptor" and 4.4 "Descriptor decoding"): validation and decoding of a "TMSD" message into a
// fixed-capacity label table (ids strictly ascending, labels 1..31 bytes of printable UTF-8,
// unique), the encoder, and the table's binary-search lookup.
//
// Layout: [0] "TMSD", [4] version_major, [5] version_minor, [6] header_size, [7] reserved,
// [8] descriptor_length u16, [10] entry_count u16, [12] table_id u32, [16] reserved u32,
// [header_size ..] entries (id u16, label_length u8, label bytes), CRC-32C of everything before it.
#include <algorithm>
#include <cstring>

#include "byte_io.hpp"
#include "tetrig/drivers/crc32c.hpp"
#include "tetrig/drivers/marker_stream.hpp"

namespace tetrig::drivers {

using detail::loadU16;
using detail::loadU32;
using detail::storeU16;
using detail::storeU32;

namespace {

constexpr std::size_t kOffMagic = 0;
constexpr std::size_t kOffVersionMajor = 4;
constexpr std::size_t kOffVersionMinor = 5;
constexpr std::size_t kOffHeaderSize = 6;
constexpr std::size_t kOffReserved7 = 7;
constexpr std::size_t kOffLength = 8;
constexpr std::size_t kOffEntryCount = 10;
constexpr std::size_t kOffTableId = 12;
constexpr std::size_t kOffReserved16 = 16;
constexpr std::size_t kMinEntrySize = kMarkerStreamDescriptorEntryHeaderSize + 1;
constexpr std::size_t kMaxEntrySize = kMarkerStreamDescriptorEntryHeaderSize + kMarkerLabelMaxLength;

bool validLabelBytes(const std::uint8_t* p, std::size_t n) noexcept {
  if (n == 0 || n > kMarkerLabelMaxLength) return false;
  std::size_t i = 0;
  while (i < n) {
    const std::uint8_t b = p[i];
    if (b < 0x80) {
      if (b < 0x20 || b == 0x7F) return false;  // C0 controls (NUL included) and DEL
      ++i;
      continue;
    }
    std::size_t len = 0;
    std::uint32_t cp = 0;
    std::uint32_t min = 0;
    if (b >= 0xC2 && b <= 0xDF) {
      len = 2;
      cp = b & 0x1Fu;
      min = 0x80;
    } else if (b >= 0xE0 && b <= 0xEF) {
      len = 3;
      cp = b & 0x0Fu;
      min = 0x800;
    } else if (b >= 0xF0 && b <= 0xF4) {
      len = 4;
      cp = b & 0x07u;
      min = 0x10000;
    } else {
      return false;  // continuation byte first, C0/C1 overlong leads, F5..FF
    }
    if (n - i < len) return false;
    for (std::size_t k = 1; k < len; ++k) {
      const std::uint8_t c = p[i + k];
      if ((c & 0xC0u) != 0x80u) return false;
      cp = (cp << 6) | (c & 0x3Fu);
    }
    if (cp < min || cp > 0x10FFFF || (cp >= 0xD800 && cp <= 0xDFFF)) return false;
    if (cp <= 0x9F) return false;  // C1 controls U+0080..U+009F
    i += len;
  }
  return true;
}

}  // namespace

bool isValidMarkerLabel(std::string_view label) noexcept {
  return validLabelBytes(reinterpret_cast<const std::uint8_t*>(label.data()), label.size());
}

const MarkerLabelEntry* MarkerLabelTable::find(std::uint16_t id) const noexcept {
  const std::size_t n = std::min<std::size_t>(count, entries.size());
  const auto* first = entries.data();
  const auto* last = first + n;
  const auto* it = std::lower_bound(first, last, id, [](const MarkerLabelEntry& e, std::uint16_t v) { return e.id < v; });
  return it != last && it->id == id ? it : nullptr;
}

std::string_view MarkerLabelTable::label(std::uint16_t id) const noexcept {
  const MarkerLabelEntry* e = find(id);
  return e != nullptr ? e->label() : std::string_view{};
}

MarkerStreamStatus decodeMarkerStreamDescriptor(std::span<const std::uint8_t> bytes, MarkerLabelTable& table) noexcept {
  const std::uint8_t* p = bytes.data();
  const std::size_t n = bytes.size();
  if (n < kMarkerStreamDescriptorMagic.size()) return MarkerStreamStatus::kTruncated;
  if (std::memcmp(p + kOffMagic, kMarkerStreamDescriptorMagic.data(), kMarkerStreamDescriptorMagic.size()) != 0) {
    return MarkerStreamStatus::kBadMagic;
  }
  if (n <= kOffVersionMajor) return MarkerStreamStatus::kTruncated;
  if (p[kOffVersionMajor] != kMarkerStreamDescriptorVersionMajor) return MarkerStreamStatus::kUnsupportedVersion;
  if (n < kMarkerStreamDescriptorHeaderSize) return MarkerStreamStatus::kTruncated;

  const std::size_t header_size = p[kOffHeaderSize];
  const std::size_t length = loadU16(p + kOffLength);
  const std::size_t count = loadU16(p + kOffEntryCount);
  if (header_size < kMarkerStreamDescriptorHeaderSize || header_size > kMarkerStreamMaxHeaderSize ||
      header_size % 4 != 0 || count > kMarkerStreamMaxMarkers) {
    return MarkerStreamStatus::kBadHeader;
  }
  // Every entry takes 4..34 bytes, so the length bounds the count both ways.
  if (length < header_size + count * kMinEntrySize + kMarkerStreamCrcSize ||
      length > header_size + count * kMaxEntrySize + kMarkerStreamCrcSize) {
    return MarkerStreamStatus::kBadLength;
  }
  if (n < length) return MarkerStreamStatus::kTruncated;
  if (n > length) return MarkerStreamStatus::kBadLength;
  const std::size_t body = length - kMarkerStreamCrcSize;
  if (crc32c(bytes.first(body)) != loadU32(p + body)) return MarkerStreamStatus::kBadCrc;

  // Pass 1: every entry well formed, ids strictly ascending, entries fill the body exactly.
  std::array<std::uint16_t, kMarkerStreamMaxMarkers> offsets{};  // of each entry's label bytes
  std::size_t pos = header_size;
  std::uint32_t previous_id = 0;
  for (std::size_t i = 0; i < count; ++i) {
    if (body - pos < kMarkerStreamDescriptorEntryHeaderSize) return MarkerStreamStatus::kBadDescriptor;
    const std::uint16_t id = loadU16(p + pos);
    const std::size_t len = p[pos + 2];
    pos += kMarkerStreamDescriptorEntryHeaderSize;
    if (len == 0 || len > kMarkerLabelMaxLength || body - pos < len) return MarkerStreamStatus::kBadDescriptor;
    if (i > 0 && id <= previous_id) return MarkerStreamStatus::kBadDescriptor;  // duplicate or unsorted
    if (!validLabelBytes(p + pos, len)) return MarkerStreamStatus::kBadDescriptor;
    offsets[i] = static_cast<std::uint16_t>(pos);
    previous_id = id;
    pos += len;
  }
  if (pos != body) return MarkerStreamStatus::kBadDescriptor;
  // Labels are unique (a rig binds by label). At most 256 * 255 / 2 short comparisons.
  for (std::size_t i = 0; i < count; ++i) {
    const std::size_t li = p[offsets[i] - 1];
    for (std::size_t j = i + 1; j < count; ++j) {
      if (p[offsets[j] - 1] == li && std::memcmp(p + offsets[i], p + offsets[j], li) == 0) {
        return MarkerStreamStatus::kBadDescriptor;
      }
    }
  }

  // Pass 2: accepted. Replace the table, noting whether anything changed.
  bool changed = table.generation == 0 || table.count != count;
  for (std::size_t i = 0; i < count; ++i) {
    MarkerLabelEntry& e = table.entries[i];
    const std::uint8_t* label = p + offsets[i];
    const auto len = static_cast<std::uint8_t>(label[-1]);
    const std::uint16_t id = loadU16(label - kMarkerStreamDescriptorEntryHeaderSize);
    if (!changed && (e.id != id || e.length != len || std::memcmp(e.text, label, len) != 0)) changed = true;
    e.id = id;
    e.length = len;
    std::memcpy(e.text, label, len);
    std::memset(e.text + len, 0, kMarkerLabelMaxLength - len);
  }
  table.count = static_cast<std::uint16_t>(count);
  table.table_id = loadU32(p + kOffTableId);
  if (changed && ++table.generation == 0) table.generation = 1;  // 0 keeps meaning "none yet"
  return MarkerStreamStatus::kDescriptor;
}

std::size_t markerStreamDescriptorSize(std::span<const MarkerLabel> labels) noexcept {
  std::size_t size = kMarkerStreamDescriptorHeaderSize + kMarkerStreamCrcSize;
  for (const MarkerLabel& l : labels) size += kMarkerStreamDescriptorEntryHeaderSize + l.label.size();
  return size;
}

std::size_t encodeMarkerStreamDescriptor(std::span<const MarkerLabel> labels, std::uint32_t table_id,
                                         std::span<std::uint8_t> out) noexcept {
  if (labels.size() > kMarkerStreamMaxMarkers) return 0;
  for (const MarkerLabel& l : labels) {
    if (l.label.size() > kMarkerLabelMaxLength) return 0;
  }
  const std::size_t size = markerStreamDescriptorSize(labels);
  if (out.size() < size) return 0;
  std::uint8_t* p = out.data();
  std::memcpy(p + kOffMagic, kMarkerStreamDescriptorMagic.data(), kMarkerStreamDescriptorMagic.size());
  p[kOffVersionMajor] = kMarkerStreamDescriptorVersionMajor;
  p[kOffVersionMinor] = kMarkerStreamDescriptorVersionMinor;
  p[kOffHeaderSize] = static_cast<std::uint8_t>(kMarkerStreamDescriptorHeaderSize);
  p[kOffReserved7] = 0;
  storeU16(p + kOffLength, static_cast<std::uint16_t>(size));
  storeU16(p + kOffEntryCount, static_cast<std::uint16_t>(labels.size()));
  storeU32(p + kOffTableId, table_id);
  storeU32(p + kOffReserved16, 0);
  std::uint8_t* e = p + kMarkerStreamDescriptorHeaderSize;
  for (const MarkerLabel& l : labels) {
    storeU16(e, l.id);
    e[2] = static_cast<std::uint8_t>(l.label.size());
    if (!l.label.empty()) std::memcpy(e + kMarkerStreamDescriptorEntryHeaderSize, l.label.data(), l.label.size());
    e += kMarkerStreamDescriptorEntryHeaderSize + l.label.size();
  }
  const std::size_t body = size - kMarkerStreamCrcSize;
  storeU32(p + body, crc32c(out.first(body)));
  return size;
}

}  // namespace tetrig::drivers
