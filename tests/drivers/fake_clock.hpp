// A clock for paced sources in tests: time moves only when the source sleeps, and every sleep
// target is recorded, so pacing is checked without real time.
#pragma once

#include <cstdint>
#include <vector>

namespace tetrig::test {

struct FakeClock {
  std::int64_t* now;
  std::vector<std::int64_t>* sleeps;
  std::int64_t nowNs() const { return *now; }
  void sleepUntilNs(std::int64_t t) const {
    sleeps->push_back(t);
    if (t > *now) *now = t;
  }
};

}  // namespace tetrig::test
