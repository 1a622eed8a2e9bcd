// Pacing vocabulary shared by the playback sources (C3D playback, raw replay, synthetic source):
// real-time or as-fast-as-possible, the clock they sleep on, and how they call a sink.
//
// A sink is any callable taking the produced item by const reference; it may return void
// (keep going) or bool (false = stop). No std::function: the sources' run() functions are
// templates, so the call is direct and allocation-free. mailboxSink() adapts anything with
// publish(const MarkerFrame&) (tetrig::FrameMailbox) into a sink.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <thread>
#include <type_traits>
#include <utility>

namespace tetrig::drivers {

enum class Pacing : std::uint8_t {
  kRealTime,         // item k is released at start + (its time - first time) / speed
  kAsFastAsPossible, // no sleeping at all
  kLockstep          // a MarkerSource only: as fast as its consumer takes frames (each frame waits, sleeping,
                     // until the mailbox's previous one was taken: none dropped, no core spun); the
                     // pacing loops themselves treat it as kAsFastAsPossible
};

// The default clock: std::chrono::steady_clock (CLOCK_MONOTONIC on Linux, the clock of
// MarkerFrame::receive_timestamp_ns). Tests pass a fake clock with the same two members.
// sleepUntilNs never returns before the target on a steady clock. Any thread; no allocation.
struct SteadyPacingClock {
  [[nodiscard]] std::int64_t nowNs() const noexcept {
    return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch())
        .count();
  }
  void sleepUntilNs(std::int64_t target_ns) const {
    std::this_thread::sleep_until(std::chrono::steady_clock::time_point(std::chrono::nanoseconds(target_ns)));
  }
};

// What a run() did.
struct PacedRunStats {
  std::uint64_t items = 0;        // items handed to the sink
  std::uint64_t late_items = 0;   // real-time only: released more than one period after their time
  std::uint64_t loops = 0;        // completed passes over the clip/recording
  bool stopped = false;           // ended by the stop flag or a sink returning false
};

namespace detail {
// Calls sink(item); returns false when the sink asked to stop.
template <class Sink, class Item>
bool callSink(Sink& sink, const Item& item) {
  if constexpr (std::is_same_v<std::invoke_result_t<Sink&, const Item&>, bool>) {
    return sink(item);
  } else {
    sink(item);
    return true;
  }
}
// A schedule offset in ns, rounded and clamped to 4e18 ns (127 years) so that adding it to a
// steady-clock reading cannot overflow, whatever a file's timestamps or rate say.
inline std::int64_t clampedNs(double ns) noexcept {
  if (!(ns > 0.0)) return 0;
  return ns >= 4e18 ? std::int64_t{4'000'000'000'000'000'000} : static_cast<std::int64_t>(ns + 0.5);
}
inline bool stopRequested(const std::atomic<bool>* stop) noexcept {
  return stop != nullptr && stop->load(std::memory_order_relaxed);
}
// Real-time pacing of item `counter` of a run that started at `start_ns` with one item every
// `step_ns`: sleeps until the item's time, or counts it late when it is more than a step behind.
template <class Clock>
void waitForItem(Clock& clock, std::int64_t start_ns, std::uint64_t counter, double step_ns, PacedRunStats& stats) {
  const std::int64_t target = start_ns + clampedNs(static_cast<double>(counter) * step_ns);
  const std::int64_t now = clock.nowNs();
  if (now < target) {
    clock.sleepUntilNs(target);
  } else if (static_cast<double>(now - target) > step_ns) {
    ++stats.late_items;
  }
}
}  // namespace detail

// Sink adapter for a latest-frame mailbox (tetrig::FrameMailbox or anything with
// publish(const Frame&)). The mailbox must outlive the sink; the caller's thread becomes the
// mailbox's single producer.
template <class Mailbox>
auto mailboxSink(Mailbox& mailbox) {
  return [&mailbox](const auto& frame) { mailbox.publish(frame); };
}

}  // namespace tetrig::drivers
