// The tetrig marker-stream protocol, version 1.0, and its descriptor message, version 1.0: pure
// decoder, fragment reassembler and encoders. The normative specification (byte tables, CRC,
// fragmentation, commands) is docs/protocol.md; this header mirrors it. Summary:
//
//   frame      = header (28 bytes) + marker_count records (16 or 32 bytes) + CRC-32C (4 bytes),
//                all little-endian; positions are IEEE-754 binary32 millimetres.
//   descriptor = header (20 bytes) + entry_count (id u16, label_length u8, label bytes) entries
//                sorted by id + CRC-32C: the label of each marker id ("TMSD"; section 2a).
//   HID        = a message (frame or descriptor) split over 64-byte input reports (report id
//                0x01, 6-byte fragment header, up to 58 payload bytes each), reassembled in order.
//   USB        = one whole message per bulk IN transfer (at most kMarkerStreamMaxMessageSize bytes).
//   control    = start / stop / set-rate / get-descriptor as HID output report 0x02 or USB vendor
//                control requests; device info as HID feature report 0x03 or a vendor IN request.
//
// Nothing here does I/O, allocates, locks or throws. Decoders and reassemblers are single-thread
// objects (one per stream, used on that stream's driver thread); the free functions may be
// called from any thread.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string_view>

#include "tetrig/marker_frame.hpp"

