// Protocol decoder and mailbox benchmarks (docs/drivers.md, "Decoders and the frame mailbox").
//
// BM_DecodeMarkerStream/fragmented:0  one 41-marker frame (688 bytes) from a whole buffer (USB bulk)
// BM_DecodeMarkerStream/fragmented:1  the same frame from its 12 HID reports (reassembly + decode)
// BM_DecodeHydra                      one 52-byte Razer Hydra report
// BM_MailboxHandoff/zero_copy:0|1     producer thread -> consumer thread latency through the
//                                     FrameMailbox (timestamp before publish -> after take), with
//                                     p50/p99/max in ns as counters; zero_copy:1 uses
//                                     producerSlot()/commit() and tryAcquireLatest().
#include <benchmark/benchmark.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <memory>
#include <thread>
#include <vector>

#include "tetrig/drivers/hydra.hpp"
#include "tetrig/drivers/marker_stream.hpp"
#include "tetrig/frame_mailbox.hpp"

namespace {

using namespace tetrig;
using namespace tetrig::drivers;

constexpr std::size_t kFrames = 256;  // distinct pre-encoded frames cycled through
constexpr std::uint16_t kBenchMarkers = 41;  // the HDM05 full-body marker set

std::int64_t nowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

std::vector<std::uint8_t> encodeBenchFrame(std::uint32_t counter) {
  auto f = std::make_unique<MarkerFrame>();
  f->frame_counter = counter;
  f->device_timestamp_ns = static_cast<std::int64_t>(counter) * 8333333;
  f->marker_count = kBenchMarkers;
  for (std::uint16_t i = 0; i < kBenchMarkers; ++i) {
    auto& m = f->markers[i];
    m.id = i;
    m.valid = (i + counter) % 13 != 0 ? 1 : 0;  // a few occluded markers
    m.position_mm[0] = 100.0f + static_cast<float>(i) * 10.0f + static_cast<float>(counter) * 0.1f;
    m.position_mm[1] = -50.0f + static_cast<float>(i);
    m.position_mm[2] = 900.0f + static_cast<float>(i % 7) * 100.0f;
  }
  std::vector<std::uint8_t> b(kMarkerStreamMaxFrameSize);
  b.resize(encodeMarkerStreamFrame(*f, {}, b));
  return b;
}

void BM_DecodeMarkerStream(benchmark::State& state) {
  const bool fragmented = state.range(0) != 0;
  std::vector<std::vector<std::uint8_t>> frames;
  std::vector<std::vector<std::uint8_t>> reports;  // all reports of frame k at [k * per, (k + 1) * per)
  for (std::uint32_t c = 1; c <= kFrames; ++c) {
    frames.push_back(encodeBenchFrame(c));
    const std::size_t n = markerStreamFragmentCount(frames.back().size());
    for (std::size_t i = 0; i < n; ++i) {
      std::vector<std::uint8_t> r(kMarkerStreamHidReportSize);
      (void)encodeMarkerStreamFragment(frames.back(), i, r);
      reports.push_back(std::move(r));
    }
  }
  const std::size_t per = reports.size() / kFrames;
  MarkerStreamDecoder dec;
  auto out = std::make_unique<MarkerFrame>();
  std::size_t k = 0;
  std::int64_t bad = 0;
  for (auto _ : state) {
    if (k == kFrames) {  // counters start over: forget the sequence (once per 256 frames)
      k = 0;
      dec.reset();
    }
    MarkerStreamStatus st = MarkerStreamStatus::kNeedMore;
    if (fragmented) {
      for (std::size_t i = 0; i < per; ++i) st = dec.decodeHidReport(reports[k * per + i], 1, *out);
    } else {
      st = dec.decodeFrame(frames[k], 1, *out);
    }
    bad += st != MarkerStreamStatus::kFrame ? 1 : 0;
    benchmark::DoNotOptimize(out->markers[0].position_mm[0]);
    ++k;
  }
  if (bad != 0) state.SkipWithError("a frame did not decode");
  state.SetBytesProcessed(static_cast<std::int64_t>(state.iterations()) * static_cast<std::int64_t>(frames[0].size()));
  state.counters["frame_bytes"] = static_cast<double>(frames[0].size());
  state.counters["reports_per_frame"] = static_cast<double>(fragmented ? per : 0);
}
BENCHMARK(BM_DecodeMarkerStream)->ArgName("fragmented")->Arg(0)->Arg(1);

void BM_DecodeHydra(benchmark::State& state) {
  std::vector<std::vector<std::uint8_t>> reports;
  for (std::size_t s = 0; s < 256; ++s) {
    HydraRawReport r;
    r.sequence = static_cast<std::uint8_t>(s);
    for (std::size_t c = 0; c < 2; ++c) {
      const float p[3] = {static_cast<float>(s), -100.0f, 250.0f + static_cast<float>(c)};
      const float q[4] = {0.9f, 0.1f * static_cast<float>(c), 0.3f, -0.2f};
      r.controllers[c] = hydraControllerFromPose(p, q);
    }
    std::vector<std::uint8_t> b(kHydraReportSize);
    (void)encodeHydraReport(r, b);
    reports.push_back(std::move(b));
  }
  HydraDecoder dec;
  auto out = std::make_unique<MarkerFrame>();
  HydraState hs;
  std::size_t k = 0;
  std::int64_t bad = 0;
  for (auto _ : state) {
    bad += dec.decode(reports[k], 1, *out, &hs) != HydraStatus::kFrame ? 1 : 0;
    benchmark::DoNotOptimize(out->markers[1].orientation[0]);
    k = (k + 1) & 0xFFu;  // the 8-bit sequence wraps with it: every report is one step ahead
  }
  if (bad != 0) state.SkipWithError("a report did not decode");
}
BENCHMARK(BM_DecodeHydra);

// Spin briefly, then yield: the machine has 2 cores shared with other work, and a pure spin
// could hold the core the other side needs.
template <class Pred>
void waitUntil(Pred pred) {
  for (int spins = 0; !pred(); ++spins) {
    if (spins > 200) std::this_thread::yield();
  }
}

void BM_MailboxHandoff(benchmark::State& state) {
  const bool zero_copy = state.range(0) != 0;
  auto box = std::make_unique<FrameMailbox>();
  std::atomic<bool> stop{false};
  std::atomic<std::uint64_t> acked{0};
  // Producer: one frame at a time, after the consumer took the previous one, so that every
  // sample is one publish -> take hand-off (no queueing, no drops).
  std::thread producer([&] {
    auto frame = std::make_unique<MarkerFrame>();
    frame->marker_count = kBenchMarkers;
    std::uint64_t c = 0;
    while (!stop.load(std::memory_order_relaxed)) {
      waitUntil([&] { return acked.load(std::memory_order_acquire) >= c || stop.load(std::memory_order_relaxed); });
      if (stop.load(std::memory_order_relaxed)) break;
      ++c;
      if (zero_copy) {
        MarkerFrame& slot = box->producerSlot();
        slot.frame_counter = c;
        slot.marker_count = kBenchMarkers;
        slot.receive_timestamp_ns = nowNs();
        box->commit();
      } else {
        frame->frame_counter = c;
        frame->receive_timestamp_ns = nowNs();
        box->publish(*frame);
      }
    }
  });
  std::vector<std::int64_t> latency;
  latency.reserve(1u << 20);
  auto out = std::make_unique<MarkerFrame>();
  for (auto _ : state) {
    const MarkerFrame* f = nullptr;
    if (zero_copy) {
      waitUntil([&] { return (f = box->tryAcquireLatest()) != nullptr; });
    } else {
      waitUntil([&] { return box->tryTakeLatest(*out); });
      f = out.get();
    }
    const std::int64_t t = nowNs();
    if (latency.size() < latency.capacity()) latency.push_back(t - f->receive_timestamp_ns);
    acked.store(f->frame_counter, std::memory_order_release);
  }
  stop.store(true);
  producer.join();
  if (latency.empty()) return;
  std::sort(latency.begin(), latency.end());
  const auto pct = [&](double p) {
    return static_cast<double>(latency[std::min(latency.size() - 1, static_cast<std::size_t>(p * static_cast<double>(latency.size())))]);
  };
  state.counters["p50_ns"] = pct(0.50);
  state.counters["p99_ns"] = pct(0.99);
  state.counters["max_ns"] = static_cast<double>(latency.back());
  state.counters["dropped"] = static_cast<double>(box->dropped());
}
BENCHMARK(BM_MailboxHandoff)->ArgName("zero_copy")->Arg(0)->Arg(1)->UseRealTime();

}  // namespace
