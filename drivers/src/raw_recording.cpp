// Raw device stream recordings ("TETRIGRW" v1, docs/recording.md): writer (through
// tetrig::AtomicFile: a temporary renamed over the target at close), reader, CRC-32 (IEEE 802.3
// polynomial, the table-driven reflected algorithm) and the replay's time table.
#include "tetrig/drivers/raw_recording.hpp"

#include <algorithm>
#include <array>
#include <cerrno>
#include <cstring>
#include <fstream>
#include <limits>
#include <stdexcept>

namespace tetrig::drivers {

namespace {

constexpr std::array<std::uint32_t, 256> makeCrcTable() {
  std::array<std::uint32_t, 256> t{};
  for (std::uint32_t i = 0; i < 256; ++i) {
    std::uint32_t c = i;
    for (int k = 0; k < 8; ++k) c = (c & 1u) != 0 ? 0xEDB88320u ^ (c >> 1) : c >> 1;
    t[i] = c;
  }
  return t;
}
constexpr std::array<std::uint32_t, 256> kCrcTable = makeCrcTable();

constexpr std::uint8_t kRecordSync[4] = {'R', 'E', 'C', '1'};
constexpr std::size_t kFixedHeader = 26;  // bytes before the description
constexpr std::size_t kRecordHead = 20;   // sync, receive_ns, channel, length

void putLe(std::uint8_t* p, std::uint64_t v, int bytes) {
  for (int i = 0; i < bytes; ++i) p[i] = static_cast<std::uint8_t>((v >> (8 * i)) & 0xffu);
}
std::uint64_t getLe(const std::uint8_t* p, int bytes) {
  std::uint64_t v = 0;
  for (int i = 0; i < bytes; ++i) v |= static_cast<std::uint64_t>(p[i]) << (8 * i);
  return v;
}

}  // namespace

std::uint32_t recordingCrc32(std::span<const std::uint8_t> bytes, std::uint32_t crc) noexcept {
  std::uint32_t c = ~crc;
  for (const std::uint8_t b : bytes) c = kCrcTable[(c ^ b) & 0xffu] ^ (c >> 8);
  return ~c;
}

// ---- recorder ----

RawRecorder::RawRecorder(const std::filesystem::path& path, const RawRecordingHeader& header) : path_(path.string()) {
  if (header.description.size() > kRawRecordingMaxDescription) {
    throw RawRecordingError(path_ + ": description is " + std::to_string(header.description.size()) +
                            " bytes, the format allows " + std::to_string(kRawRecordingMaxDescription));
  }
  try {
    file_ = std::make_unique<AtomicFile>(path);
    stream_ = file_->stream();
  } catch (const AtomicFileError& e) {
    file_.reset();
    throw RawRecordingError(std::string("cannot create the recording: ") + e.what());
  }
  std::setvbuf(stream_, nullptr, _IOFBF, 1u << 20);
  std::vector<std::uint8_t> h(kFixedHeader + header.description.size() + 4);
  std::memcpy(h.data(), kRawRecordingMagic, 8);
  putLe(&h[8], kRawRecordingVersion, 2);
  putLe(&h[10], h.size(), 2);
  putLe(&h[12], header.vendor_id, 2);
  putLe(&h[14], header.product_id, 2);
  putLe(&h[16], static_cast<std::uint64_t>(header.created_unix_ns), 8);
  putLe(&h[24], header.description.size(), 2);
  std::memcpy(&h[kFixedHeader], header.description.data(), header.description.size());
  const std::uint32_t crc = recordingCrc32(std::span<const std::uint8_t>(h.data(), h.size() - 4));
  putLe(&h[h.size() - 4], crc, 4);
  put(h.data(), h.size());
}

RawRecorder::~RawRecorder() {
  try {
    close();
  } catch (...) {  // close() removed the temporary; the target is untouched
  }
}

std::filesystem::path RawRecorder::temporaryPath() const { return file_ != nullptr ? file_->temporaryPath() : std::filesystem::path(); }

void RawRecorder::abandon(const std::string& what) {
  file_.reset();  // removes the temporary
  stream_ = nullptr;
  throw RawRecordingError(path_ + ": " + what + "; the recording is abandoned (" + path_ + " is untouched)");
}

void RawRecorder::put(const void* data, std::size_t size) {
  if (size != 0 && std::fwrite(data, 1, size, stream_) != size) {
    abandon("write failed at byte " + std::to_string(bytes_) + ": " + std::strerror(errno));
  }
  bytes_ += size;
}

void RawRecorder::write(std::uint32_t channel, std::int64_t receive_ns, std::span<const std::uint8_t> bytes) {
  if (file_ == nullptr) throw RawRecordingError(path_ + ": write after close");
  if (bytes.size() > kRawRecordingMaxPayload) {
    throw RawRecordingError(path_ + ": record of " + std::to_string(bytes.size()) + " bytes exceeds the format's " +
                            std::to_string(kRawRecordingMaxPayload) + "-byte limit");
  }
  std::uint8_t head[kRecordHead];
  std::memcpy(head, kRecordSync, 4);
  putLe(&head[4], static_cast<std::uint64_t>(receive_ns), 8);
  putLe(&head[12], channel, 4);
  putLe(&head[16], bytes.size(), 4);
  std::uint32_t crc = recordingCrc32(head);
  crc = recordingCrc32(bytes, crc);
  std::uint8_t tail[4];
  putLe(tail, crc, 4);
  put(head, sizeof(head));
  put(bytes.data(), bytes.size());
  put(tail, sizeof(tail));
  ++records_;
}

void RawRecorder::flush() {
  if (file_ != nullptr && std::fflush(stream_) != 0) abandon(std::string("flush failed: ") + std::strerror(errno));
}

void RawRecorder::close() {
  if (file_ == nullptr) return;
  std::unique_ptr<AtomicFile> file = std::move(file_);
  stream_ = nullptr;
  try {
    file->commit();  // flushes the stream, fsync, rename over the target; removes the temporary on failure
  } catch (const AtomicFileError& e) {
    throw RawRecordingError(std::string("closing the recording failed: ") + e.what());
  }
}

// ---- reader ----

RawRecording RawRecording::load(const std::filesystem::path& path, bool tolerate_truncated_tail) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw RawRecordingError(path.string() + ": cannot open the recording");
  std::vector<std::uint8_t> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  return parse(bytes, path.string(), tolerate_truncated_tail);
}

