// Sleeping on a 32-bit atomic word until it changes (Linux futex; elsewhere a 1 ms poll slice).
// Internal to the runtime: FrameMailbox::waitForFrame and the pose-transfer worker use it.
#pragma once

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <thread>

#if defined(__linux__)
#include <linux/futex.h>
#include <sys/syscall.h>
#include <time.h>
#include <unistd.h>
#endif

namespace tetrig::detail {

// Sleeps while word == expected, at most timeout_ns (spurious returns are fine: callers re-check).
inline void futexWait(std::atomic<std::uint32_t>& word, std::uint32_t expected, std::int64_t timeout_ns) noexcept {
#if defined(__linux__)
  static_assert(sizeof(std::atomic<std::uint32_t>) == sizeof(std::uint32_t));
  timespec ts{};
  ts.tv_sec = static_cast<time_t>(timeout_ns / 1'000'000'000);
  ts.tv_nsec = static_cast<long>(timeout_ns % 1'000'000'000);
  syscall(SYS_futex, reinterpret_cast<std::uint32_t*>(&word), FUTEX_WAIT_PRIVATE, expected, &ts, nullptr, 0);
#else
  if (word.load(std::memory_order_seq_cst) == expected) {
    std::this_thread::sleep_for(std::chrono::nanoseconds(std::min<std::int64_t>(timeout_ns, 1'000'000)));
  }
#endif
}

// Wakes every thread sleeping on `word`.
inline void futexWakeAll(std::atomic<std::uint32_t>& word) noexcept {
#if defined(__linux__)
  syscall(SYS_futex, reinterpret_cast<std::uint32_t*>(&word), FUTEX_WAKE_PRIVATE, 1 << 30, nullptr, nullptr, 0);
#else
  (void)word;
#endif
}

}  // namespace tetrig::detail
