// The plausibility bound on a published pose: see tetrig/pose_bound.hpp.
#include "tetrig/pose_bound.hpp"

#include <algorithm>
#include <cmath>

namespace tetrig {
namespace {

// Median of v[0, n) (n > 0), reordering it: the middle value, or the mean of the two middle ones.
double median(double* v, std::size_t n) noexcept {
  double* mid = v + n / 2;
  std::nth_element(v, mid, v + n);
  if (n % 2 == 1) return *mid;
  return 0.5 * (*std::max_element(v, mid) + *mid);
}

}  // namespace

PoseBound::PoseBound(double rest_diagonal, double max_abs_coordinate, std::size_t capacity)
    : reach_(kPoseBoundReach * rest_diagonal), max_abs_(max_abs_coordinate) {
  for (std::vector<double>& a : axis_) a.assign(capacity, 0.0);
  beginTargets();
}

void PoseBound::beginTargets() noexcept {
  count_ = 0;
  centre_.setZero();
  low_ = Eigen::Vector3d::Constant(-max_abs_);
  high_ = Eigen::Vector3d::Constant(max_abs_);
}

void PoseBound::addTarget(const Eigen::Vector3d& p) noexcept {
  if (!p.allFinite() || count_ >= axis_[0].size()) return;
  for (int c = 0; c < 3; ++c) axis_[c][count_] = p[c];
  ++count_;
}

void PoseBound::endTargets() noexcept {
  if (count_ == 0) {
    beginTargets();
    return;
  }
  for (int c = 0; c < 3; ++c) {
    centre_[c] = median(axis_[c].data(), count_);
    low_[c] = std::max(centre_[c] - reach_, -max_abs_);
    high_[c] = std::min(centre_[c] + reach_, max_abs_);
  }
}

bool PoseBound::accepts(const float* xyz, std::size_t floats) const noexcept {
  // The box's bounds repeated along a block whose length is a multiple of 3 (x, y, z) and of the
  // SIMD width, so the test runs over contiguous floats (6890 vertices: about 5 us, where a test
  // per vertex and axis took 30). A NaN fails both comparisons; +-inf lies outside any finite box.
  constexpr std::size_t kBlock = 48;
  float lo[kBlock], hi[kBlock];
  for (std::size_t j = 0; j < kBlock; ++j) {
    lo[j] = static_cast<float>(low_[static_cast<Eigen::Index>(j % 3)]);
    hi[j] = static_cast<float>(high_[static_cast<Eigen::Index>(j % 3)]);
  }
  int inside = floats % 3 == 0 ? 1 : 0;
  std::size_t i = 0;
  for (; i + kBlock <= floats; i += kBlock) {
    int block = 1;
    for (std::size_t j = 0; j < kBlock; ++j) block &= static_cast<int>(lo[j] <= xyz[i + j]) & static_cast<int>(xyz[i + j] <= hi[j]);
    inside &= block;
  }
  for (std::size_t j = 0; i + j < floats; ++j) inside &= static_cast<int>(lo[j] <= xyz[i + j]) & static_cast<int>(xyz[i + j] <= hi[j]);
  return inside != 0;
}

}  // namespace tetrig
