// The vector types of the frame-path kernels, written with GCC/Clang vector extensions so every
// build (AVX-512, AVX2, SSE2, NEON) vectorises the same source, and their unaligned loads and
// stores (memcpy: one vector move). Private to runtime/src; a file including it is compiled with
// -Wno-psabi (runtime/CMakeLists.txt).
//   Lanes: one quantity of the kTetBlockWidth (8) tets of a block; Mask: a comparison of Lanes.
//   Vec4:  one vertex's x, y, z, pad (kVectorStride doubles), as the per-vertex vectors hold it.
#pragma once

#include "tetrig/ldlt_factor.hpp"
#include "tetrig/rotation_kernel.hpp"

#include <cstring>

// Kernel helpers are forced inline: a call would cross the target_clones boundary (the helper
// compiled for the baseline) and would spill every vector register.
#define TETRIG_INLINE __attribute__((always_inline)) inline

namespace tetrig::lanes {

using Lanes = double __attribute__((vector_size(kTetBlockWidth * sizeof(double))));
using Mask = long long __attribute__((vector_size(kTetBlockWidth * sizeof(double))));
using Vec4 = double __attribute__((vector_size(kVectorStride * sizeof(double))));

TETRIG_INLINE Lanes load(const double* p) {
  Lanes v;
  std::memcpy(&v, p, sizeof v);
  return v;
}
TETRIG_INLINE void store(double* p, Lanes v) { std::memcpy(p, &v, sizeof v); }
TETRIG_INLINE Vec4 load4(const double* p) {
  Vec4 v;
  std::memcpy(&v, p, sizeof v);
  return v;
}
TETRIG_INLINE void store4(double* p, Vec4 v) { std::memcpy(p, &v, sizeof v); }

}  // namespace tetrig::lanes
