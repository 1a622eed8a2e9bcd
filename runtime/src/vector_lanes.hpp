// The vector types of the frame-path kernels, written with GCC/Clang vector extensions so every
// build (AVX-512, AVX2, SSE2, NEON) vectorises the same source, and their unaligned loads and
// stores (memcpy: one vector move). Private to runtime/src; a file including it is compiled with
// -Wno-psabi (runtime/CMakeLists.txt).
//   Lanes:  kLanes (8) doubles, one AVX-512 register; Mask: a comparison of Lanes.
//   Vec4:   one vertex's x, y, z, pad (kVectorStride doubles), as the per-vertex vectors hold it.
//   FLanes: one quantity of the kTetBlockWidth (16) tets of a TetBlock, in float (one AVX-512
//           register); FMask: a comparison of FLanes. A block's lanes 0-7 and 8-15 are its two
//           halves in double (toDouble / toFloat).
// transposeIn / transposeOut move 8 vertices between the per-vertex and the lane layouts.
#pragma once

#include "tetrig/ldlt_factor.hpp"
#include "tetrig/rotation_kernel.hpp"

#include <cstring>

// Kernel helpers are forced inline: a call would cross the target_clones boundary (the helper
// compiled for the baseline) and would spill every vector register.
#define TETRIG_INLINE __attribute__((always_inline)) inline

