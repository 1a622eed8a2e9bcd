// The runtime's one clock: CLOCK_MONOTONIC in nanoseconds. Every timestamp the live path takes
// (a frame's receive time, the solver's take / step / pose-transfer / publish times, the
// shared-memory heartbeat) comes from here, so differences between them are meaningful across
// threads and processes on one machine. (The same clock as std::chrono::steady_clock on Linux.)
// Any thread; no allocation; never fails.
#pragma once

#include <cstdint>

namespace tetrig {

std::int64_t monotonicNowNs() noexcept;

}  // namespace tetrig
