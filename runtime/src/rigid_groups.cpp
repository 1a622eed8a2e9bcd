// Rigid groups: Stoll et al. 2007, 2.3.2. Average = closest rotation to the weighted sum of rotations.
#include "tetrig/rigid_groups.hpp"

#include "tetrig/polar.hpp"

namespace tetrig {

void applyRigidGroups(std::span<const std::int32_t> group_start, std::span<const std::int32_t> group_slot,
                      TetBlock* blocks) {
  constexpr int W = kTetBlockWidth;
  for (size_t g = 0; g + 1 < group_start.size(); ++g) {
    Eigen::Matrix3d sum = Eigen::Matrix3d::Zero();
    for (auto i = group_start[g]; i < group_start[g + 1]; ++i) {
      const std::int32_t s = group_slot[static_cast<size_t>(i)];
      const TetBlock& block = blocks[s / W];
      const int l = s % W;
      const Eigen::Quaterniond q(block.rotation[0][l], block.rotation[1][l], block.rotation[2][l], block.rotation[3][l]);
      sum += block.weight[l] * q.toRotationMatrix();
    }
    const Eigen::Quaterniond average = closestRotation(sum);
    for (auto i = group_start[g]; i < group_start[g + 1]; ++i) {
      const std::int32_t s = group_slot[static_cast<size_t>(i)];
      TetBlock& block = blocks[s / W];
      const int l = s % W;
      block.rotation[0][l] = static_cast<float>(average.w());
      block.rotation[1][l] = static_cast<float>(average.x());
      block.rotation[2][l] = static_cast<float>(average.y());
      block.rotation[3][l] = static_cast<float>(average.z());
    }
  }
}

}  // namespace tetrig
