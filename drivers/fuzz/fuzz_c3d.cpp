// libFuzzer target for the C3D reader's in-memory entry point (C3DClip::parse). Every input
// must either parse or throw C3DError; anything else (crash, sanitizer report, other exception)
// is a finding. When a clip parses, every frame accessor is exercised and the sample contract is
// checked (valid: finite position, residual >= 0, never a zero-residual origin under the default
// options; otherwise position 0 and residual -1); warnings and error messages must be printable
// ASCII (file text in them is escaped).
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string_view>

#include "tetrig/drivers/c3d_reader.hpp"

namespace {

void requirePrintable(std::string_view text) {
  for (const char c : text) {
    const auto u = static_cast<unsigned char>(c);
    if (u < 0x20 || u >= 0x7f) __builtin_trap();  // raw file bytes reached a message
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using tetrig::drivers::C3DSample;
  try {
    const tetrig::drivers::C3DClip clip = tetrig::drivers::C3DClip::parse(std::span(data, size), "fuzz.c3d");
    double sum = 0.0;
    for (std::size_t f = 0; clip.pointCount() > 0 && f < clip.frameCount(); ++f) {
      const float* p = clip.positions(f);
      const C3DSample* s = clip.samples(f);
      for (int i = 0; i < clip.pointCount(); ++i) {
        const float r = clip.residual(f, i);
        if (clip.isValid(f, i)) {
          sum += p[3 * i] + p[3 * i + 1] + p[3 * i + 2] + r;
          // Valid samples are finite by contract, and a zero-residual origin is a gap by default.
          if (!std::isfinite(p[3 * i]) || !std::isfinite(p[3 * i + 1]) || !std::isfinite(p[3 * i + 2])) __builtin_trap();
          if (!(r >= 0.0f)) __builtin_trap();
          if (r == 0.0f && clip.pointScale() > 0.0f && p[3 * i] == 0.0f && p[3 * i + 1] == 0.0f &&
              p[3 * i + 2] == 0.0f) {
            __builtin_trap();
          }
        } else {
          if (s[i] != C3DSample::kInvalid && s[i] != C3DSample::kNonFinite && s[i] != C3DSample::kZeroGap) __builtin_trap();
          if (p[3 * i] != 0.0f || p[3 * i + 1] != 0.0f || p[3 * i + 2] != 0.0f || r != -1.0f) __builtin_trap();
        }
      }
    }
    for (int i = 0; i < clip.pointCount(); ++i) sum += static_cast<int>(clip.pointKind(i));
    for (const std::string& w : clip.warnings()) requirePrintable(w);
    (void)clip.findPoint("LFHD");
    volatile double sink = sum;
    (void)sink;
  } catch (const tetrig::drivers::C3DError& e) {
    requirePrintable(e.what());
  }
  return 0;
}
