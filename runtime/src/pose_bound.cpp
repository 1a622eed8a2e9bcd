// The plausibility bound on a published pose: see tetrig/pose_bound.hpp.
#include "tetrig/pose_bound.hpp"

#include <algorithm>
#include <cmath>

namespace tetrig {

PoseBound::PoseBound(double rest_diagonal, double max_abs_coordinate) noexcept
    : margin_(kPoseBoundMargin * rest_diagonal), max_abs_(max_abs_coordinate) {}

void PoseBound::beginTargets() noexcept { any_ = false; }

void PoseBound::addTarget(const Eigen::Vector3d& p) noexcept {
  if (!p.allFinite()) return;
  if (!any_) {
    lo_ = hi_ = p;
    any_ = true;
    return;
  }
  lo_ = lo_.cwiseMin(p);
  hi_ = hi_.cwiseMax(p);
}

Eigen::Vector3d PoseBound::low() const noexcept {
  const Eigen::Vector3d limit = Eigen::Vector3d::Constant(-max_abs_);
  return any_ ? Eigen::Vector3d((lo_.array() - margin_).max(limit.array())) : limit;
}

Eigen::Vector3d PoseBound::high() const noexcept {
  const Eigen::Vector3d limit = Eigen::Vector3d::Constant(max_abs_);
  return any_ ? Eigen::Vector3d((hi_.array() + margin_).min(limit.array())) : limit;
}

bool PoseBound::accepts(const float* xyz, std::size_t floats) const noexcept {
  // The box's bounds repeated along a block whose length is a multiple of 3 (x, y, z) and of the
  // SIMD width, so the test runs over contiguous floats (6890 vertices: about 5 us, where a test
  // per vertex and axis took 30). A NaN fails both comparisons; +-inf lies outside any finite box.
  constexpr std::size_t kBlock = 48;
  const Eigen::Vector3d low3 = low(), high3 = high();
  float lo[kBlock], hi[kBlock];
  for (std::size_t j = 0; j < kBlock; ++j) {
    lo[j] = static_cast<float>(low3[static_cast<Eigen::Index>(j % 3)]);
    hi[j] = static_cast<float>(high3[static_cast<Eigen::Index>(j % 3)]);
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
