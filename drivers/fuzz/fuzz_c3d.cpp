// libFuzzer target for the C3D reader's in-memory entry point (C3DClip::parse). Every input
// must either parse or throw C3DError; anything else (crash, sanitizer report, other exception)
// is a finding. When a clip parses, every frame accessor is exercised.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <span>

#include "tetrig/drivers/c3d_reader.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  try {
    const tetrig::drivers::C3DClip clip = tetrig::drivers::C3DClip::parse(std::span(data, size), "fuzz.c3d");
    double sum = 0.0;
    for (std::size_t f = 0; clip.pointCount() > 0 && f < clip.frameCount(); ++f) {
      const float* p = clip.positions(f);
      for (int i = 0; i < clip.pointCount(); ++i) {
        if (clip.isValid(f, i)) {
          sum += p[3 * i] + p[3 * i + 1] + p[3 * i + 2] + clip.residual(f, i);
          if (!std::isfinite(p[3 * i])) __builtin_trap();  // valid samples are finite by contract
        }
      }
    }
    for (int i = 0; i < clip.pointCount(); ++i) sum += static_cast<int>(clip.pointKind(i));
    (void)clip.findPoint("LFHD");
    volatile double sink = sum;
    (void)sink;
  } catch (const tetrig::drivers::C3DError&) {
  }
  return 0;
}
