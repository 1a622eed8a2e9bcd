// The fine mesh's volume and its gradient in one pass over the triangles (private to runtime/src;
// FineVolumeConstraint::linearize, docs/deformation.md "Volume constraint").
//
// For a closed, consistently oriented triangle mesh,
//   6 V = sum_{triangles (a, b, c)} a . (b x c),   6 dV/dv = sum_{triangles t of v} (b_t x c_t)
// with (v, b_t, c_t) the corners of t in order from v. Each triangle's area vector
//   n = (b - a) x (c - a) = b x c + c x a + a x b
// is the same from each of its corners, and around v's closed ring the extra terms
// v x (b_t - c_t) cancel (each ring edge is walked once each way), so
//   6 dV/dv = sum_{t of v} n_t,   6 V = sum_t a_t . n_t   (a . (c x a) = a . (a x b) = 0).
// One cross product of two short edges per triangle instead of three of whole positions: no
// cancellation (|n| ~ the triangle's area, not |x|^2), so float sums hold ~1e-7 of each ring's area.
#pragma once

#include <cstdint>
#include <span>

namespace tetrig {

// x: #V*3 positions. gradient4: #V*4 (x, y, z, pad), overwritten with 6 dV/dx (pad 0). Returns 6 V,
// summed in double. `triangles` must hold indices below vertex_count (checked by the caller, once).
// No allocation.
double volumeGradientPass(std::span<const std::int32_t> triangles, const float* x, float* gradient4,
                          std::int32_t vertex_count) noexcept;
double volumeGradientPass(std::span<const std::int32_t> triangles, const double* x, double* gradient4,
                          std::int32_t vertex_count) noexcept;
// The same 6 V without the gradient (enclosedVolume's kernel), every product in double. points4:
// vertex_count*4 scratch (overwritten with the points widened to (x, y, z, 0)).
double volumePass(std::span<const std::int32_t> triangles, const float* x, std::int32_t vertex_count, double* points4) noexcept;
double volumePass(std::span<const std::int32_t> triangles, const double* x, std::int32_t vertex_count, double* points4) noexcept;

}  // namespace tetrig