namespace tetrig::drivers {

// ---------------------------------------------------------------------------------------------
// Wire constants (docs/protocol.md, section "Frame").

inline constexpr std::array<std::uint8_t, 4> kMarkerStreamMagic = {0x54, 0x4D, 0x53, 0x46};  // "TMSF"
inline constexpr std::uint8_t kMarkerStreamVersionMajor = 1;
inline constexpr std::uint8_t kMarkerStreamVersionMinor = 0;
inline constexpr std::size_t kMarkerStreamHeaderSize = 28;     // header_size written by v1.0 senders
inline constexpr std::size_t kMarkerStreamMaxHeaderSize = 64;  // largest header_size a decoder accepts
inline constexpr std::size_t kMarkerStreamCrcSize = 4;
inline constexpr std::size_t kMarkerStreamMaxMarkers = 256;    // == tetrig::kMaxMarkers
inline constexpr std::size_t kMarkerRecordSizePosition = 16;
inline constexpr std::size_t kMarkerRecordSizePose = 32;
// Largest frame a v1 decoder accepts: 64 + 256 * 32 + 4 = 8260 bytes.
inline constexpr std::size_t kMarkerStreamMaxFrameSize =
    kMarkerStreamMaxHeaderSize + kMarkerStreamMaxMarkers * kMarkerRecordSizePose + kMarkerStreamCrcSize;
static_assert(kMarkerStreamMaxMarkers == static_cast<std::size_t>(tetrig::kMaxMarkers));

// Descriptor message (docs/protocol.md, section 2a): labels for marker ids.
inline constexpr std::array<std::uint8_t, 4> kMarkerStreamDescriptorMagic = {0x54, 0x4D, 0x53, 0x44};  // "TMSD"
inline constexpr std::uint8_t kMarkerStreamDescriptorVersionMajor = 1;
inline constexpr std::uint8_t kMarkerStreamDescriptorVersionMinor = 0;
inline constexpr std::size_t kMarkerStreamDescriptorHeaderSize = 20;  // header_size written by v1.0 senders
inline constexpr std::size_t kMarkerLabelMaxLength = 31;              // label bytes (UTF-8, no NUL)
inline constexpr std::size_t kMarkerStreamDescriptorEntryHeaderSize = 3;  // id u16 + label_length u8
// Largest descriptor a v1 decoder accepts: 64 + 256 * (3 + 31) + 4 = 8772 bytes.
inline constexpr std::size_t kMarkerStreamMaxDescriptorSize =
    kMarkerStreamMaxHeaderSize + kMarkerStreamMaxMarkers * (kMarkerStreamDescriptorEntryHeaderSize + kMarkerLabelMaxLength) +
    kMarkerStreamCrcSize;
// Largest message of either kind: what a USB IN transfer and the HID reassembly buffer must hold.
inline constexpr std::size_t kMarkerStreamMaxMessageSize =
    kMarkerStreamMaxDescriptorSize > kMarkerStreamMaxFrameSize ? kMarkerStreamMaxDescriptorSize : kMarkerStreamMaxFrameSize;

// Largest |coordinate| a decoder accepts by default (100 m); larger values are "absurd".
inline constexpr float kMarkerStreamDefaultMaxAbsCoordinateMm = 100000.0f;

enum class MarkerRecordFormat : std::uint8_t {
  kPosition = 0,  // 16-byte records: id, flags, x, y, z
  kPose = 1,      // 32-byte records: id, flags, x, y, z, qw, qx, qy, qz
};

// Frame flags (header offset 24, u16). Bits not listed are reserved: senders write 0, decoders ignore.
inline constexpr std::uint16_t kStreamFlagStreamStart = 1u << 0;     // first frame after START/reset
inline constexpr std::uint16_t kStreamFlagDeviceOverflow = 1u << 1;  // device saw more markers than it sent

// Marker flags (record offset 2, u8). Other bits reserved: senders write 0, decoders ignore.
inline constexpr std::uint8_t kMarkerFlagValid = 1u << 0;
inline constexpr std::uint8_t kMarkerFlagHasOrientation = 1u << 1;  // kPose records only

// HID transport (docs/protocol.md, section "HID").
inline constexpr std::size_t kMarkerStreamHidReportSize = 64;      // including the report id byte
inline constexpr std::uint8_t kMarkerStreamHidInputReportId = 0x01;   // frame fragments, device -> host
inline constexpr std::uint8_t kMarkerStreamHidOutputReportId = 0x02;  // commands, host -> device
inline constexpr std::uint8_t kMarkerStreamHidFeatureReportId = 0x03; // device info (GET_FEATURE)
inline constexpr std::size_t kMarkerStreamFragmentHeaderSize = 6;
inline constexpr std::size_t kMarkerStreamFragmentPayload = kMarkerStreamHidReportSize - kMarkerStreamFragmentHeaderSize;  // 58
inline constexpr std::size_t kMarkerStreamMaxFragments =
    (kMarkerStreamMaxMessageSize + kMarkerStreamFragmentPayload - 1) / kMarkerStreamFragmentPayload;  // 152

// ---------------------------------------------------------------------------------------------
// Status codes (libusb style: 0 and positive = success kinds, negative = errors).

enum class MarkerStreamStatus : int {
  kFrame = 0,                // a frame was decoded into the caller's MarkerFrame
  kNeedMore = 1,             // fragment stored; the message is not complete yet (not an error)
  kDescriptor = 2,           // a descriptor was accepted: the label table changed hands (the
                             // caller's MarkerFrame is not modified)
  kTruncated = -1,           // fewer bytes than the header / frame_length / fragment header says
  kBadMagic = -2,            // first four bytes are neither "TMSF" (frame) nor "TMSD" (descriptor)
  kUnsupportedVersion = -3,  // version_major is not 1: nothing else in the frame is interpreted
  kBadHeader = -4,           // header_size, record_format or marker_count out of range
  kBadLength = -5,           // frame_length / descriptor_length disagrees with the header, or bytes
                             // follow the message
  kBadCrc = -6,              // CRC-32C mismatch
  kDuplicate = -7,           // same frame counter as the last accepted frame: dropped
  kOutOfOrder = -8,          // frame counter behind the last accepted frame: dropped
  kBadReport = -9,           // HID report with another report id (not a marker-stream fragment)
  kBadFragment = -10,        // fragment header inconsistent (index/count/length), or the frame's
                             // counter does not match the fragment tag
  kFragmentLost = -11,       // a fragment is missing or out of order: the partial frame was dropped
  kBadDescriptor = -12,      // descriptor entries invalid (label length or bytes, ids not strictly
                             // ascending, duplicate label, entries not filling the message exactly):
                             // the whole descriptor is rejected and the previous label table kept
};

// Short stable name ("frame", "bad crc", ...). Any thread; returns a static string.
[[nodiscard]] const char* markerStreamStatusName(MarkerStreamStatus status) noexcept;

// ---------------------------------------------------------------------------------------------
// Stateless parsing.

struct MarkerStreamHeader {
  std::uint8_t version_major = 0;
  std::uint8_t version_minor = 0;
  std::uint8_t header_size = 0;
  MarkerRecordFormat record_format = MarkerRecordFormat::kPosition;
  std::uint16_t frame_length = 0;   // whole frame in bytes, CRC included
  std::uint16_t marker_count = 0;
  std::uint32_t frame_counter = 0;  // device counter (wraps at 2^32)
  std::int64_t device_time_ns = 0;  // device clock; 0 = unknown
  std::uint16_t frame_flags = 0;    // kStreamFlag*
};

// Bytes one frame of `marker_count` records occupies with a v1.0 (28-byte) header.
[[nodiscard]] constexpr std::size_t markerStreamFrameSize(std::size_t marker_count, MarkerRecordFormat format) noexcept {
  return kMarkerStreamHeaderSize +
         marker_count * (format == MarkerRecordFormat::kPose ? kMarkerRecordSizePose : kMarkerRecordSizePosition) +
         kMarkerStreamCrcSize;
}

// Checks that `bytes` is exactly one well-formed frame: magic, version, header fields,
// frame_length == bytes.size(), CRC. Fills `header` on kFrame (and leaves it unspecified
// otherwise). Returns kFrame or one of kTruncated, kBadMagic, kUnsupportedVersion, kBadHeader,
// kBadLength, kBadCrc. Does not look at the marker records' values. Any thread; no allocation.
[[nodiscard]] MarkerStreamStatus validateMarkerStreamFrame(std::span<const std::uint8_t> bytes,
                                                           MarkerStreamHeader& header) noexcept;

// For byte streams (raw recordings): the length of the message at the start of `bytes` as its
// header announces it (a frame's frame_length or a descriptor's descriptor_length), or 0 when
// fewer than 12 bytes are given, the magic is neither "TMSF" nor "TMSD", the major version is not
// 1, or the length is outside [header minimum, kMarkerStreamMaxFrameSize] for a frame or
// [24, kMarkerStreamMaxDescriptorSize] for a descriptor. Any thread; no allocation.
[[nodiscard]] std::size_t markerStreamPeekFrameLength(std::span<const std::uint8_t> bytes) noexcept;

// ---------------------------------------------------------------------------------------------
// Labels: the descriptor message (docs/protocol.md, sections 2a and 4.4).

// One named marker id. `text[0 .. length)` is the label (1..31 bytes of printable ASCII or UTF-8,
// no NUL, not NUL-terminated); bytes after `length` are 0.
struct MarkerLabelEntry {
  std::uint16_t id = 0;
  std::uint8_t length = 0;
  char text[kMarkerLabelMaxLength] = {};
  [[nodiscard]] std::string_view label() const noexcept { return {text, length}; }
};

// The label of each marker id a descriptor named: fixed capacity (256 entries, about 8.7 KB, no
// heap), trivially copyable, entries sorted by strictly ascending id (binary search). Ids not in
// the table are unnamed. Any thread may read a table no one writes; the decoder writes its own on
// its driver thread.
struct MarkerLabelTable {
  std::uint16_t count = 0;       // entries[0 .. count) are meaningful
  std::uint32_t generation = 0;  // 0: no descriptor accepted yet; +1 whenever an accepted
                                 // descriptor's entries differ from the table's (or it is the first)
  std::uint32_t table_id = 0;    // the last accepted descriptor's table_id field
  std::array<MarkerLabelEntry, kMarkerStreamMaxMarkers> entries{};

