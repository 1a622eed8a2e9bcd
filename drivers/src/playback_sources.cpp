// Playback sources in the one MarkerSource shape (DESIGN.md 6a, "one source shape"): a C3D clip,
// the synthetic source and raw-recording replay, each run by its pacing loop on a driver thread
// that publishes into the frame mailbox, with a pacing clock whose sleep a stop request cuts
// short (condition variable). Replay picks the decoder from the recording (docs/recording.md,
// docs/protocol.md) and estimates the rate from the median frame interval.
#include "tetrig/drivers/playback_sources.hpp"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdint>
#include <cstdio>
#include <exception>
#include <limits>
#include <mutex>
#include <span>
#include <stdexcept>
#include <system_error>
#include <thread>
#include <utility>

#include "tetrig/clock.hpp"
#include "tetrig/drivers/hydra.hpp"
#include "tetrig/drivers/marker_stream.hpp"
#include "tetrig/drivers/raw_recording.hpp"

namespace tetrig::drivers {

namespace {

constexpr auto kRelaxed = std::memory_order_relaxed;
constexpr std::int64_t kSleepSliceNs = 10'000'000;  // longest single wait of a paced sleep
constexpr int kLockstepSliceUs = 50;  // as-fast-as-possible: poll of the mailbox while the solver has not taken a frame
constexpr std::size_t kRateFrames = 64;             // frames whose intervals give a replay's rate

// prefix + decimal number (built by appending: GCC 12 warns falsely about "literal" + to_string).
std::string numbered(const char* prefix, std::size_t n) {
  std::string s = prefix;
  s += std::to_string(n);
  return s;
}

std::string formatHz(double hz) {
  char buffer[32];
  std::snprintf(buffer, sizeof(buffer), "%.6g Hz", hz);
  return buffer;
}

// The rate frames arrive at: a paced playback at `speed` delivers `rate` x speed frames a second.
double arrivalRate(double rate, Pacing pacing, double speed) { return pacing == Pacing::kRealTime ? rate * speed : rate; }

std::string pacingText(Pacing pacing, double speed) {
  if (pacing == Pacing::kAsFastAsPossible) return ", as fast as possible";
  if (pacing == Pacing::kLockstep) return ", as fast as the solver takes frames";
  if (speed != 1.0) {
    char buffer[40];
    std::snprintf(buffer, sizeof(buffer), ", speed x%g", speed);
    return buffer;
  }
  return "";
}

// The stop flag of one source and the condition variable its pacing sleeps on.
class StopSignal {
 public:
  // Control thread, before the driver thread starts.
  void reset() {
    const std::lock_guard<std::mutex> lock(mutex_);
    stop_.store(false, std::memory_order_release);
  }
  // Control thread: wakes a sleeping driver thread at once.
  void request() {
    {
      const std::lock_guard<std::mutex> lock(mutex_);
      stop_.store(true, std::memory_order_release);
    }
    cv_.notify_all();
  }
  [[nodiscard]] bool requested() const noexcept { return stop_.load(std::memory_order_acquire); }
  // Driver thread: waits, without spinning, while `busy()` holds, until stop is requested.
  template <class Busy>
  void waitWhile(Busy busy) {
    std::unique_lock<std::mutex> lock(mutex_);
    while (!stop_.load(kRelaxed) && busy()) cv_.wait_for(lock, std::chrono::microseconds(kLockstepSliceUs));
  }
  [[nodiscard]] const std::atomic<bool>* flag() const noexcept { return &stop_; }

  // Driver thread: returns at `target_ns` (monotonicNowNs clock) or as soon as stop is requested.
  // Waits in slices of at most kSleepSliceNs, so even a lost wake-up costs at most one slice.
  void sleepUntilNs(std::int64_t target_ns) {
    std::unique_lock<std::mutex> lock(mutex_);
    while (!stop_.load(kRelaxed)) {
      const std::int64_t now = monotonicNowNs();
      if (now >= target_ns) return;
      const std::int64_t until = std::min(target_ns, now + kSleepSliceNs);
      cv_.wait_until(lock, std::chrono::steady_clock::time_point(std::chrono::nanoseconds(until)));
    }
  }

