// The fine mesh's enclosed volume as a linear constraint on the tet-mesh positions, its direction
// from the body tets' boundary (tetrig/volume_constraint.hpp has the equations).
#include "tetrig/volume_constraint.hpp"

#include "padded_dot.hpp"
#include "volume_gradient.hpp"

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <utility>

namespace tetrig {
namespace {

// The edges of `triangles` walked forward and backward, each sorted: equal when every edge is walked
// once each way, as often as the other.
std::pair<std::vector<std::uint64_t>, std::vector<std::uint64_t>> sortedEdges(std::span<const std::int32_t> triangles) {
  std::vector<std::uint64_t> forward, backward;
  forward.reserve(triangles.size());
  backward.reserve(triangles.size());
  for (std::size_t f = 0; f + 2 < triangles.size(); f += 3)
    for (std::size_t k = 0; k < 3; ++k) {
      const auto from = static_cast<std::uint32_t>(triangles[f + k]), to = static_cast<std::uint32_t>(triangles[f + (k + 1) % 3]);
      forward.push_back(static_cast<std::uint64_t>(from) << 32 | to);
      backward.push_back(static_cast<std::uint64_t>(to) << 32 | from);
    }
  std::sort(forward.begin(), forward.end());
  std::sort(backward.begin(), backward.end());
  return {std::move(forward), std::move(backward)};
}

// The gradient pass (volume_gradient.hpp) holds on a closed, consistently oriented mesh only (then
// the enclosed volume does not depend on the origin either).
void requireClosedOriented(std::span<const std::int32_t> triangles) {
  const auto [forward, backward] = sortedEdges(triangles);
  const auto [f, b] = std::mismatch(forward.begin(), forward.end(), backward.begin());
  if (f != forward.end()) {
    const std::uint64_t edge = std::min(*f, *b);
    throw std::invalid_argument("volume constraint: the fine mesh is not closed and consistently oriented (edge " +
                                std::to_string(edge >> 32) + " -> " + std::to_string(edge & 0xffffffffu) +
                                " has no matching edge the other way); it needs a watertight surface");
  }
}

}  // namespace

bool closedOrientedSurface(std::span<const std::int32_t> triangles) {
  if (triangles.empty()) return false;
  const auto [forward, backward] = sortedEdges(triangles);
  return forward == backward;
}

FineVolumeConstraint::FineVolumeConstraint(const TetMesh& tet_mesh, std::int32_t body_tets, std::span<const std::int32_t> fine_triangles,
                                           std::span<const double> rest_fine)
    : tet_vertices_(tet_mesh.vertexCount()),
      fine_vertices_(static_cast<std::int32_t>(rest_fine.size() / 3)),
      triangles_(fine_triangles) {
  const Tets& tets = tet_mesh.tets;
  if (tet_vertices_ <= 0 || tets.rows() <= 0) throw std::invalid_argument("volume constraint: empty tet mesh");
  if (body_tets <= 0 || body_tets > tets.rows())
    throw std::invalid_argument("volume constraint: " + std::to_string(body_tets) + " body tets of " + std::to_string(tets.rows()));
  for (Eigen::Index t = 0; t < body_tets; ++t)
    for (int k = 0; k < 4; ++k)
      if (tets(t, k) < 0 || tets(t, k) >= tet_vertices_)
        throw std::invalid_argument("volume constraint: tet corner " + std::to_string(tets(t, k)) + " out of range");
  if (rest_fine.empty() || rest_fine.size() % 3 != 0)
    throw std::invalid_argument("volume constraint: " + std::to_string(rest_fine.size()) + " rest coordinates are no fine positions");
  if (fine_triangles.empty() || fine_triangles.size() % 3 != 0) throw std::invalid_argument("volume constraint: no triangles");
  for (const std::int32_t v : fine_triangles)
    if (v < 0 || v >= fine_vertices_) throw std::invalid_argument("volume constraint: triangle corner " + std::to_string(v) + " out of range");
  requireClosedOriented(fine_triangles);
  boundary_ = boundaryFaces(tet_mesh, body_tets);
  gradient4_.assign(4 * static_cast<std::size_t>(tet_vertices_), 0.0);
  points4_.assign(4 * static_cast<std::size_t>(fine_vertices_), 0.0);
  rest_volume_ = volume(rest_fine.data());
}

template <typename T>
double enclosedVolume(std::span<const std::int32_t> triangles, const T* x) {
  // 6 V = sum (a - o) . ((b - a) x (c - a)) about o, a vertex of the mesh (volume_gradient.hpp).
  if (triangles.size() < 3) return 0.0;
  const std::int32_t vertex_count = *std::max_element(triangles.begin(), triangles.end()) + 1;
  std::vector<double> points4(4 * static_cast<std::size_t>(vertex_count));
  return volumePass(triangles, x, vertex_count, points4.data()) / 6.0;
}

template <typename T>
double FineVolumeConstraint::volume(const T* x_fine) const noexcept {
  return volumePass(triangles_, x_fine, fine_vertices_, points4_.data()) / 6.0;
}

template <typename T>
double FineVolumeConstraint::value(std::span<const double> x_tet, const T* x_fine, std::span<const double> g) const noexcept {
  double g_x = 0.0;
  for (std::size_t i = 0; i < x_tet.size(); ++i) g_x += g[i] * x_tet[i];
  return rest_volume_ - volume(x_fine) + g_x;
}

template <typename T>
double FineVolumeConstraint::linearize(std::span<const double> x_tet, const T* x_fine, std::span<double> g,
                                       double* volume_now) noexcept {
  // g = dW/dx: 6 dW/dx in one pass over the boundary's triangles (volume_gradient.hpp).
  volumeGradientPass(boundaryTriangles(), x_tet.data(), gradient4_.data(), tet_vertices_);
  for (std::size_t v = 0; v < static_cast<std::size_t>(tet_vertices_); ++v)
    for (std::size_t c = 0; c < 3; ++c) g[3 * v + c] = gradient4_[4 * v + c] * (1.0 / 6.0);
  const double now = volume(x_fine);
  if (volume_now != nullptr) *volume_now = now;
  return rest_volume_ - now + dot(g.data(), x_tet.data(), x_tet.size());
}

template double enclosedVolume(std::span<const std::int32_t>, const float*);
template double enclosedVolume(std::span<const std::int32_t>, const double*);
template double FineVolumeConstraint::volume(const float*) const noexcept;
template double FineVolumeConstraint::volume(const double*) const noexcept;
template double FineVolumeConstraint::value(std::span<const double>, const float*, std::span<const double>) const noexcept;
template double FineVolumeConstraint::value(std::span<const double>, const double*, std::span<const double>) const noexcept;
template double FineVolumeConstraint::linearize(std::span<const double>, const float*, std::span<double>, double*) noexcept;
template double FineVolumeConstraint::linearize(std::span<const double>, const double*, std::span<double>, double*) noexcept;

}  // namespace tetrig
