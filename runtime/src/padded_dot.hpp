// Dot products and scaled additions over double arrays, among them the solver's per-vertex vectors
// (x, y, z, pad; kVectorStride doubles a vertex), private to runtime/src (padded_dot.cpp, compiled for
// the widest instruction set the CPU runs). Each dot product keeps eight running sums, where a single
// sum would wait on each addition's latency; the order of the additions is fixed, so results do not
// depend on the data.
#pragma once

#include "tetrig/ldlt_factor.hpp"

#include <array>
#include <cstddef>

namespace tetrig {

// sum over i < n of a[i] b[i], split by lane (i mod kVectorStride): [0..2] the x, y, z parts, [3]
// the pad lanes'. n is a multiple of kVectorStride.
std::array<double, kVectorStride> paddedDotByLane(const double* a, const double* b, std::size_t n) noexcept;
// The same with b in float (each entry widened exactly: the same products and sums as with b's
// double copy).
std::array<double, kVectorStride> paddedDotByLane(const double* a, const float* b, std::size_t n) noexcept;

// sum over i < n of a[i] b[i], any n.
double dot(const double* a, const double* b, std::size_t n) noexcept;

// y[i] += s x[i], i < n (any n).
void addScaled(double* y, double s, const double* x, std::size_t n) noexcept;

// y += s_c x per lane of the per-vertex vectors: lanes 0..2 (x, y, z) scaled by s[0..2], the pad
// lane left as it is. n is a multiple of kVectorStride.
void addScaledByLane(double* y, const std::array<double, 3>& s, const double* x, std::size_t n) noexcept;
void addScaledByLane(double* y, const std::array<double, 3>& s, const float* x, std::size_t n) noexcept;

// The same with one more term along a second vector: y += s_c x (per lane, pad lane kept) + t w
// (every lane; w's pad lanes are 0). One pass instead of two.
void addScaledByLaneAndScaled(double* y, const std::array<double, 3>& s, const double* x, double t, const double* w,
                              std::size_t n) noexcept;
void addScaledByLaneAndScaled(double* y, const std::array<double, 3>& s, const float* x, double t, const double* w,
                              std::size_t n) noexcept;

// out[i] = a[i] rounded to float, and back (i < n): the implicit guard's float solve.
void toFloat(const double* a, float* out, std::size_t n) noexcept;
void toDouble(const float* a, double* out, std::size_t n) noexcept;

}  // namespace tetrig
