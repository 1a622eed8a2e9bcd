// Raw device stream recordings: a recorder that writes byte buffers exactly as a transport
// received them (with the host receive time and a channel/endpoint id) and a replay source that
// yields them back bit-exactly with their original relative timing.
//
// File format "TETRIGRW" version 1 (all integers little-endian; full description in
// docs/recording.md):
//   header:  magic "TETRIGRW" (8) | u16 version = 1 | u16 header_size | u16 vendor_id |
//            u16 product_id | i64 created_unix_ns | u16 description_length |
//            description (UTF-8, no terminator) | u32 CRC-32 of every preceding header byte
//   records: u32 sync "REC1" | i64 receive_ns | u32 channel | u32 length | payload (length bytes) |
//            u32 CRC-32 of every preceding byte of the record
// CRC-32 is the IEEE 802.3 / zlib one (reflected polynomial 0xEDB88320, init and final xor
// 0xFFFFFFFF; check value of "123456789" is 0xCBF43926).
//
// Threads: a RawRecorder does buffered file I/O and may allocate; use it on a recording thread
// (or a driver thread that is allowed to block on the disk), never on the solver thread. Loading
// a RawRecording allocates and may throw; afterwards its accessors are const, noexcept,
// allocation-free and usable from any thread. RawReplay::run() runs on the caller's thread.
#pragma once

#include <atomic>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "tetrig/atomic_file.hpp"
#include "tetrig/drivers/pacing.hpp"

namespace tetrig::drivers {

inline constexpr char kRawRecordingMagic[8] = {'T', 'E', 'T', 'R', 'I', 'G', 'R', 'W'};
inline constexpr std::uint16_t kRawRecordingVersion = 1;
inline constexpr std::size_t kRawRecordingMaxDescription = 4096;       // bytes
inline constexpr std::size_t kRawRecordingMaxPayload = 16u * 1024u * 1024u;  // bytes per record

// Any failure to write or read a recording; what() names the file, the byte offset and what was
// expected.
class RawRecordingError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// CRC-32 (IEEE 802.3 / zlib). `crc` is the running value from a previous call (0 to start).
// Pure; no allocation; any thread.
std::uint32_t recordingCrc32(std::span<const std::uint8_t> bytes, std::uint32_t crc = 0) noexcept;

struct RawRecordingHeader {
  std::uint16_t vendor_id = 0;    // USB VID of the recorded device (0 if none)
  std::uint16_t product_id = 0;   // USB PID
  std::int64_t created_unix_ns = 0;  // wall-clock creation time (informative; 0 = unknown)
  std::string description;        // free text, e.g. "Razer Hydra, HID interface 0, motion mode"
  std::uint16_t version = kRawRecordingVersion;  // as read (writers always write the current one)
};

// One record: a view into the recording's (or the caller's) storage.
struct RawRecordView {
  std::int64_t receive_ns = 0;  // host CLOCK_MONOTONIC when the buffer arrived
  std::uint32_t channel = 0;    // endpoint address / HID report stream / application-defined
  std::span<const std::uint8_t> bytes;
};

// Writes a recording under a temporary name beside `path` (tetrig::AtomicFile: a fresh
// ".<name>.tmp-XXXXXX", never an existing file or a planted link) and renames it over `path` at
// close(): an existing recording at `path` stays whole until the new one is complete, and
// readers never see a half-written file there. The file gets 0666 minus the umask, or the mode
// of the file it replaces. A write error abandons the recording (the temporary is removed,
// `path` is untouched). A process killed while recording leaves its data in the temporary (a
// valid prefix plus at most one partial record: RawRecording::load with tolerate_truncated_tail).
class RawRecorder {
 public:
  // Creates the temporary and writes the header. Throws RawRecordingError when the file
  // cannot be created or the description is longer than kRawRecordingMaxDescription.
  RawRecorder(const std::filesystem::path& path, const RawRecordingHeader& header);
  RawRecorder(const RawRecorder&) = delete;
  RawRecorder& operator=(const RawRecorder&) = delete;
  // Finishes like close() (errors at this point are swallowed, and then `path` is untouched:
  // call close() to see them).
  ~RawRecorder();

  // Appends one record (buffered). Throws RawRecordingError on a write error (the recording is
  // then abandoned), on a payload larger than kRawRecordingMaxPayload, or after close().
  void write(std::uint32_t channel, std::int64_t receive_ns, std::span<const std::uint8_t> bytes);
  // Pushes buffered records to the operating system (into the temporary). Throws on error.
  void flush();
  // Flushes, syncs and renames the recording to `path`; throws RawRecordingError on error (the
  // temporary is removed, `path` untouched). Idempotent.
  void close();

  [[nodiscard]] std::uint64_t recordCount() const noexcept { return records_; }
  [[nodiscard]] std::uint64_t bytesWritten() const noexcept { return bytes_; }
  // Where the data goes until close() (empty after close() or after a failure).
  [[nodiscard]] std::filesystem::path temporaryPath() const;

