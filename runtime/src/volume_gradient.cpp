// The fine mesh's volume and its gradient in one pass over the triangles, or the volume alone
// (volume_gradient.hpp):
//
//   n_t = (b - a) x (c - a),   6 dV/dv = sum_{t of v} n_t,   6 V = sum_t (a - o) . n_t  (o: any point).
//
// The gradient pass loads a vertex as one 4-lane vector (x, y, z, and the next vertex's x, which the
// cross product drops): three loads, one cross product by shuffles, three 4-lane adds into the
// per-vertex sums, per triangle. The volume-only pass widens every point to (x, y, z, 0) in double
// once, then reads three of those per triangle.
#include "volume_gradient.hpp"

#include <algorithm>
#include <cstring>

#include "multiversion.hpp"
#include "vector_lanes.hpp"

namespace tetrig {
namespace {

// The per-vertex vector types of vector_lanes.hpp, by element type (GCC takes no vector attribute on
// a dependent type).
template <typename T>
struct Vector4;
template <>
struct Vector4<float> {
  using type = lanes::Vec4f;
};
template <>
struct Vector4<double> {
  using type = lanes::Vec4;
};
template <typename T>
using Vec4 = typename Vector4<T>::type;

// Vertex i of x (3 values each) as (x, y, z, w): one 4-lane load, w the next vertex's x, except for
// the last vertex, which has nothing after it (built lane by lane, w = 0; a 12-byte copy into a
// stack vector reloaded whole would stall store forwarding: measured 3x slower). Lane by lane for
// every vertex was 1.15x the time of the whole pass.
template <typename T>
TETRIG_INLINE Vec4<T> loadPoint(const T* x, std::size_t i, std::size_t last) {
  const T* p = x + 3 * i;
  return i != last ? lanes::loadAs<Vec4<T>>(p) : Vec4<T>{p[0], p[1], p[2], T(0)};
}

// (u x v, 0): lane 3 of the inputs is not used.
template <typename V>
TETRIG_INLINE V cross(V u, V v) {
  const V u_yzx = __builtin_shufflevector(u, u, 1, 2, 0, 3), v_yzx = __builtin_shufflevector(v, v, 1, 2, 0, 3);
  const V w = u * v_yzx - u_yzx * v;  // (u x v) in z, x, y order
  return __builtin_shufflevector(w, V{}, 1, 2, 0, 4);
}

template <typename T>
TETRIG_INLINE double pass(std::span<const std::int32_t> triangles, const T* x, T* gradient4, std::int32_t vertex_count) {
  std::memset(gradient4, 0, 4 * sizeof(T) * static_cast<std::size_t>(vertex_count));
  lanes::Vec4 six = {0, 0, 0, 0};
  if (triangles.size() < 3) return 0.0;
  // 6 V = sum_t (a - o) . n_t for any o (sum_t n_t = 0 on a closed mesh): o, a vertex of the mesh,
  // keeps the terms at the mesh's size, not its distance from the origin.
  const std::size_t last_vertex = static_cast<std::size_t>(vertex_count) - 1;
  const Vec4<T> o = loadPoint(x, static_cast<std::size_t>(triangles[0]), last_vertex);
  // (a - o) . n summed in float over runs of kRun triangles (|terms| ~ the mesh's size times a
  // triangle's area), each run's sum then added in double.
  constexpr std::size_t kRun = 32;
  const std::size_t count = triangles.size() / 3;
  for (std::size_t first = 0; first < count; first += kRun) {
    Vec4<T> run = {0, 0, 0, 0};
    const std::size_t last = std::min(count, first + kRun);
    for (std::size_t f = 3 * first; f < 3 * last; f += 3) {
      const std::size_t ia = static_cast<std::size_t>(triangles[f]), ib = static_cast<std::size_t>(triangles[f + 1]),
                        ic = static_cast<std::size_t>(triangles[f + 2]);
      const Vec4<T> a = loadPoint(x, ia, last_vertex), b = loadPoint(x, ib, last_vertex), c = loadPoint(x, ic, last_vertex);
      const Vec4<T> n = cross(b - a, c - a);  // lane 3: 0
      run += (a - o) * n;
      for (const std::size_t i : {ia, ib, ic}) lanes::storeAs(gradient4 + 4 * i, lanes::loadAs<Vec4<T>>(gradient4 + 4 * i) + n);
    }
    six += __builtin_convertvector(run, lanes::Vec4);
  }
  return six[0] + six[1] + six[2];
}

// 6 V alone, every product in double: the volume to ~1e-15 of each term, as the constraint's value
// and the fidelity measures read it. The points are widened to (x, y, z, 0) doubles once each into
// points4 (a vertex is a corner of about six triangles), then each triangle reads three whole vectors.
template <typename T>
TETRIG_INLINE double volumeOnly(std::span<const std::int32_t> triangles, const T* x, std::int32_t vertex_count, double* points4) {
  if (triangles.size() < 3) return 0.0;
  const std::size_t last_vertex = static_cast<std::size_t>(vertex_count) - 1;
  for (std::size_t i = 0; i <= last_vertex; ++i) {
    lanes::Vec4 p = __builtin_convertvector(loadPoint(x, i, last_vertex), lanes::Vec4);
    p[3] = 0.0;
    lanes::store4(points4 + 4 * i, p);
  }
  const auto point = [points4](std::int32_t i) { return lanes::load4(points4 + 4 * static_cast<std::size_t>(i)); };
  const lanes::Vec4 o = point(triangles[0]);
  const auto term = [&](std::size_t f) {
    const lanes::Vec4 a = point(triangles[f]);
    return (a - o) * cross(point(triangles[f + 1]) - a, point(triangles[f + 2]) - a);
  };
  // Four sums, a triangle each in turn: one sum's chain of dependent adds would set the pace.
  lanes::Vec4 six[4] = {};
  const std::size_t count = triangles.size() / 3;
  std::size_t t = 0;
  for (; t + 4 <= count; t += 4)
    for (std::size_t k = 0; k < 4; ++k) six[k] += term(3 * (t + k));
  for (; t < count; ++t) six[0] += term(3 * t);
  const lanes::Vec4 sum = (six[0] + six[1]) + (six[2] + six[3]);
  return sum[0] + sum[1] + sum[2];
}

}  // namespace

TETRIG_MULTIVERSION double volumeGradientPass(std::span<const std::int32_t> triangles, const float* x, float* gradient4,
                                              std::int32_t vertex_count) noexcept {
  return pass(triangles, x, gradient4, vertex_count);
}

TETRIG_MULTIVERSION double volumeGradientPass(std::span<const std::int32_t> triangles, const double* x, double* gradient4,
                                              std::int32_t vertex_count) noexcept {
  return pass(triangles, x, gradient4, vertex_count);
}

TETRIG_MULTIVERSION double volumePass(std::span<const std::int32_t> triangles, const float* x, std::int32_t vertex_count,
                                      double* points4) noexcept {
  return volumeOnly(triangles, x, vertex_count, points4);
}

TETRIG_MULTIVERSION double volumePass(std::span<const std::int32_t> triangles, const double* x, std::int32_t vertex_count,
                                      double* points4) noexcept {
  return volumeOnly(triangles, x, vertex_count, points4);
}

}  // namespace tetrig
