// Dot products of double arrays, among them the solver's per-vertex vectors (x, y, z, pad;
// kVectorStride doubles a vertex), private to runtime/src. Eight running sums instead of one: the
// compiler keeps them in vector registers, where a single sum would wait on each addition's latency
// (a 6000-entry product: ~8 us as one chain, ~1 us as eight). The order of the additions is fixed,
// so results are deterministic.
#pragma once

#include "tetrig/ldlt_factor.hpp"

#include <array>
#include <cstddef>

namespace tetrig {

// sum over i < n of a[i] b[i], split by lane (i mod kVectorStride): [0..2] the x, y, z parts, [3]
// the pad lanes'. n is a multiple of kVectorStride.
inline std::array<double, kVectorStride> paddedDotByLane(const double* a, const double* b, std::size_t n) noexcept {
  static_assert(kVectorStride == 4, "two vertices per eight sums");
  double s[8] = {};
  std::size_t i = 0;
  for (; i + 8 <= n; i += 8)
    for (std::size_t k = 0; k < 8; ++k) s[k] += a[i + k] * b[i + k];
  for (; i < n; i += kVectorStride)
    for (std::size_t k = 0; k < kVectorStride; ++k) s[k] += a[i + k] * b[i + k];
  return {s[0] + s[4], s[1] + s[5], s[2] + s[6], s[3] + s[7]};
}

// sum over i < n of a[i] b[i], any n (eight running sums, then the rest).
inline double dot(const double* a, const double* b, std::size_t n) noexcept {
  double s[8] = {};
  std::size_t i = 0;
  for (; i + 8 <= n; i += 8)
    for (std::size_t k = 0; k < 8; ++k) s[k] += a[i + k] * b[i + k];
  for (std::size_t k = 0; i < n; ++i, ++k) s[k] += a[i] * b[i];
  return ((s[0] + s[1]) + (s[2] + s[3])) + ((s[4] + s[5]) + (s[6] + s[7]));
}

}  // namespace tetrig
