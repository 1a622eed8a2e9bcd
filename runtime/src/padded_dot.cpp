// Dot products and scaled additions (padded_dot.hpp), written with the kernels' vector types so the
// x86-64-v4 and v3 clones use whole AVX registers: the volume constraint's projection and the
// implicit guard's step run them over every free vertex a few times per iteration.
#include "padded_dot.hpp"

#include "multiversion.hpp"
#include "vector_lanes.hpp"

namespace tetrig {

using lanes::load4;
using lanes::store4;
using lanes::Vec4;

namespace {

template <typename T>
TETRIG_INLINE std::array<double, kVectorStride> dotByLane(const double* a, const T* b, std::size_t n) {
  static_assert(kVectorStride == 4, "two vertices per eight sums");
  Vec4 s0 = {0, 0, 0, 0}, s1 = {0, 0, 0, 0};
  std::size_t i = 0;
  for (; i + 8 <= n; i += 8) {
    s0 += load4(a + i) * lanes::load4AsDouble(b + i);
    s1 += load4(a + i + 4) * lanes::load4AsDouble(b + i + 4);
  }
  if (i < n) s0 += load4(a + i) * lanes::load4AsDouble(b + i);
  const Vec4 s = s0 + s1;
  return {s[0], s[1], s[2], s[3]};
}

template <typename T>
TETRIG_INLINE void scaledByLane(double* y, const std::array<double, 3>& s, const T* x, std::size_t n) {
  const Vec4 scale = {s[0], s[1], s[2], 0.0};
  for (std::size_t i = 0; i < n; i += kVectorStride) {
    const Vec4 v = load4(y + i);
    const Vec4 sum = v + scale * lanes::load4AsDouble(x + i);
    store4(y + i, __builtin_shufflevector(sum, v, 0, 1, 2, 7));  // the pad lane: y's own
  }
}

template <typename T>
TETRIG_INLINE void scaledByLaneAndScaled(double* y, const std::array<double, 3>& s, const T* x, double t, const double* w,
                                         std::size_t n) {
  const Vec4 scale = {s[0], s[1], s[2], 0.0};
  for (std::size_t i = 0; i < n; i += kVectorStride) {
    const Vec4 v = load4(y + i);
    const Vec4 sum = v + scale * lanes::load4AsDouble(x + i);
    store4(y + i, __builtin_shufflevector(sum, v, 0, 1, 2, 7) + t * load4(w + i));  // the pad lane: y's own (+ 0)
  }
}

}  // namespace

TETRIG_MULTIVERSION std::array<double, kVectorStride> paddedDotByLane(const double* a, const double* b, std::size_t n) noexcept {
  return dotByLane(a, b, n);
}

TETRIG_MULTIVERSION std::array<double, kVectorStride> paddedDotByLane(const double* a, const float* b, std::size_t n) noexcept {
  return dotByLane(a, b, n);
}

TETRIG_MULTIVERSION double dot(const double* a, const double* b, std::size_t n) noexcept {
  Vec4 s0 = {0, 0, 0, 0}, s1 = {0, 0, 0, 0};
  std::size_t i = 0;
  for (; i + 8 <= n; i += 8) {
    s0 += load4(a + i) * load4(b + i);
    s1 += load4(a + i + 4) * load4(b + i + 4);
  }
  double rest = 0.0;
  for (; i < n; ++i) rest += a[i] * b[i];
  return ((s0[0] + s0[1]) + (s0[2] + s0[3])) + ((s1[0] + s1[1]) + (s1[2] + s1[3])) + rest;
}

TETRIG_MULTIVERSION void addScaled(double* y, double s, const double* x, std::size_t n) noexcept {
  std::size_t i = 0;
  for (; i + 4 <= n; i += 4) store4(y + i, load4(y + i) + s * load4(x + i));
  for (; i < n; ++i) y[i] += s * x[i];
}

TETRIG_MULTIVERSION void addScaledByLane(double* y, const std::array<double, 3>& s, const double* x, std::size_t n) noexcept {
  scaledByLane(y, s, x, n);
}

TETRIG_MULTIVERSION void addScaledByLane(double* y, const std::array<double, 3>& s, const float* x, std::size_t n) noexcept {
  scaledByLane(y, s, x, n);
}

TETRIG_MULTIVERSION void addScaledByLaneAndScaled(double* y, const std::array<double, 3>& s, const double* x, double t, const double* w,
                                                  std::size_t n) noexcept {
  scaledByLaneAndScaled(y, s, x, t, w, n);
}

TETRIG_MULTIVERSION void addScaledByLaneAndScaled(double* y, const std::array<double, 3>& s, const float* x, double t, const double* w,
                                                  std::size_t n) noexcept {
  scaledByLaneAndScaled(y, s, x, t, w, n);
}

TETRIG_MULTIVERSION void toFloat(const double* a, float* out, std::size_t n) noexcept {
  for (std::size_t i = 0; i < n; ++i) out[i] = static_cast<float>(a[i]);
}

TETRIG_MULTIVERSION void toDouble(const float* a, double* out, std::size_t n) noexcept {
  for (std::size_t i = 0; i < n; ++i) out[i] = a[i];
}

}  // namespace tetrig