 private:
  void put(const void* data, std::size_t size);
  [[noreturn]] void abandon(const std::string& what);
  std::string path_;
  std::unique_ptr<AtomicFile> file_;
  std::FILE* stream_ = nullptr;  // file_'s stream
  std::uint64_t records_ = 0;
  std::uint64_t bytes_ = 0;
};

// A whole recording held in memory.
class RawRecording {
 public:
  // Reads and verifies every CRC. A file whose last record is cut short (a recorder that died)
  // throws unless `tolerate_truncated_tail`, in which case the partial record is dropped and
  // truncatedTail() says so. Any other damage (bad magic, unknown version, CRC mismatch, bad
  // sync) throws RawRecordingError with the byte offset. Allocates.
  static RawRecording load(const std::filesystem::path& path, bool tolerate_truncated_tail = false);
  static RawRecording parse(std::span<const std::uint8_t> bytes, std::string_view source_name,
                            bool tolerate_truncated_tail = false);

  [[nodiscard]] const RawRecordingHeader& header() const noexcept { return header_; }
  [[nodiscard]] std::size_t size() const noexcept { return records_.size(); }
  // Precondition: index < size(). The view points into this object.
  [[nodiscard]] RawRecordView record(std::size_t index) const noexcept {
    const Entry& e = records_[index];
    return {e.receive_ns, e.channel, std::span<const std::uint8_t>(bytes_.data() + e.offset, e.length)};
  }
  [[nodiscard]] bool truncatedTail() const noexcept { return truncated_tail_; }
  [[nodiscard]] const std::string& sourceName() const noexcept { return source_name_; }

 private:
  struct Entry {
    std::int64_t receive_ns;
    std::uint32_t channel;
    std::size_t offset;
    std::size_t length;
  };
  std::string source_name_;
  RawRecordingHeader header_;
  std::vector<std::uint8_t> bytes_;
  std::vector<Entry> records_;
  bool truncated_tail_ = false;
};

struct RawReplayOptions {
  Pacing pacing = Pacing::kRealTime;
  double speed = 1.0;  // real-time only
  bool loop = false;   // after the last record, start again one mean record gap later
};

// Replays a RawRecording: record i is released at start + (receive_ns[i] - receive_ns[0]) /
// speed (timestamps that go backwards are clamped to the previous release time), the sink gets
// the record exactly as stored (its original receive_ns; bytes identical). Sink: callable
// (const RawRecordView&) returning void or bool (false = stop).
class RawReplay {
 public:
  // The recording must outlive the replay. Throws std::invalid_argument when speed <= 0.
  RawReplay(const RawRecording& recording, RawReplayOptions options);

  // Runs on the calling thread; no allocation. Same contract as C3DPlayback::run().
  template <class Sink, class Clock = SteadyPacingClock>
  PacedRunStats run(Sink&& sink, const std::atomic<bool>* stop = nullptr, Clock clock = Clock{}) const;

  // Offset of record `index` from the start of one pass, in ns of recording time (clamped to be
  // non-decreasing). Precondition: index < recording size.
  [[nodiscard]] std::int64_t relativeTimeNs(std::size_t index) const noexcept { return offsets_[index]; }
  // Recording time of one pass when looping (last offset + mean gap).
  [[nodiscard]] std::int64_t loopPeriodNs() const noexcept { return loop_period_ns_; }

 private:
  const RawRecording* recording_;
  RawReplayOptions options_;
  std::vector<std::int64_t> offsets_;
  std::int64_t loop_period_ns_ = 0;
};

template <class Sink, class Clock>
PacedRunStats RawReplay::run(Sink&& sink, const std::atomic<bool>* stop, Clock clock) const {
  PacedRunStats stats;
  const std::size_t n = recording_->size();
  if (n == 0) return stats;
  const bool real_time = options_.pacing == Pacing::kRealTime;
  const std::int64_t start = clock.nowNs();
  std::uint64_t pass = 0;
  double previous_target = 0.0;
  while (true) {
    for (std::size_t i = 0; i < n; ++i) {
      if (detail::stopRequested(stop)) {
        stats.stopped = true;
        return stats;
      }
      if (real_time) {
        const double rel = (static_cast<double>(pass) * static_cast<double>(loop_period_ns_) +
                            static_cast<double>(offsets_[i])) / options_.speed;
        const std::int64_t target = start + detail::clampedNs(rel);
        const std::int64_t now = clock.nowNs();
        if (now < target) {
          clock.sleepUntilNs(target);
        } else if (i > 0 && static_cast<double>(now - target) > (rel - previous_target) + 1e6) {
          ++stats.late_items;  // later than one record gap plus 1 ms
        }
        previous_target = rel;
      }
      ++stats.items;
      if (!detail::callSink(sink, recording_->record(i))) {
        stats.stopped = true;
        return stats;
      }
    }
    ++stats.loops;
    ++pass;
    if (!options_.loop) return stats;
  }
}

}  // namespace tetrig::drivers