 private:
  std::mutex mutex_;
  std::condition_variable cv_;
  std::atomic<bool> stop_{false};
};

// The pacing clock of every playback source (pacing.hpp's Clock shape): the runtime's monotonic
// clock (CLOCK_MONOTONIC, the same as steady_clock on Linux), sleeping on the stop signal.
struct InterruptiblePacingClock {
  StopSignal* signal;
  [[nodiscard]] std::int64_t nowNs() const noexcept { return monotonicNowNs(); }
  void sleepUntilNs(std::int64_t target_ns) const { signal->sleepUntilNs(target_ns); }
};

struct SourceCounters {
  std::atomic<std::uint64_t> frames_published{0};
  std::atomic<std::uint64_t> frames_lost{0};
  std::atomic<std::uint64_t> decode_errors{0};
  std::atomic<std::uint64_t> late_frames{0};
  std::atomic<std::uint64_t> rejected_markers{0};
};

// The driver thread's side of the mailbox: stamps, commits and counts frames. As a sink
// (operator()) it copies a playback's frame into the producer slot; slot()/commit() are the
// zero-copy form for decoders. Driver thread only; no allocation, no exception.
// In lockstep (Pacing::kLockstep) commit() first waits until the solver (every solver of a
// fan-out chain, FrameMailbox::forwardTo) has taken the previous frame: no frame is dropped, and the driver thread sleeps instead of spinning a core
// against the solver and the segment's readers.
class Publisher {
 public:
  Publisher(FrameMailbox& mailbox, StopSignal& signal, SourceCounters& counters, bool lockstep) noexcept
      : mailbox_(mailbox), signal_(signal), counters_(counters), lockstep_(lockstep) {}

  // Sink for C3DPlayback::run / SyntheticSource::run: false (= stop the run) once stop was
  // requested, without publishing.
  bool operator()(const MarkerFrame& frame) noexcept {
    if (signal_.requested()) return false;
    mailbox_.producerSlot() = frame;
    commit();
    return true;
  }
  [[nodiscard]] MarkerFrame& slot() noexcept { return mailbox_.producerSlot(); }
  void commit() noexcept {
    if (lockstep_) signal_.waitWhile([this] { return mailbox_.pendingAlongChain(); });
    MarkerFrame& frame = mailbox_.producerSlot();
    frame.receive_timestamp_ns = monotonicNowNs();
    const std::uint16_t rejected = frame.rejected_count;
    mailbox_.commit();
    counters_.frames_published.fetch_add(1, kRelaxed);
    if (rejected != 0) counters_.rejected_markers.fetch_add(rejected, kRelaxed);
  }
  [[nodiscard]] bool stopRequested() const noexcept { return signal_.requested(); }
  [[nodiscard]] const std::atomic<bool>* stopFlag() const noexcept { return signal_.flag(); }
  SourceCounters& counters() noexcept { return counters_; }

 private:
  FrameMailbox& mailbox_;
  StopSignal& signal_;
  SourceCounters& counters_;
  bool lockstep_;
};

// What differs between the kinds: one playback from the beginning, on the driver thread.
class Producer {
 public:
  virtual ~Producer() = default;
  virtual PacedRunStats run(Publisher& out, const InterruptiblePacingClock& clock) = 0;
};

// One MarkerSource for every playback kind: the thread, the stop signal, the counters.
class PlaybackSource final : public MarkerSource {
 public:
  PlaybackSource(std::unique_ptr<Producer> producer, std::string description, double rate_hz, bool has_labels,
                 std::vector<std::string> labels, Pacing pacing)
      : producer_(std::move(producer)),
        description_(std::move(description)),
        rate_hz_(rate_hz),
        has_labels_(has_labels),
        labels_(std::move(labels)),
        lockstep_(pacing == Pacing::kLockstep) {}
  ~PlaybackSource() override { stop(); }
  PlaybackSource(const PlaybackSource&) = delete;
  PlaybackSource& operator=(const PlaybackSource&) = delete;