  // The entry for `id`, or nullptr if the table does not name it. O(log count); no allocation.
  [[nodiscard]] const MarkerLabelEntry* find(std::uint16_t id) const noexcept;
  // The label of `id`, or "" if it is unnamed. The view points into this table. No allocation.
  [[nodiscard]] std::string_view label(std::uint16_t id) const noexcept;
};

// Validates one whole descriptor message (`bytes` = exactly the message, CRC included) and, on
// success, replaces `table`'s entries and table_id with its contents and returns kDescriptor;
// `table.generation` grows by one when the entries differ from the ones it held or it held none
// (generation 0). On any other status (kTruncated, kBadMagic, kUnsupportedVersion, kBadHeader,
// kBadLength, kBadCrc, kBadDescriptor; checks in the order of docs/protocol.md section 4.4)
// `table` is not modified. Any thread (for `table`, the thread that owns it); no allocation.
[[nodiscard]] MarkerStreamStatus decodeMarkerStreamDescriptor(std::span<const std::uint8_t> bytes,
                                                              MarkerLabelTable& table) noexcept;

// One (id, label) pair for the encoder.
struct MarkerLabel {
  std::uint16_t id = 0;
  std::string_view label;
};

// Bytes a v1.0 descriptor of these labels occupies: 20 + sum(3 + label length) + 4.
[[nodiscard]] std::size_t markerStreamDescriptorSize(std::span<const MarkerLabel> labels) noexcept;

// Encodes a v1.0 descriptor (header_size 20) with `labels` in the order given and `table_id`
// (also the HID fragment tag's source) into `out`. Writes what it is given: unsorted or
// duplicate ids, empty or non-printable labels are encoded as they are (so tests and mock devices
// can produce hostile descriptors; a conforming sender passes ids in strictly ascending order and
// valid labels). Returns the message length, or 0 when there are more than 256 labels, a label is
// longer than kMarkerLabelMaxLength bytes, or `out` is smaller than markerStreamDescriptorSize().
// Any thread; no allocation.
[[nodiscard]] std::size_t encodeMarkerStreamDescriptor(std::span<const MarkerLabel> labels, std::uint32_t table_id,
                                                       std::span<std::uint8_t> out) noexcept;

// True if `label` is a valid descriptor label: 1..31 bytes of well-formed UTF-8 (no overlong
// forms, surrogates or code points above U+10FFFF) with no control character (U+0000..U+001F,
// U+007F..U+009F). Any thread; no allocation.
[[nodiscard]] bool isValidMarkerLabel(std::string_view label) noexcept;

// ---------------------------------------------------------------------------------------------
// Fragment reassembly (HID). Fixed 8.8 KB buffer inside the object; no allocation.

struct MarkerStreamReassemblerStats {
  std::uint64_t reports = 0;                // reports pushed
  std::uint64_t frames = 0;                 // messages (frames or descriptors) completed
  std::uint64_t partial_frames_dropped = 0; // frames abandoned because a fragment was lost/out of order
  std::uint64_t orphan_fragments = 0;       // fragments with index > 0 and no frame in progress
  std::uint64_t bad_reports = 0;            // wrong report id, truncated or inconsistent fragment headers
};

class MarkerStreamReassembler {
 public:
  // Feeds one HID input report as hidapi's hid_read returns it: byte 0 is the report id (0x01),
  // then the fragment header and payload (bytes after 6 + payload_length are ignored).
  // Returns kNeedMore (stored), kFrame (a whole message, frame or descriptor, is in frame()), or
  // kTruncated, kBadReport, kBadFragment, kFragmentLost. Reassembly is strictly in order
  // (docs/protocol.md): any missing, repeated or reordered fragment drops the message in
  // progress, and the reassembler waits for the next fragment with index 0. Driver thread; no
  // allocation.
  [[nodiscard]] MarkerStreamStatus push(std::span<const std::uint8_t> report) noexcept;

