// The fine mesh's enclosed volume as a linear constraint on the tet-mesh positions
// (tetrig/volume_constraint.hpp has the equations).
#include "tetrig/volume_constraint.hpp"

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <algorithm>
#include <stdexcept>
#include <string>
#include <utility>

namespace tetrig {

FineVolumeConstraint::FineVolumeConstraint(const PoseTransferView<double>& b, std::span<const std::int32_t> triangles,
                                           std::span<const double> rest_fine)
    : tet_vertices_(b.cols), fine_vertices_(b.rows), triangles_(triangles) {
  if (b.rows <= 0 || b.cols <= 0) throw std::invalid_argument("volume constraint: empty pose transfer");
  if (triangles.empty() || triangles.size() % 3 != 0) throw std::invalid_argument("volume constraint: no triangles");
  if (rest_fine.size() != 3 * static_cast<std::size_t>(b.rows))
    throw std::invalid_argument("volume constraint: " + std::to_string(rest_fine.size() / 3) + " rest positions for " +
                                std::to_string(b.rows) + " fine vertices");
  for (const std::int32_t v : triangles)
    if (v < 0 || v >= b.rows) throw std::invalid_argument("volume constraint: triangle corner " + std::to_string(v) + " out of range");
  fine_gradient4_.assign(4 * static_cast<std::size_t>(b.rows), 0.0);
  rest_volume_ = volume(rest_fine.data());
  // B^T: count the entries per column, then place them (rows ascending within a column).
  PoseTransferCsr<double> bt;
  bt.rows = b.cols;
  bt.cols = b.rows;
  bt.row_offsets.assign(static_cast<std::size_t>(b.cols) + 1, 0);
  const std::int32_t entries = b.row_offsets[b.rows];
  for (std::int32_t k = 0; k < entries; ++k) {
    if (b.columns[k] < 0 || b.columns[k] >= b.cols) throw std::invalid_argument("volume constraint: pose-transfer column out of range");
    ++bt.row_offsets[static_cast<std::size_t>(b.columns[k]) + 1];
  }
  for (std::size_t j = 0; j < static_cast<std::size_t>(b.cols); ++j) bt.row_offsets[j + 1] += bt.row_offsets[j];
  bt.columns.resize(static_cast<std::size_t>(entries));
  bt.weights.resize(static_cast<std::size_t>(entries));
  std::vector<std::int32_t> next(bt.row_offsets.begin(), bt.row_offsets.end() - 1);
  for (std::int32_t r = 0; r < b.rows; ++r)
    for (std::int32_t k = b.row_offsets[r]; k < b.row_offsets[r + 1]; ++k) {
      const auto at = static_cast<std::size_t>(next[static_cast<std::size_t>(b.columns[k])]++);
      bt.columns[at] = r;
      bt.weights[at] = b.weights[k];
    }
  if (fitsCompactPoseTransfer(bt.cols)) {
    bt_compact_ = narrowPoseTransfer(bt);
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
  // dV/dx_fine: 1/6 (b x c) at a, cyclically.
  std::fill(fine_gradient4_.begin(), fine_gradient4_.end(), 0.0);
  double six = 0.0;
  for (std::size_t f = 0; f < triangles_.size(); f += 3) {
    Eigen::Vector3d p[3];
    for (std::size_t k = 0; k < 3; ++k) {
      const T* q = x_fine + 3 * static_cast<std::size_t>(triangles_[f + k]);
      p[k] = Eigen::Vector3d(q[0], q[1], q[2]);
    }
    six += p[0].dot(p[1].cross(p[2]));
    for (std::size_t k = 0; k < 3; ++k) {
      const Eigen::Vector3d d = p[(k + 1) % 3].cross(p[(k + 2) % 3]);
      double* out = &fine_gradient4_[4 * static_cast<std::size_t>(triangles_[f + k])];
      for (int c = 0; c < 3; ++c) out[c] += d[c] / 6.0;
    }
  }
  // g = B^T dV/dx_fine (a gather per tet vertex: the pose transfer's padded kernel), and g . x0.
  if (bt_compact_.rows > 0) {
    applyPoseTransferPadded(bt_compact_.view(), fine_gradient4_.data(), g.data());
  } else {
    applyPoseTransferPadded(bt_wide_.view(), fine_gradient4_.data(), g.data());
  }
  double g_x0 = 0.0;
  for (std::size_t i = 0; i < x_tet.size(); ++i) g_x0 += g[i] * x_tet[i];
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
