// The fine mesh's enclosed volume as a linear constraint on the tet-mesh positions
// (tetrig/volume_constraint.hpp has the equations).
#include "tetrig/volume_constraint.hpp"
#include "tetrig/pose_transfer_padded.hpp"

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

FineVolumeConstraint::FineVolumeConstraint(const PoseTransferView<double>& b, std::span<const std::int32_t> triangles,
                                           std::span<const double> rest_fine, std::int32_t gradient_entries)
    : tet_vertices_(b.cols), fine_vertices_(b.rows), triangles_(triangles) {
  if (gradient_entries < 0) throw std::invalid_argument("volume constraint: a negative number of gradient entries per row");
  if (b.rows <= 0 || b.cols <= 0) throw std::invalid_argument("volume constraint: empty pose transfer");
  if (triangles.empty() || triangles.size() % 3 != 0) throw std::invalid_argument("volume constraint: no triangles");
  if (rest_fine.size() != 3 * static_cast<std::size_t>(b.rows))
    throw std::invalid_argument("volume constraint: " + std::to_string(rest_fine.size() / 3) + " rest positions for " +
                                std::to_string(b.rows) + " fine vertices");
  for (const std::int32_t v : triangles)
    if (v < 0 || v >= b.rows) throw std::invalid_argument("volume constraint: triangle corner " + std::to_string(v) + " out of range");
  requireClosedOriented(triangles);
  fine_gradient4_.assign(4 * static_cast<std::size_t>(b.rows), 0.0);
  fine_gradient4f_.assign(4 * static_cast<std::size_t>(b.rows), 0.0f);
  rest_volume_ = volume(rest_fine.data());
  // The entries of B that g uses: all, or per row the gradient_entries largest weights rescaled to
  // the row's sum.
  std::vector<std::int32_t> kept_offsets(static_cast<std::size_t>(b.rows) + 1, 0), kept_columns;
  std::vector<double> kept_weights;
  std::vector<std::int32_t> order;
  for (std::int32_t r = 0; r < b.rows; ++r) {
    const std::int32_t begin = b.row_offsets[r], end = b.row_offsets[r + 1];
    order.resize(static_cast<std::size_t>(end - begin));
    for (std::int32_t k = begin; k < end; ++k) {
      if (b.columns[k] < 0 || b.columns[k] >= b.cols) throw std::invalid_argument("volume constraint: pose-transfer column out of range");
      order[static_cast<std::size_t>(k - begin)] = k;
    }
    double row_sum = 0.0, kept_sum = 0.0;
    for (std::int32_t k = begin; k < end; ++k) row_sum += b.weights[k];
    if (gradient_entries > 0 && static_cast<std::int32_t>(order.size()) > gradient_entries) {
      std::partial_sort(order.begin(), order.begin() + gradient_entries, order.end(),
                        [&](std::int32_t x, std::int32_t y) { return b.weights[x] > b.weights[y]; });
      order.resize(static_cast<std::size_t>(gradient_entries));
    }
    for (const std::int32_t k : order) kept_sum += b.weights[k];
    const double scale = kept_sum != 0.0 ? row_sum / kept_sum : 1.0;
    for (const std::int32_t k : order) {
      kept_columns.push_back(b.columns[k]);
      kept_weights.push_back(b.weights[k] * scale);
    }
    kept_offsets[static_cast<std::size_t>(r) + 1] = static_cast<std::int32_t>(kept_columns.size());
  }
  // Their transpose: count the entries per column, then place them (rows ascending within a column).
  PoseTransferCsr<double> bt;
  bt.rows = b.cols;
  bt.cols = b.rows;
  bt.row_offsets.assign(static_cast<std::size_t>(b.cols) + 1, 0);
  for (const std::int32_t c : kept_columns) ++bt.row_offsets[static_cast<std::size_t>(c) + 1];
  for (std::size_t j = 0; j < static_cast<std::size_t>(b.cols); ++j) bt.row_offsets[j + 1] += bt.row_offsets[j];
  bt.columns.resize(kept_columns.size());
  bt.weights.resize(kept_columns.size());
  std::vector<std::int32_t> next(bt.row_offsets.begin(), bt.row_offsets.end() - 1);
  for (std::int32_t r = 0; r < b.rows; ++r)
    for (std::int32_t k = kept_offsets[static_cast<std::size_t>(r)]; k < kept_offsets[static_cast<std::size_t>(r) + 1]; ++k) {
      const auto at = static_cast<std::size_t>(next[static_cast<std::size_t>(kept_columns[static_cast<std::size_t>(k)])]++);
      bt.columns[at] = r;
      bt.weights[at] = kept_weights[static_cast<std::size_t>(k)];
    }
  if (fitsCompactPoseTransfer(bt.cols)) {
    // Each tet vertex placed where it acts: the |B|-weighted mean of the fine vertices it moves (its
    // row of B^T), for the blocks' grouping by place.
    std::vector<double> where(3 * static_cast<std::size_t>(bt.rows), 0.0);
    for (std::int32_t j = 0; j < bt.rows; ++j) {
      double total = 0.0;
      for (std::int32_t k = bt.row_offsets[static_cast<std::size_t>(j)]; k < bt.row_offsets[static_cast<std::size_t>(j) + 1]; ++k) {
        const double w = std::abs(bt.weights[static_cast<std::size_t>(k)]);
        total += w;
        for (std::size_t c = 0; c < 3; ++c)
          where[3 * static_cast<std::size_t>(j) + c] += w * rest_fine[3 * static_cast<std::size_t>(bt.columns[static_cast<std::size_t>(k)]) + c];
      }
      if (total > 0.0)
        for (std::size_t c = 0; c < 3; ++c) where[3 * static_cast<std::size_t>(j) + c] /= total;
    }
    bt_blocked_ = blockPoseTransfer(bt, where);
    // g is a direction (the constraint's value comes from the measured volume): weights to 11 bits
    // tilt it by ~2^-11 and halve the bytes the gather streams.
    bt_blocked_.toHalfWeights();
    tet_gradient3f_.assign(3 * static_cast<std::size_t>(b.cols), 0.0f);
  } else {
    bt_wide_.rows = bt.rows;
    bt_wide_.cols = bt.cols;
    bt_wide_.row_offsets = std::move(bt.row_offsets);
    bt_wide_.columns = std::move(bt.columns);
    bt_wide_.weights.assign(bt.weights.begin(), bt.weights.end());
  }
}