  // The completed message's bytes (valid after push() returned kFrame, until the next push/reset).
  [[nodiscard]] std::span<const std::uint8_t> frame() const noexcept { return {buffer_.data(), frame_size_}; }
  // Fragment tag of the completed message (a frame's counter or a descriptor's table_id, low 16 bits).
  [[nodiscard]] std::uint16_t frameTag() const noexcept { return tag_; }

  // Drops any partial frame (e.g. after a reconnect). Counters are kept.
  void reset() noexcept;
  [[nodiscard]] const MarkerStreamReassemblerStats& stats() const noexcept { return stats_; }

 private:
  void dropPartial() noexcept;

  std::array<std::uint8_t, kMarkerStreamMaxFragments * kMarkerStreamFragmentPayload> buffer_{};
  std::size_t filled_ = 0;
  std::size_t frame_size_ = 0;
  std::uint16_t tag_ = 0;
  std::uint8_t count_ = 0;
  std::uint8_t next_index_ = 0;
  bool active_ = false;
  MarkerStreamReassemblerStats stats_;
};

// ---------------------------------------------------------------------------------------------
// Stateful decoder: validation + sequence tracking + marker sanitising.

struct MarkerStreamDecoderOptions {
  // Coordinates with |value| above this (mm) are absurd: the marker is invalidated and counted.
  float max_abs_coordinate_mm = kMarkerStreamDefaultMaxAbsCoordinateMm;
  // After this many consecutive out-of-order frames the decoder assumes the device restarted
  // without setting the stream-start flag and resynchronises on the next frame.
  std::uint32_t resync_after_out_of_order = 8;
};

struct MarkerStreamStats {
  std::uint64_t frames_decoded = 0;    // frames written to the caller
  std::uint64_t frames_lost = 0;       // sum of counter gaps (frames the device sent that never arrived)
  std::uint64_t gap_events = 0;        // frames decoded with kFrameSequenceGap
  std::uint64_t duplicates = 0;        // frames dropped as kDuplicate
  std::uint64_t out_of_order = 0;      // frames dropped as kOutOfOrder
  std::uint64_t resyncs = 0;           // stream restarts (stream-start flag after the first frame, or forced)
  std::uint64_t crc_errors = 0;        // kBadCrc
  std::uint64_t format_errors = 0;     // kTruncated, kBadMagic, kBadHeader, kBadLength
  std::uint64_t version_errors = 0;    // kUnsupportedVersion
  std::uint64_t fragment_errors = 0;   // kBadReport, kBadFragment, kFragmentLost from HID reports
  std::uint64_t rejected_markers = 0;  // markers invalidated for non-finite/absurd values
  std::uint64_t descriptors_accepted = 0;  // descriptors returned as kDescriptor
  std::uint64_t descriptors_rejected = 0;  // messages with the descriptor magic that were rejected
                                           // (also counted in crc/format/version_errors when that
                                           // was the reason; kBadDescriptor only here)
};

class MarkerStreamDecoder {
 public:
  explicit MarkerStreamDecoder(const MarkerStreamDecoderOptions& options = {}) noexcept : options_(options) {}

