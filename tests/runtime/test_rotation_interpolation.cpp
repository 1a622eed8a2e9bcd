// applyRotationIncrements (the per-frame blend of relative handle rotations, 8 slots per vector)
// against a scalar Eigen reference.
#include "tetrig/rotation_interpolation.hpp"

#include <gtest/gtest.h>

#include <random>
#include <vector>

namespace tetrig {
namespace {

Eigen::Quaterniond slotRotation(const std::vector<TetBlock>& blocks, int s) {
  const TetBlock& b = blocks[static_cast<size_t>(s / kTetBlockWidth)];
  const int l = s % kTetBlockWidth;
  return {b.rotation[0][l], b.rotation[1][l], b.rotation[2][l], b.rotation[3][l]};
}

TEST(RotationIncrements, BlendEachSlotLikeTheScalarReference) {
  constexpr int kBlocks = 5, kSlots = kBlocks * kTetBlockWidth;
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  std::vector<TetBlock> blocks(kBlocks);
  std::vector<Eigen::Quaterniond> before;
  for (int s = 0; s < kSlots; ++s) {
    const Eigen::Quaterniond q = Eigen::Quaterniond::UnitRandom();
    TetBlock& b = blocks[static_cast<size_t>(s / kTetBlockWidth)];
    const int l = s % kTetBlockWidth;
    b.rotation[0][l] = static_cast<float>(q.w());
    b.rotation[1][l] = static_cast<float>(q.x());
    b.rotation[2][l] = static_cast<float>(q.y());
    b.rotation[3][l] = static_cast<float>(q.z());
    before.push_back(slotRotation(blocks, s));  // as stored (float)
  }
  const std::vector<Eigen::Quaterniond> increments = {
      Eigen::Quaterniond(Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized())),
      Eigen::Quaterniond(Eigen::AngleAxisd(2.0, Eigen::Vector3d(-1, 0, 1).normalized()))};
  std::vector<double> weights(2 * kSlots);
  for (int s = 0; s < kSlots; ++s) {
    weights[static_cast<size_t>(s)] = unit(rng);
    weights[static_cast<size_t>(kSlots + s)] = unit(rng) * (1.0 - weights[static_cast<size_t>(s)]);
  }
  weights[3] = 1.0;  // slot 3: fully the first handle, then also some of the second (sum > 1)
  weights[kSlots + 3] = 0.4;
  applyRotationIncrements(weights, increments, blocks.data(), kSlots);
  for (int s = 0; s < kSlots; ++s) {
    const double w1 = weights[static_cast<size_t>(s)], w2 = weights[static_cast<size_t>(kSlots + s)];
    Eigen::Vector4d blend = w1 * increments[0].coeffs() + w2 * increments[1].coeffs();  // (x, y, z, w)
    blend[3] += std::max(0.0, 1.0 - w1 - w2);
    const Eigen::Quaterniond inc(blend.normalized());
    const Eigen::Quaterniond expected = inc * before[static_cast<size_t>(s)];
    // The blend runs in double; the result is stored in float (2^-24 per component).
    EXPECT_LT((slotRotation(blocks, s).coeffs() - expected.coeffs()).norm(), 3e-7) << "slot " << s;
  }
}

TEST(RotationIncrements, AVanishingBlendKeepsTheRotation) {
  std::vector<TetBlock> blocks(1);
  const Eigen::Quaterniond q(Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitZ()));
  for (int l = 0; l < kTetBlockWidth; ++l) {
    blocks[0].rotation[0][l] = static_cast<float>(q.w());
    blocks[0].rotation[1][l] = static_cast<float>(q.x());
    blocks[0].rotation[2][l] = static_cast<float>(q.y());
    blocks[0].rotation[3][l] = static_cast<float>(q.z());
  }
  // Half-turns about +x and -x, half each: the blend is the zero quaternion (no direction).
  const std::vector<Eigen::Quaterniond> increments = {Eigen::Quaterniond(0, 1, 0, 0), Eigen::Quaterniond(0, -1, 0, 0)};
  std::vector<double> weights(2 * kTetBlockWidth, 0.5);
  weights[0] = 1.0;  // lane 0: fully the first half-turn
  weights[kTetBlockWidth] = 0.0;
  const Eigen::Quaterniond stored = slotRotation(blocks, 1);  // q rounded to float
  applyRotationIncrements(weights, increments, blocks.data(), kTetBlockWidth);
  EXPECT_LT((slotRotation(blocks, 0).coeffs() - (increments[0] * stored).coeffs()).norm(), 3e-7);
  for (int l = 1; l < kTetBlockWidth; ++l) {
    EXPECT_EQ(slotRotation(blocks, l).coeffs(), stored.coeffs()) << "lane " << l;
  }
}

}  // namespace
}  // namespace tetrig
