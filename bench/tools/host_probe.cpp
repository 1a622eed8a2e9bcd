// What the host lets a 120 Hz frame loop have, independent of tetrig's code: a thread sleeps to each
// tick of a fixed rate (absolute clock_nanosleep, as the solver thread waits for a frame), then runs
// a fixed, cache-resident arithmetic workload of about --work-us microseconds, and records how late
// it woke and how long the workload took. On an idle machine of its own the workload's p99 is close
// to its p50; on a contended virtual machine it is not, and then so is every phase of the latency
// harness: a frame cannot finish sooner than the host runs it. bench/latency.sh runs this first and
// prints it beside the table (docs/live.md, "Latency").
//
//   build/release/tetrig_host_probe [--frames 1200] [--rate 120] [--work-us 700] [--json FILE]
#include "tetrig/clock.hpp"
#include "tetrig/latency_histogram.hpp"

#include <algorithm>
#include <array>
#include <cerrno>
#include <charconv>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <string>
#include <string_view>

namespace {

// A fixed amount of arithmetic over 16 KiB (L1-resident: it measures CPU time given, not memory).
float workload(const std::array<float, 4096>& a, int repeats) {
  float acc = 0.0f;
  for (int r = 0; r < repeats; ++r)
    for (std::size_t i = 0; i + 2 < a.size(); i += 4) acc += a[i] * a[i + 1] + a[i + 2];
  return acc;
}

struct Percentiles {
  double p50, p99, max;  // microseconds
};

// The same histogram as `tetrig run`'s latencies, so the probe and the harness's table compare
// like with like (a percentile within 3.1 % above the true value).
Percentiles percentiles(const tetrig::LatencyHistogram& h) {
  return {static_cast<double>(h.percentileNs(0.5)) / 1e3, static_cast<double>(h.percentileNs(0.99)) / 1e3,
          static_cast<double>(h.maxNs()) / 1e3};
}

bool parseInt(std::string_view text, int lo, int hi, int& out) {
  int v = 0;
  const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
  if (ec != std::errc() || end != text.data() + text.size() || v < lo || v > hi) return false;
  out = v;
  return true;
}

}  // namespace

int main(int argc, char** argv) {
  int frames = 1200, rate = 120, work_us = 700;
  std::string json;
  for (int i = 1; i < argc; ++i) {
    const std::string_view arg = argv[i];
    const bool has_value = i + 1 < argc;
    if (arg == "--frames" && has_value && parseInt(argv[i + 1], 10, 10'000'000, frames)) { ++i; continue; }
    if (arg == "--rate" && has_value && parseInt(argv[i + 1], 1, 100'000, rate)) { ++i; continue; }
    if (arg == "--work-us" && has_value && parseInt(argv[i + 1], 1, 1'000'000, work_us)) { ++i; continue; }
    if (arg == "--json" && has_value) { json = argv[++i]; continue; }
    if (arg == "--frames" || arg == "--rate" || arg == "--work-us" || arg == "--json") {
      std::fprintf(stderr, "tetrig_host_probe: %s needs %s\n", argv[i],
                   arg == "--json" ? "a file name" : arg == "--frames" ? "an integer from 10 to 10000000" : "a positive integer");
    } else {
      std::fprintf(stderr, "tetrig_host_probe: unknown argument '%s' (usage: [--frames N] [--rate HZ] [--work-us US] [--json FILE])\n", argv[i]);
    }
    return 2;
  }
  const std::int64_t period_ns = 1'000'000'000LL / rate;
  if (static_cast<std::int64_t>(work_us) * 1000 >= period_ns) {
    std::fprintf(stderr, "tetrig_host_probe: --work-us %d does not fit in a period of %.1f us at %d Hz\n", work_us, static_cast<double>(period_ns) / 1e3, rate);
    return 2;
  }
  std::array<float, 4096> a{};
  for (std::size_t i = 0; i < a.size(); ++i) a[i] = static_cast<float>(i) * 1e-6f;
  volatile float sink = 0.0f;

  // Calibrate on the fastest of 200 runs of one repeat (the uncontended speed).
  std::int64_t one = INT64_MAX;
  for (int k = 0; k < 200; ++k) {
    const std::int64_t t0 = tetrig::monotonicNowNs();
    sink = sink + workload(a, 1);
    one = std::min(one, tetrig::monotonicNowNs() - t0);
  }
  const int repeats = std::max(1, static_cast<int>(static_cast<std::int64_t>(work_us) * 1000 / std::max<std::int64_t>(one, 1)));

  tetrig::LatencyHistogram late, took;
  const std::int64_t start = tetrig::monotonicNowNs() + period_ns;
  for (int f = 0; f < frames; ++f) {
    const std::int64_t tick = start + static_cast<std::int64_t>(f) * period_ns;
    const timespec ts{static_cast<time_t>(tick / 1'000'000'000LL), static_cast<long>(tick % 1'000'000'000LL)};
    while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
    }
    const std::int64_t woke = tetrig::monotonicNowNs();
    sink = sink + workload(a, repeats);
    const std::int64_t done = tetrig::monotonicNowNs();
    late.record(woke - tick);  // negative (early) counts as 0
    took.record(done - woke);
  }
  const Percentiles w = percentiles(late), t = percentiles(took);
  std::printf("host probe: %d frames at %d Hz, a fixed workload of ~%d us (calibrated), microseconds p50 / p99 / max:\n"
              "  wake-up lateness  %.1f / %.1f / %.1f\n  workload          %.1f / %.1f / %.1f  (p99 / p50 = %.1f)\n",
              frames, rate, work_us, w.p50, w.p99, w.max, t.p50, t.p99, t.max, t.p99 / t.p50);
  if (!json.empty()) {
    std::FILE* out = std::fopen(json.c_str(), "w");
    if (out == nullptr) {
      std::fprintf(stderr, "tetrig_host_probe: cannot write %s: %s\n", json.c_str(), std::strerror(errno));
      return 1;
    }
    std::fprintf(out,
                 "{\"frames\": %d, \"rate_hz\": %d, \"work_us\": %d, \"wake_lateness_us\": {\"p50\": %.1f, \"p99\": %.1f, \"max\": %.1f}, "
                 "\"workload_us\": {\"p50\": %.1f, \"p99\": %.1f, \"max\": %.1f}}\n",
                 frames, rate, work_us, w.p50, w.p99, w.max, t.p50, t.p99, t.max);
    if (std::fclose(out) != 0) {
      std::fprintf(stderr, "tetrig_host_probe: cannot write %s\n", json.c_str());
      return 1;
    }
  }
  return 0;
}