  // Decodes one whole message: a frame or a descriptor (a USB bulk transfer, or a message cut
  // from a recording). A descriptor ("TMSD") that passes every check replaces labels() and
  // returns kDescriptor; a rejected one leaves labels() as they were. Neither touches `out`
  // or the sequence state (docs/protocol.md 4.4).
  // On kFrame `out` holds the frame: frame_counter is the device counter extended to 64 bits
  // (kept monotonic across device restarts), device_timestamp_ns from the frame,
  // receive_timestamp_ns = `receive_ns`, markers in wire order with ids, positions in mm;
  // invalid or rejected markers have valid = 0, position 0 and identity orientation; quaternions
  // are normalised. Flags: kFrameSequenceGap (frames lost before this one, or a forced resync),
  // kFrameRejectedMarkers (+ rejected_count), kFrameTruncatedMarkers (device overflow flag).
  // On any other status `out` is not modified. Driver thread; no allocation.
  [[nodiscard]] MarkerStreamStatus decodeFrame(std::span<const std::uint8_t> bytes, std::int64_t receive_ns,
                                               MarkerFrame& out) noexcept;

  // Feeds one 64-byte HID input report (see MarkerStreamReassembler::push). Returns kNeedMore
  // while a message is incomplete, then what decodeFrame returns for the reassembled message
  // (also kBadFragment when its frame_counter / table_id does not match the fragment tag).
  // Driver thread; no allocation.
  [[nodiscard]] MarkerStreamStatus decodeHidReport(std::span<const std::uint8_t> report, std::int64_t receive_ns,
                                                   MarkerFrame& out) noexcept;