  [[nodiscard]] std::string describe() const override { return description_; }
  [[nodiscard]] double nominalRateHz() const override { return rate_hz_; }

  bool start(FrameMailbox& mailbox) override {
    if (running_.load(std::memory_order_acquire)) {
      setError(description_ + ": already running");
      return false;
    }
    if (thread_.joinable()) thread_.join();  // a playback that ended on its own
    signal_.reset();
    finished_.store(false, std::memory_order_release);
    setError("");
    running_.store(true, std::memory_order_release);
    try {
      thread_ = std::thread([this, &mailbox] { body(mailbox); });
    } catch (const std::system_error& e) {
      running_.store(false, std::memory_order_release);
      setError(description_ + ": cannot start the driver thread: " + e.what());
      return false;
    }
    return true;
  }

  bool waitForLabels(std::chrono::milliseconds /*timeout*/, std::vector<std::string>& labels) override {
    if (!has_labels_) return false;  // known at construction: waiting cannot change it
    labels = labels_;
    return true;
  }

  void stop() override {
    signal_.request();
    if (thread_.joinable()) thread_.join();
  }

  [[nodiscard]] bool finished() const noexcept override { return finished_.load(std::memory_order_acquire); }

  [[nodiscard]] MarkerSourceStats stats() const noexcept override {
    MarkerSourceStats s;
    s.frames_published = counters_.frames_published.load(kRelaxed);
    s.frames_lost = counters_.frames_lost.load(kRelaxed);
    s.decode_errors = counters_.decode_errors.load(kRelaxed);
    s.late_frames = counters_.late_frames.load(kRelaxed);
    s.rejected_markers = counters_.rejected_markers.load(kRelaxed);
    s.connected = running_.load(std::memory_order_acquire);
    return s;
  }

  [[nodiscard]] std::string lastError() const override {
    const std::lock_guard<std::mutex> lock(error_mutex_);
    return error_;
  }

 private:
  void body(FrameMailbox& mailbox) noexcept {
    Publisher publisher(mailbox, signal_, counters_, lockstep_);
    const InterruptiblePacingClock clock{&signal_};
    try {
      const PacedRunStats run = producer_->run(publisher, clock);
      counters_.late_frames.fetch_add(run.late_items, kRelaxed);
      if (!run.stopped) finished_.store(true, std::memory_order_release);
    } catch (const std::exception& e) {  // not expected: the pacing loops do not throw per frame
      setError(description_ + ": playback failed: " + e.what());
    }
    running_.store(false, std::memory_order_release);
  }

  void setError(std::string text) {
    const std::lock_guard<std::mutex> lock(error_mutex_);
    error_ = std::move(text);
  }

  std::unique_ptr<Producer> producer_;
  const std::string description_;
  const double rate_hz_;
  const bool has_labels_;
  const std::vector<std::string> labels_;
  const bool lockstep_;  // Pacing::kLockstep: the publisher waits for the solver (Publisher)
  StopSignal signal_;
  SourceCounters counters_;
  std::atomic<bool> running_{false};
  std::atomic<bool> finished_{false};
  mutable std::mutex error_mutex_;
  std::string error_;
  std::thread thread_;
};

// ---- C3D ----

class C3DProducer final : public Producer {
 public:
  C3DProducer(std::shared_ptr<const C3DClip> clip, C3DPlaybackOptions options)
      : clip_(std::move(clip)), playback_(*clip_, std::move(options)) {}
  [[nodiscard]] const C3DPlayback& playback() const noexcept { return playback_; }
  PacedRunStats run(Publisher& out, const InterruptiblePacingClock& clock) override {
    return playback_.run(out, out.stopFlag(), clock);
  }

 private:
  std::shared_ptr<const C3DClip> clip_;  // kept alive for playback_
  C3DPlayback playback_;
};

// ---- synthetic ----

class SyntheticProducer final : public Producer {
 public:
  explicit SyntheticProducer(SyntheticOptions options) : source_(std::move(options)) {}
  [[nodiscard]] const SyntheticSource& source() const noexcept { return source_; }
  PacedRunStats run(Publisher& out, const InterruptiblePacingClock& clock) override {
    return source_.run(out, out.stopFlag(), clock);
  }