namespace tetrig::lanes {

inline constexpr int kLanes = 8;
using Lanes = double __attribute__((vector_size(kLanes * sizeof(double))));
using Mask = long long __attribute__((vector_size(kLanes * sizeof(double))));
using Vec4 = double __attribute__((vector_size(kVectorStride * sizeof(double))));
using FLanes = float __attribute__((vector_size(kTetBlockWidth * sizeof(float))));
using FMask = int __attribute__((vector_size(kTetBlockWidth * sizeof(float))));
using Float8 = float __attribute__((vector_size(kLanes * sizeof(float))));
using Vec4f = float __attribute__((vector_size(kVectorStride * sizeof(float))));
static_assert(kTetBlockWidth == 2 * kLanes, "a TetBlock is two halves of kLanes doubles");

// Unaligned loads and stores of each vector type (memcpy: one vector move).
template <class V, class T>
TETRIG_INLINE V loadAs(const T* p) {
  V v;
  std::memcpy(&v, p, sizeof v);
  return v;
}
template <class V, class T>
TETRIG_INLINE void storeAs(T* p, V v) {
  std::memcpy(p, &v, sizeof v);
}
TETRIG_INLINE Lanes load(const double* p) { return loadAs<Lanes>(p); }
TETRIG_INLINE void store(double* p, Lanes v) { storeAs(p, v); }
TETRIG_INLINE Vec4 load4(const double* p) { return loadAs<Vec4>(p); }
TETRIG_INLINE void store4(double* p, Vec4 v) { storeAs(p, v); }
TETRIG_INLINE FLanes loadF(const float* p) { return loadAs<FLanes>(p); }
TETRIG_INLINE void storeF(float* p, FLanes v) { storeAs(p, v); }
TETRIG_INLINE Vec4f load4f(const float* p) { return loadAs<Vec4f>(p); }
TETRIG_INLINE void store4f(float* p, Vec4f v) { storeAs(p, v); }
// A vertex's 4 lanes as doubles, from double or from float (widened exactly).
TETRIG_INLINE Vec4 load4AsDouble(const double* p) { return load4(p); }
TETRIG_INLINE Vec4 load4AsDouble(const float* p) { return __builtin_convertvector(load4f(p), Vec4); }

// Two halves of a block (lanes 0-7, 8-15) in double <-> its 16 lanes in float.
TETRIG_INLINE FLanes toFloat(Lanes low, Lanes high) {
  const Float8 a = __builtin_convertvector(low, Float8), b = __builtin_convertvector(high, Float8);
  return __builtin_shufflevector(a, b, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
}
TETRIG_INLINE Lanes lowHalf(FLanes v) {
  return __builtin_convertvector(__builtin_shufflevector(v, v, 0, 1, 2, 3, 4, 5, 6, 7), Lanes);
}
TETRIG_INLINE Lanes highHalf(FLanes v) {
  return __builtin_convertvector(__builtin_shufflevector(v, v, 8, 9, 10, 11, 12, 13, 14, 15), Lanes);
}
// Eight floats of a TetBlock field (one half) as doubles, and back.
TETRIG_INLINE Lanes loadHalf(const float* p) { return __builtin_convertvector(loadAs<Float8>(p), Lanes); }
TETRIG_INLINE void storeHalf(float* p, Lanes v) { storeAs(p, __builtin_convertvector(v, Float8)); }

// The 8-lane <-> 8 x 4 transposes between per-vertex vectors (x, y, z, pad) and per-coordinate
// lanes (shuffles instead of scalar loads and inserts), in double (Lanes, Vec4) or float (Float8,
// Vec4f: the same shuffles on half the bytes).
static_assert(kLanes == 8 && kVectorStride == 4, "the transposes below are written for 8 lanes of 4");
template <class L, class V>
TETRIG_INLINE L concat(V a, V b) {
  return __builtin_shufflevector(a, b, 0, 1, 2, 3, 4, 5, 6, 7);
}

// v[l] = (x, y, z, pad) of lane l  ->  x, y, z as lanes.
template <class L, class V>
TETRIG_INLINE void transposeIn(const V (&v)[kLanes], L& x, L& y, L& z) {
  const L a = concat<L>(v[0], v[1]), b = concat<L>(v[2], v[3]), c = concat<L>(v[4], v[5]), d = concat<L>(v[6], v[7]);
  const L ab_xy = __builtin_shufflevector(a, b, 0, 4, 8, 12, 1, 5, 9, 13);  // x0..x3 y0..y3
  const L ab_z = __builtin_shufflevector(a, b, 2, 6, 10, 14, 3, 7, 11, 15);  // z0..z3 pad
  const L cd_xy = __builtin_shufflevector(c, d, 0, 4, 8, 12, 1, 5, 9, 13);
  const L cd_z = __builtin_shufflevector(c, d, 2, 6, 10, 14, 3, 7, 11, 15);
  x = __builtin_shufflevector(ab_xy, cd_xy, 0, 1, 2, 3, 8, 9, 10, 11);
  y = __builtin_shufflevector(ab_xy, cd_xy, 4, 5, 6, 7, 12, 13, 14, 15);
  z = __builtin_shufflevector(ab_z, cd_z, 0, 1, 2, 3, 8, 9, 10, 11);
}

// x, y, z lanes  ->  v[l] = (x_l, y_l, z_l, 0).
template <class L, class V>
TETRIG_INLINE void transposeOut(L x, L y, L z, V (&v)[kLanes]) {
  const L zero{};
  const L xy_lo = __builtin_shufflevector(x, y, 0, 8, 1, 9, 2, 10, 3, 11);   // x0 y0 x1 y1 x2 y2 x3 y3
  const L xy_hi = __builtin_shufflevector(x, y, 4, 12, 5, 13, 6, 14, 7, 15);
  const L z0_lo = __builtin_shufflevector(z, zero, 0, 8, 1, 9, 2, 10, 3, 11);  // z0 0 z1 0 ...
  const L z0_hi = __builtin_shufflevector(z, zero, 4, 12, 5, 13, 6, 14, 7, 15);
  const L l01 = __builtin_shufflevector(xy_lo, z0_lo, 0, 1, 8, 9, 2, 3, 10, 11);  // lane 0, lane 1
  const L l23 = __builtin_shufflevector(xy_lo, z0_lo, 4, 5, 12, 13, 6, 7, 14, 15);
  const L l45 = __builtin_shufflevector(xy_hi, z0_hi, 0, 1, 8, 9, 2, 3, 10, 11);
  const L l67 = __builtin_shufflevector(xy_hi, z0_hi, 4, 5, 12, 13, 6, 7, 14, 15);
  v[0] = __builtin_shufflevector(l01, l01, 0, 1, 2, 3);
  v[1] = __builtin_shufflevector(l01, l01, 4, 5, 6, 7);
  v[2] = __builtin_shufflevector(l23, l23, 0, 1, 2, 3);
  v[3] = __builtin_shufflevector(l23, l23, 4, 5, 6, 7);
  v[4] = __builtin_shufflevector(l45, l45, 0, 1, 2, 3);
  v[5] = __builtin_shufflevector(l45, l45, 4, 5, 6, 7);
  v[6] = __builtin_shufflevector(l67, l67, 0, 1, 2, 3);
  v[7] = __builtin_shufflevector(l67, l67, 4, 5, 6, 7);
}

// x, y, z as 16 float lanes  ->  v[l] = (x_l, y_l, z_l, 0): 8 two-source shuffles, then the
// 16 quarters.
TETRIG_INLINE void transposeOut16(FLanes x, FLanes y, FLanes z, Vec4f (&v)[kTetBlockWidth]) {
  const FLanes zero{};
  const FLanes xy_lo = __builtin_shufflevector(x, y, 0, 16, 1, 17, 2, 18, 3, 19, 4, 20, 5, 21, 6, 22, 7, 23);
  const FLanes xy_hi = __builtin_shufflevector(x, y, 8, 24, 9, 25, 10, 26, 11, 27, 12, 28, 13, 29, 14, 30, 15, 31);
  const FLanes z0_lo = __builtin_shufflevector(z, zero, 0, 16, 1, 17, 2, 18, 3, 19, 4, 20, 5, 21, 6, 22, 7, 23);
  const FLanes z0_hi = __builtin_shufflevector(z, zero, 8, 24, 9, 25, 10, 26, 11, 27, 12, 28, 13, 29, 14, 30, 15, 31);
  FLanes q[4];  // lanes 4i .. 4i + 3 as (x, y, z, 0)
  q[0] = __builtin_shufflevector(xy_lo, z0_lo, 0, 1, 16, 17, 2, 3, 18, 19, 4, 5, 20, 21, 6, 7, 22, 23);
  q[1] = __builtin_shufflevector(xy_lo, z0_lo, 8, 9, 24, 25, 10, 11, 26, 27, 12, 13, 28, 29, 14, 15, 30, 31);
  q[2] = __builtin_shufflevector(xy_hi, z0_hi, 0, 1, 16, 17, 2, 3, 18, 19, 4, 5, 20, 21, 6, 7, 22, 23);
  q[3] = __builtin_shufflevector(xy_hi, z0_hi, 8, 9, 24, 25, 10, 11, 26, 27, 12, 13, 28, 29, 14, 15, 30, 31);
  for (int i = 0; i < 4; ++i) {
    v[4 * i] = __builtin_shufflevector(q[i], q[i], 0, 1, 2, 3);
    v[4 * i + 1] = __builtin_shufflevector(q[i], q[i], 4, 5, 6, 7);
    v[4 * i + 2] = __builtin_shufflevector(q[i], q[i], 8, 9, 10, 11);
    v[4 * i + 3] = __builtin_shufflevector(q[i], q[i], 12, 13, 14, 15);
  }
}

}  // namespace tetrig::lanes