template <typename T>
double enclosedVolume(std::span<const std::int32_t> triangles, const T* x) noexcept {
  double six = 0.0;
  for (std::size_t f = 0; f + 2 < triangles.size(); f += 3) {
    const auto p = [&](std::size_t k) {
      const T* q = x + 3 * static_cast<std::size_t>(triangles[f + k]);
      return Eigen::Vector3d(q[0], q[1], q[2]);
    };
    six += p(0).dot(p(1).cross(p(2)));
  }
  return six / 6.0;
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
  // 6 dV/dx_fine and 6 V: one pass over the triangles (volume_gradient.hpp), in the fine pose's type.
  constexpr bool kFloat = std::is_same_v<T, float>;
  T* gradient4 = nullptr;
  if constexpr (kFloat)
    gradient4 = fine_gradient4f_.data();
  else
    gradient4 = fine_gradient4_.data();
  const double six = volumeGradientPass(triangles_, x_fine, gradient4, fine_vertices_);
  // g = B^T dV/dx_fine (a gather per tet vertex: the pose transfer's kernels), and g . x0.
  if (bt_blocked_.rows > 0) {
    if (!kFloat)
      for (std::size_t i = 0; i < fine_gradient4_.size(); ++i) fine_gradient4f_[i] = static_cast<float>(fine_gradient4_[i]);
    applyPoseTransferBlocked(bt_blocked_.view(), fine_gradient4f_.data(), tet_gradient3f_.data());
    for (std::size_t i = 0; i < g.size(); ++i) g[i] = static_cast<double>(tet_gradient3f_[i]);
  } else {
    if (kFloat)
      for (std::size_t i = 0; i < fine_gradient4_.size(); ++i) fine_gradient4_[i] = static_cast<double>(fine_gradient4f_[i]);
    applyPoseTransferPadded(bt_wide_.view(), fine_gradient4_.data(), g.data());
  }
  for (double& v : g) v *= 1.0 / 6.0;
  const double g_x0 = dot(g.data(), x_tet.data(), x_tet.size());
  const double now = six / 6.0;
  if (volume_now != nullptr) *volume_now = now;
  return rest_volume_ - now + g_x0;
}

template double enclosedVolume(std::span<const std::int32_t>, const float*) noexcept;
template double enclosedVolume(std::span<const std::int32_t>, const double*) noexcept;
template double FineVolumeConstraint::value(std::span<const double>, const float*, std::span<const double>) const noexcept;
template double FineVolumeConstraint::linearize(std::span<const double>, const float*, std::span<double>, double*) noexcept;
template double FineVolumeConstraint::linearize(std::span<const double>, const double*, std::span<double>, double*) noexcept;

}  // namespace tetrig