 private:
  SyntheticSource source_;
};

// ---- replay ----

enum class ReplayKind : std::uint8_t { kHydra, kMarkerStream };

bool isMarkerStreamHidReport(std::span<const std::uint8_t> bytes) noexcept {
  return bytes.size() == kMarkerStreamHidReportSize && bytes[0] == kMarkerStreamHidInputReportId;
}
// A whole marker-stream message: a frame ("TMSF") or a descriptor ("TMSD").
bool hasMarkerStreamMagic(std::span<const std::uint8_t> bytes) noexcept {
  if (bytes.size() < kMarkerStreamMagic.size()) return false;
  return std::equal(kMarkerStreamMagic.begin(), kMarkerStreamMagic.end(), bytes.begin()) ||
         std::equal(kMarkerStreamDescriptorMagic.begin(), kMarkerStreamDescriptorMagic.end(), bytes.begin());
}

// One record through the marker-stream decoder: a HID input report or a whole frame.
MarkerStreamStatus decodeMarkerStreamRecord(MarkerStreamDecoder& decoder, std::span<const std::uint8_t> bytes,
                                            std::int64_t receive_ns, MarkerFrame& out) noexcept {
  return isMarkerStreamHidReport(bytes) ? decoder.decodeHidReport(bytes, receive_ns, out)
                                        : decoder.decodeFrame(bytes, receive_ns, out);
}

std::string hex4(std::uint16_t v) {
  char buffer[8];
  std::snprintf(buffer, sizeof(buffer), "%04x", static_cast<unsigned>(v));
  return buffer;
}

ReplayKind classifyRecording(const RawRecording& recording) {
  const RawRecordingHeader& h = recording.header();
  if (h.vendor_id == kHydraVendorId && h.product_id == kHydraProductId) return ReplayKind::kHydra;
  for (std::size_t i = 0; i < recording.size(); ++i) {
    const std::span<const std::uint8_t> bytes = recording.record(i).bytes;
    if (bytes.empty()) continue;
    if (bytes.size() == kHydraReportSize) return ReplayKind::kHydra;
    if (isMarkerStreamHidReport(bytes) || hasMarkerStreamMagic(bytes)) return ReplayKind::kMarkerStream;
    throw std::invalid_argument(recording.sourceName() + ": cannot tell which device made this recording (" +
                                hex4(h.vendor_id) + ":" + hex4(h.product_id) + ", \"" + h.description +
                                "\"): its first record (" + std::to_string(bytes.size()) +
                                " bytes) is neither a 52-byte Razer Hydra report, a 64-byte marker-stream HID "
                                "report (report id 0x01) nor a marker-stream message (magic TMSF or TMSD)");
  }
  throw std::invalid_argument(recording.sourceName() + ": the recording has no data to replay");
}

double medianRate(std::vector<std::int64_t> frame_times) {
  if (frame_times.size() < 2) return 0.0;
  std::vector<std::int64_t> gaps;
  for (std::size_t i = 1; i < frame_times.size(); ++i) {
    // The times come from the recording: their difference may not fit (5e18 then -5e18). Such a
    // gap saturates, keeping its sign (a backwards step stays negative and gives no rate).
    std::int64_t gap = 0;
    if (__builtin_sub_overflow(frame_times[i], frame_times[i - 1], &gap)) {
      gap = frame_times[i] > frame_times[i - 1] ? std::numeric_limits<std::int64_t>::max()
                                                : std::numeric_limits<std::int64_t>::min();
    }
    gaps.push_back(gap);
  }
  std::sort(gaps.begin(), gaps.end());
  const std::size_t m = gaps.size() / 2;
  const double median = gaps.size() % 2 == 1 ? static_cast<double>(gaps[m])
                                             : 0.5 * (static_cast<double>(gaps[m - 1]) + static_cast<double>(gaps[m]));
  return median > 0.0 ? 1e9 / median : 0.0;
}

// What the construction-time scan of a recording found.
struct ReplayScan {
  bool has_labels = false;
  std::vector<std::string> labels;
  double rate_hz = 0.0;
};

ReplayScan scanRecording(const RawRecording& recording, ReplayKind kind) {
  ReplayScan scan;
  auto frame = std::make_unique<MarkerFrame>();
  std::vector<std::int64_t> frame_times;
  if (kind == ReplayKind::kHydra) {
    scan.has_labels = true;
    scan.labels = {"hydra0", "hydra1"};
    HydraDecoder decoder;
    for (std::size_t i = 0; i < recording.size() && frame_times.size() < kRateFrames; ++i) {
      const RawRecordView r = recording.record(i);
      if (decoder.decode(r.bytes, r.receive_ns, *frame) == HydraStatus::kFrame) frame_times.push_back(r.receive_ns);
    }
  } else {
    MarkerStreamDecoder decoder;
    for (std::size_t i = 0; i < recording.size() && (!scan.has_labels || frame_times.size() < kRateFrames); ++i) {
      const RawRecordView r = recording.record(i);
      const MarkerStreamStatus status = decodeMarkerStreamRecord(decoder, r.bytes, r.receive_ns, *frame);
      if (status == MarkerStreamStatus::kFrame) {
        if (frame_times.size() < kRateFrames) frame_times.push_back(r.receive_ns);
      } else if (status == MarkerStreamStatus::kDescriptor && !scan.has_labels) {
        // labels[id] for every id the descriptor names (ids may be sparse; the rest stay "").
        const MarkerLabelTable& table = decoder.labels();
        scan.has_labels = true;
        for (std::size_t e = 0; e < table.count; ++e) {
          const MarkerLabelEntry& entry = table.entries[e];
          if (scan.labels.size() <= entry.id) scan.labels.resize(std::size_t{entry.id} + 1);
          scan.labels[entry.id] = std::string(entry.label());
        }
      }
    }
  }
  scan.rate_hz = medianRate(std::move(frame_times));
  return scan;
}

class ReplayProducer final : public Producer {
 public:
  ReplayProducer(RawRecording recording, ReplayKind kind, Pacing pacing, double speed)
      : recording_(std::move(recording)), replay_(recording_, RawReplayOptions{pacing, speed, false}), kind_(kind) {}

