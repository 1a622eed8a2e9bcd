// Tests for the plausibility bound on a published pose (runtime/src/pose_bound.cpp): a pose is
// accepted within kPoseBoundReach rest diagonals of its targets' per-axis median along each axis and
// within the absolute coordinate bound, and rejected just beyond either, or with any non-finite
// coordinate; a few far targets do not widen the box.
#include "tetrig/pose_bound.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <vector>

namespace tetrig {
namespace {

constexpr double kDiagonal = 2.0;  // rest diagonal: the reach is kPoseBoundReach * 2 = 4 units
constexpr std::size_t kCapacity = 16;

PoseBound boundAround(const std::vector<Eigen::Vector3d>& targets, double max_abs = 1e6) {
  PoseBound bound(kDiagonal, max_abs, kCapacity);
  bound.beginTargets();
  for (const auto& p : targets) bound.addTarget(p);
  bound.endTargets();
  return bound;
}

std::vector<float> pose(std::initializer_list<Eigen::Vector3d> points) {
  std::vector<float> xyz;
  for (const auto& p : points)
    for (int c = 0; c < 3; ++c) xyz.push_back(static_cast<float>(p[c]));
  return xyz;
}

TEST(PoseBound, TheBoxIsTheTargetsMedianGrownByTheReachOnEverySide) {
  const PoseBound bound = boundAround({{100, 0, -5}, {103, 4, -5}, {101, 1, 10}});
  const double r = kPoseBoundReach * kDiagonal;
  EXPECT_TRUE(bound.centre().isApprox(Eigen::Vector3d(101, 1, -5)));
  EXPECT_TRUE(bound.low().isApprox(Eigen::Vector3d(101 - r, 1 - r, -5 - r)));
  EXPECT_TRUE(bound.high().isApprox(Eigen::Vector3d(101 + r, 1 + r, -5 + r)));
  // Every face of the box: just inside accepted, just outside rejected (one vertex is enough).
  for (int axis = 0; axis < 3; ++axis) {
    for (const bool upper : {false, true}) {
      Eigen::Vector3d face = 0.5 * (bound.low() + bound.high());
      face[axis] = upper ? bound.high()[axis] : bound.low()[axis];
      const Eigen::Vector3d inward = (upper ? -0.01 : 0.01) * Eigen::Vector3d::Unit(axis);
      const Eigen::Vector3d centre(101, 1, -5);
      EXPECT_TRUE(bound.accepts(pose({centre, face + inward}).data(), 6)) << "axis " << axis << (upper ? " high" : " low");
      EXPECT_FALSE(bound.accepts(pose({centre, face - inward}).data(), 6)) << "axis " << axis << (upper ? " high" : " low");
    }
  }
  // An even count: the mean of the two middle values.
  const PoseBound even = boundAround({{0, 0, 0}, {1, 2, 3}, {3, 6, 9}, {10, 20, 30}});
  EXPECT_TRUE(even.centre().isApprox(Eigen::Vector3d(2, 4, 6)));
}

// A pose dragged away from the body by a few far targets (a marker thrown 100 units) is refused:
// the median stays where most targets are, where a box around all of them would reach the far one.
TEST(PoseBound, AFewFarTargetsDoNotWidenTheBox) {
  std::vector<Eigen::Vector3d> targets;
  for (int k = 0; k < 9; ++k) targets.emplace_back(0.1 * k, 0.2 * k, -0.1 * k);
  targets.emplace_back(100, 0, 0);
  targets.emplace_back(0, -100, 50);
  const PoseBound bound = boundAround(targets);
  EXPECT_LT(bound.centre().norm(), 1.0);
  EXPECT_TRUE(bound.accepts(pose({{0, 0, 0}, {1, 1.5, -1}, {3.5, 0, 0}}).data(), 9)) << "the body around its markers";
  EXPECT_FALSE(bound.accepts(pose({{0, 0, 0}, {5, 0, 0}}).data(), 6)) << "a vertex pulled towards the far marker";
  EXPECT_FALSE(bound.accepts(pose({{0, 0, 0}, {99, 0, 0}}).data(), 6));
}

TEST(PoseBound, TargetsBeyondTheCapacityAreIgnored) {
  PoseBound bound(kDiagonal, 1e6, 3);
  bound.beginTargets();
  for (int k = 0; k < 3; ++k) bound.addTarget({0, 0, 0});
  bound.addTarget({1000, 1000, 1000});
  bound.addTarget({1000, 1000, 1000});
  bound.endTargets();
  EXPECT_EQ(bound.centre(), Eigen::Vector3d::Zero());
}

TEST(PoseBound, NonFiniteCoordinatesAreRejected) {
  const PoseBound bound = boundAround({{0, 0, 0}, {1, 1, 1}});
  for (const float bad : {std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::infinity(),
                          -std::numeric_limits<float>::infinity()}) {
    for (int c = 0; c < 6; ++c) {
      std::vector<float> xyz = pose({{0.5, 0.5, 0.5}, {0.2, 0.3, 0.4}});
      ASSERT_TRUE(bound.accepts(xyz.data(), xyz.size()));
      xyz[static_cast<std::size_t>(c)] = bad;
      EXPECT_FALSE(bound.accepts(xyz.data(), xyz.size())) << "coordinate " << c << " = " << bad;
    }
  }
}

TEST(PoseBound, TheAbsoluteBoundCapsTheBoxAndAppliesWithoutTargets) {
  // Targets near the absolute bound: the margin does not reach past it.
  const PoseBound near_limit = boundAround({{9, 0, 0}, {9.5, 1, 1}}, 10.0);
  EXPECT_DOUBLE_EQ(near_limit.high().x(), 10.0);
  EXPECT_TRUE(near_limit.accepts(pose({{9.9, 0.5, 0.5}}).data(), 3));
  EXPECT_FALSE(near_limit.accepts(pose({{10.1, 0.5, 0.5}}).data(), 3));
  // No target (a rig without handles): only finite and |c| <= max_abs.
  PoseBound none(kDiagonal, 10.0, kCapacity);
  none.beginTargets();
  none.endTargets();
  EXPECT_TRUE(none.accepts(pose({{-9.9, 9.9, 0}}).data(), 3));
  EXPECT_FALSE(none.accepts(pose({{-10.1, 0, 0}}).data(), 3));
  // A non-finite target is ignored rather than widening (or poisoning) the box.
  PoseBound ignored(kDiagonal, 1e6, kCapacity);
  ignored.beginTargets();
  ignored.addTarget({0, 0, 0});
  ignored.addTarget({std::numeric_limits<double>::quiet_NaN(), 0, 0});
  ignored.addTarget({std::numeric_limits<double>::infinity(), 0, 0});
  ignored.endTargets();
  EXPECT_DOUBLE_EQ(ignored.high().x(), kPoseBoundReach * kDiagonal);
  EXPECT_FALSE(ignored.accepts(pose({{100, 0, 0}}).data(), 3));
}

TEST(PoseBound, EachFrameStartsAFreshBox) {
  PoseBound bound(kDiagonal, 1e6, kCapacity);
  bound.beginTargets();
  bound.addTarget({1000, 0, 0});
  bound.endTargets();
  EXPECT_TRUE(bound.accepts(pose({{1000, 1, 1}}).data(), 3));
  bound.beginTargets();
  bound.addTarget({0, 0, 0});
  bound.endTargets();
  EXPECT_FALSE(bound.accepts(pose({{1000, 1, 1}}).data(), 3)) << "last frame's targets must not widen this frame's box";
  EXPECT_TRUE(bound.accepts(pose({{1, 1, 1}}).data(), 3));
}

}  // namespace
}  // namespace tetrig