  // Forgets the sequence state and any partial frame (next frame is accepted as a new stream).
  // The label table is kept (a reconnected device re-sends its descriptor; see clearLabels()).
  void reset() noexcept;
  // Empties the label table (count 0; generation and table_id are kept). Driver thread.
  void clearLabels() noexcept { labels_.count = 0; }

  // The current label table (empty, generation 0, until a descriptor is accepted). Valid until
  // the next decode call; read it on the decoder's thread (copy it to hand it to another thread).
  [[nodiscard]] const MarkerLabelTable& labels() const noexcept { return labels_; }
  [[nodiscard]] const MarkerStreamStats& stats() const noexcept { return stats_; }
  [[nodiscard]] const MarkerStreamReassembler& reassembler() const noexcept { return reassembler_; }

 private:
  MarkerStreamDecoderOptions options_;
  MarkerStreamStats stats_;
  MarkerStreamReassembler reassembler_;
  MarkerLabelTable labels_;
  bool have_last_ = false;
  std::uint32_t last_counter_ = 0;   // device counter of the last accepted frame
  std::uint64_t last_extended_ = 0;  // its 64-bit extension
  std::uint32_t consecutive_out_of_order_ = 0;
};

// ---------------------------------------------------------------------------------------------
// Encoder (mock devices, tests, firmware reference). Writes what it is given, unchecked values
// included (NaN positions are encoded as NaN), so tests can produce hostile frames.

struct MarkerStreamEncodeOptions {
  MarkerRecordFormat record_format = MarkerRecordFormat::kPosition;
  std::uint16_t frame_flags = 0;  // kStreamFlag*
};

// Encodes `frame` (frame_counter low 32 bits, device_timestamp_ns, markers[0 .. marker_count):
// id, valid -> kMarkerFlagValid, has_orientation -> kMarkerFlagHasOrientation in kPose) into
// `out`. Returns the frame length, or 0 when `out` is smaller than
// markerStreamFrameSize(marker_count, format) or marker_count > kMarkerStreamMaxMarkers.
// Any thread; no allocation.
[[nodiscard]] std::size_t encodeMarkerStreamFrame(const MarkerFrame& frame, const MarkerStreamEncodeOptions& options,
                                                  std::span<std::uint8_t> out) noexcept;

// Number of 64-byte HID reports a message of `frame_length` bytes needs (0 for 0 or more than
// kMarkerStreamMaxMessageSize).
[[nodiscard]] constexpr std::size_t markerStreamFragmentCount(std::size_t frame_length) noexcept {
  if (frame_length == 0 || frame_length > kMarkerStreamMaxMessageSize) return 0;
  return (frame_length + kMarkerStreamFragmentPayload - 1) / kMarkerStreamFragmentPayload;
}

// Writes HID report `index` (0-based) of the encoded message `frame_bytes` (a frame or a
// descriptor) into `report` (kMarkerStreamHidReportSize bytes: report id 0x01, fragment header,
// payload, zero padding). The tag is the low 16 bits of the u32 at message offset 12 (a frame's
// frame_counter, a descriptor's table_id). Returns 64, or 0 when `frame_bytes` is shorter than
// 16 bytes or longer than kMarkerStreamMaxMessageSize, index is out of range, or `report` is too
// small. Any thread; no allocation.
[[nodiscard]] std::size_t encodeMarkerStreamFragment(std::span<const std::uint8_t> frame_bytes, std::size_t index,
                                                     std::span<std::uint8_t> report) noexcept;

// ---------------------------------------------------------------------------------------------
// Commands and device info (docs/protocol.md, section "Control").

enum class MarkerStreamCommand : std::uint8_t {
  kStart = 0x01,    // begin streaming; param: record format wanted (0 position, 1 pose)
  kStop = 0x02,     // stop streaming; param 0
  kSetRate = 0x03,  // param: frame rate in Hz (1..65535); the device picks the nearest it supports
  kGetInfo = 0x04,  // USB only (vendor IN request); over HID read feature report 0x03 instead
  kGetDescriptor = 0x05,  // param 0: the device sends its descriptor (on the data path, between frames)
};

// Writes the 64-byte HID output report for `command` into `report` (byte 0 = 0x02, byte 1 =
// opcode, bytes 2-3 = param u16 LE, rest 0). Returns 64, or 0 if `report` is too small.
[[nodiscard]] std::size_t encodeMarkerStreamCommandReport(MarkerStreamCommand command, std::uint16_t param,
                                                          std::span<std::uint8_t> report) noexcept;
// Parses such a report (mock devices). Returns false for a short report, wrong report id or
// unknown opcode. Any thread; no allocation.
[[nodiscard]] bool decodeMarkerStreamCommandReport(std::span<const std::uint8_t> report, MarkerStreamCommand& command,
                                                   std::uint16_t& param) noexcept;

// A USB control transfer setup (values for libusb_control_transfer / libusb_fill_control_setup).
struct UsbControlSetup {
  std::uint8_t request_type = 0;  // bmRequestType
  std::uint8_t request = 0;       // bRequest
  std::uint16_t value = 0;        // wValue
  std::uint16_t index = 0;        // wIndex
  std::uint16_t length = 0;       // wLength
};
// The vendor control request carrying `command` to interface `interface_number`:
// kStart/kStop/kSetRate/kGetDescriptor: bmRequestType 0x41 (host-to-device | vendor |
// interface), wValue = param, wLength 0;
// kGetInfo: bmRequestType 0xC1 (device-to-host | vendor | interface), wLength 16.
[[nodiscard]] UsbControlSetup markerStreamControlSetup(MarkerStreamCommand command, std::uint16_t param,
                                                       std::uint16_t interface_number) noexcept;

inline constexpr std::size_t kMarkerStreamInfoSize = 16;
struct MarkerStreamDeviceInfo {
  std::uint8_t version_major = kMarkerStreamVersionMajor;
  std::uint8_t version_minor = kMarkerStreamVersionMinor;
  std::uint8_t streaming = 0;  // 1 while streaming
  MarkerRecordFormat record_format = MarkerRecordFormat::kPosition;
  std::uint16_t max_markers = 0;
  std::uint16_t rate_hz = 0;      // current frame rate
  std::uint16_t min_rate_hz = 0;
  std::uint16_t max_rate_hz = 0;
};
// Info block (16 bytes, docs/protocol.md). Returns bytes written (16) or 0 if `out` is too small.
[[nodiscard]] std::size_t encodeMarkerStreamInfo(const MarkerStreamDeviceInfo& info, std::span<std::uint8_t> out) noexcept;
// Parses an info block. Returns false if shorter than 16 bytes or record_format is unknown.
[[nodiscard]] bool decodeMarkerStreamInfo(std::span<const std::uint8_t> bytes, MarkerStreamDeviceInfo& info) noexcept;

}  // namespace tetrig::drivers
