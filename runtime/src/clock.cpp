// CLOCK_MONOTONIC in nanoseconds (tetrig/clock.hpp).
#include "tetrig/clock.hpp"

#include <time.h>

namespace tetrig {

std::int64_t monotonicNowNs() noexcept {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

}  // namespace tetrig