  PacedRunStats run(Publisher& out, const InterruptiblePacingClock& clock) override {
    // Fresh decoders for every run: the replay starts a new stream.
    marker_stream_ = MarkerStreamDecoder{};
    hydra_ = HydraDecoder{};
    const std::uint64_t lost_before = out.counters().frames_lost.load(kRelaxed);
    if (kind_ == ReplayKind::kHydra) {
      return replay_.run(
          [&](const RawRecordView& record) noexcept {
            if (out.stopRequested()) return false;
            if (hydra_.decode(record.bytes, monotonicNowNs(), out.slot()) == HydraStatus::kFrame) {
              out.commit();
              out.counters().frames_lost.store(lost_before + hydra_.stats().frames_lost, kRelaxed);
            } else {
              out.counters().decode_errors.fetch_add(1, kRelaxed);
            }
            return true;
          },
          out.stopFlag(), clock);
    }
    return replay_.run(
        [&](const RawRecordView& record) noexcept {
          if (out.stopRequested()) return false;
          const MarkerStreamStatus status =
              decodeMarkerStreamRecord(marker_stream_, record.bytes, monotonicNowNs(), out.slot());
          if (status == MarkerStreamStatus::kFrame) {
            out.commit();
            out.counters().frames_lost.store(lost_before + marker_stream_.stats().frames_lost, kRelaxed);
          } else if (static_cast<int>(status) < 0) {
            out.counters().decode_errors.fetch_add(1, kRelaxed);
          }
          return true;
        },
        out.stopFlag(), clock);
  }

