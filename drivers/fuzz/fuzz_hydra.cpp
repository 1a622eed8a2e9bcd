// libFuzzer target for the Razer Hydra decoder (docs/protocol.md, "Fuzzing"). Checks, besides
// memory safety: decoded markers are finite with unit quaternions, the 64-bit counter only grows,
// and encode(parse(report)) reproduces every byte the decoder interprets.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>

#include "tetrig/drivers/hydra.hpp"

namespace {
void check(bool ok) {
  if (!ok) __builtin_trap();
}
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace tetrig::drivers;
  static auto frame = std::make_unique<tetrig::MarkerFrame>();
  const std::span<const std::uint8_t> in(data, size);

  // Whole input as one report (any length).
  {
    HydraDecoder dec;
    const HydraStatus st = dec.decode(in, 0, *frame);
    check(st == (size < kHydraReportSize   ? HydraStatus::kTruncated
                 : size > kHydraReportSize ? HydraStatus::kBadLength
                                           : HydraStatus::kFrame));
  }
  // Input as a stream of 52-byte reports through one decoder.
  HydraDecoder dec;
  HydraState state;
  std::uint64_t last = 0;
  bool have = false;
  for (std::size_t pos = 0; pos + kHydraReportSize <= size; pos += kHydraReportSize) {
    const auto report = in.subspan(pos, kHydraReportSize);
    if (dec.decode(report, 0, *frame, &state) == HydraStatus::kFrame) {
      check(frame->marker_count == 2);
      check(!have || frame->frame_counter > last);
      last = frame->frame_counter;
      have = true;
      for (std::size_t c = 0; c < 2; ++c) {
        const auto& m = frame->markers[c];
        for (float p : m.position_mm) check(std::isfinite(p));
        double n2 = 0.0;
        for (float q : m.orientation) n2 += static_cast<double>(q) * q;
        check(std::fabs(n2 - 1.0) < 1e-5);
        check(m.valid == (state.controllers[c].pose_valid ? 1 : 0));
      }
    }
    HydraRawReport raw;
    check(parseHydraReport(report, raw) == HydraStatus::kFrame);
    std::uint8_t again[kHydraReportSize];
    check(encodeHydraReport(raw, again) == kHydraReportSize);
    for (std::size_t i = 7; i < kHydraReportSize; ++i) {
      const bool unused = i == 28 || i == 29 || i == 50 || i == 51;
      check(unused || again[i] == report[i]);
    }
  }
  return 0;
}