RawRecording RawRecording::parse(std::span<const std::uint8_t> bytes, std::string_view source_name,
                                 bool tolerate_truncated_tail) {
  RawRecording r;
  r.source_name_ = source_name;
  const std::string& name = r.source_name_;
  auto fail = [&](std::size_t offset, const std::string& what) -> void {
    throw RawRecordingError(name + ": " + what + " (at byte " + std::to_string(offset) + ")");
  };
  const std::size_t n = bytes.size();
  if (n < kFixedHeader) {
    fail(n, "truncated header: expected at least " + std::to_string(kFixedHeader) + " bytes, file has " +
                std::to_string(n));
  }
  if (std::memcmp(bytes.data(), kRawRecordingMagic, 8) != 0) fail(0, "not a tetrig raw recording (magic is not TETRIGRW)");
  const auto version = static_cast<std::uint16_t>(getLe(&bytes[8], 2));
  if (version != kRawRecordingVersion) {
    fail(8, "unsupported recording version " + std::to_string(version) + " (this reader knows version 1)");
  }
  const std::size_t header_size = getLe(&bytes[10], 2);
  const std::size_t desc = getLe(&bytes[24], 2);
  if (header_size != kFixedHeader + desc + 4) {
    fail(10, "inconsistent header: header_size " + std::to_string(header_size) + " but description length " +
                 std::to_string(desc) + " needs " + std::to_string(kFixedHeader + desc + 4));
  }
  if (n < header_size) {
    fail(n, "truncated header: expected " + std::to_string(header_size) + " bytes, file has " + std::to_string(n));
  }
  const std::uint32_t stored = static_cast<std::uint32_t>(getLe(&bytes[header_size - 4], 4));
  if (recordingCrc32(bytes.subspan(0, header_size - 4)) != stored) fail(header_size - 4, "header CRC mismatch");
  r.header_.version = version;
  r.header_.vendor_id = static_cast<std::uint16_t>(getLe(&bytes[12], 2));
  r.header_.product_id = static_cast<std::uint16_t>(getLe(&bytes[14], 2));
  r.header_.created_unix_ns = static_cast<std::int64_t>(getLe(&bytes[16], 8));
  r.header_.description.assign(reinterpret_cast<const char*>(&bytes[kFixedHeader]), desc);

  r.bytes_.assign(bytes.begin(), bytes.end());
  std::size_t p = header_size;
  while (p < n) {
    if (n - p < kRecordHead) {
      if (tolerate_truncated_tail) {
        r.truncated_tail_ = true;
        break;
      }
      fail(p, "truncated record " + std::to_string(r.records_.size()) + ": expected a " +
                  std::to_string(kRecordHead) + "-byte record header, file ends at byte " + std::to_string(n));
    }
    if (std::memcmp(&bytes[p], kRecordSync, 4) != 0) {
      fail(p, "record " + std::to_string(r.records_.size()) + " does not start with the sync word REC1");
    }
    const std::size_t len = getLe(&bytes[p + 16], 4);
    if (len > kRawRecordingMaxPayload) {
      fail(p + 16, "record " + std::to_string(r.records_.size()) + " claims " + std::to_string(len) +
                       " bytes, more than the format's limit");
    }
    if (n - p < kRecordHead + len + 4) {
      if (tolerate_truncated_tail) {
        r.truncated_tail_ = true;
        break;
      }
      fail(p, "truncated record " + std::to_string(r.records_.size()) + ": expected " +
                  std::to_string(kRecordHead + len + 4) + " bytes, file ends at byte " + std::to_string(n));
    }
    const std::uint32_t crc = static_cast<std::uint32_t>(getLe(&bytes[p + kRecordHead + len], 4));
    if (recordingCrc32(bytes.subspan(p, kRecordHead + len)) != crc) {
      fail(p, "CRC mismatch in record " + std::to_string(r.records_.size()));
    }
    r.records_.push_back({static_cast<std::int64_t>(getLe(&bytes[p + 4], 8)),
                          static_cast<std::uint32_t>(getLe(&bytes[p + 12], 4)), p + kRecordHead, len});
    p += kRecordHead + len + 4;
  }
  return r;
}

// ---- replay ----

RawReplay::RawReplay(const RawRecording& recording, RawReplayOptions options)
    : recording_(&recording), options_(options) {
  if (!(options_.speed > 0.0) || !std::isfinite(options_.speed)) {
    throw std::invalid_argument("raw replay: speed must be a positive number");
  }
  const std::size_t n = recording.size();
  offsets_.resize(n);
  if (n == 0) return;
  const std::int64_t t0 = recording.record(0).receive_ns;
  std::int64_t previous = 0;
  for (std::size_t i = 0; i < n; ++i) {
    // Difference computed in unsigned arithmetic so hostile timestamps cannot overflow.
    const auto diff = static_cast<std::int64_t>(static_cast<std::uint64_t>(recording.record(i).receive_ns) -
                                                static_cast<std::uint64_t>(t0));
    previous = std::max(previous, diff);
    offsets_[i] = previous;
  }
  const std::int64_t last = offsets_[n - 1];
  constexpr std::int64_t kHalf = std::numeric_limits<std::int64_t>::max() / 2;  // no overflow below
  loop_period_ns_ = n < 2 ? 0 : (last > kHalf ? kHalf : last + last / static_cast<std::int64_t>(n - 1));
}

}  // namespace tetrig::drivers