 private:
  RawRecording recording_;
  RawReplay replay_;  // refers to recording_ (this object is never moved: it lives behind a unique_ptr)
  ReplayKind kind_;
  MarkerStreamDecoder marker_stream_;
  HydraDecoder hydra_;
};

}  // namespace

std::unique_ptr<MarkerSource> makeC3DSource(std::shared_ptr<const C3DClip> clip, C3DPlaybackOptions options,
                                            std::string name) {
  if (!clip) throw std::invalid_argument("c3d source: no clip given");
  const Pacing pacing = options.pacing;
  const double speed = options.speed;
  const bool loop = options.loop;
  auto producer = std::make_unique<C3DProducer>(clip, std::move(options));
  const C3DPlayback& playback = producer->playback();
  const std::vector<int>& points = playback.selectedPoints();
  const std::size_t count = playback.markerCount();
  std::vector<std::string> labels;
  for (std::size_t k = 0; k < count; ++k) {
    const auto p = static_cast<std::size_t>(points[k]);
    if (labels.size() <= p) labels.resize(p + 1);
    labels[p] = c3dPointLabel(*clip, points[k]);
  }
  const double rate = playback.framePeriodNs() > 0 ? playback.frameRate() : 0.0;
  std::string description = "c3d:" + name + ", " + std::to_string(count) + " markers, " +
                            (rate > 0.0 ? formatHz(rate) : std::string("no frame rate")) + pacingText(pacing, speed) +
                            (loop ? ", loop" : "");
  return std::make_unique<PlaybackSource>(std::move(producer), std::move(description), arrivalRate(rate, pacing, speed), true,
                                          std::move(labels), pacing);
}

std::unique_ptr<MarkerSource> makeSyntheticSource(SyntheticOptions options, std::vector<std::string> labels) {
  auto producer = std::make_unique<SyntheticProducer>(std::move(options));
  const SyntheticSource& source = producer->source();
  const std::size_t count = source.markerCount();
  if (labels.empty()) {
    for (std::size_t i = 0; i < count; ++i) labels.push_back(numbered("M", i));
  } else if (labels.size() != count) {
    throw std::invalid_argument("synthetic source: " + std::to_string(labels.size()) + " labels given for " +
                                std::to_string(count) + " markers");
  }
  const SyntheticOptions& o = source.options();
  std::string description = "synthetic, " + std::to_string(count) + " markers, " + formatHz(o.rate_hz) +
                            pacingText(o.pacing, o.speed);
  return std::make_unique<PlaybackSource>(std::move(producer), std::move(description), arrivalRate(o.rate_hz, o.pacing, o.speed), true,
                                          std::move(labels), o.pacing);
}

std::unique_ptr<MarkerSource> makeReplaySource(std::filesystem::path recording, Pacing pacing, double speed) {
  if (!(speed > 0.0) || !std::isfinite(speed)) throw std::invalid_argument("replay: speed must be a positive number");
  RawRecording loaded = RawRecording::load(recording, /*tolerate_truncated_tail=*/true);
  if (loaded.size() == 0) throw std::invalid_argument(recording.string() + ": the recording has no records");
  const ReplayKind kind = classifyRecording(loaded);
  ReplayScan scan = scanRecording(loaded, kind);
  std::string description = "replay:" + recording.string() + " (";
  if (kind == ReplayKind::kHydra) {
    description += "Razer Hydra";
  } else {
    description += "marker stream, " +
                   (scan.has_labels ? std::to_string(scan.labels.size()) + " labels" : std::string("no descriptor"));
  }
  description += ", " + std::to_string(loaded.size()) + " records), " +
                 (scan.rate_hz > 0.0 ? formatHz(scan.rate_hz) : std::string("rate unknown")) +
                 pacingText(pacing, speed);
  auto producer = std::make_unique<ReplayProducer>(std::move(loaded), kind, pacing, speed);
  return std::make_unique<PlaybackSource>(std::move(producer), std::move(description), arrivalRate(scan.rate_hz, pacing, speed),
                                          scan.has_labels,
                                          std::move(scan.labels), pacing);
}

}  // namespace tetrig::drivers
