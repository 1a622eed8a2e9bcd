// Rigid marker groups found from a clip's geometry (tetrig/rigbuild/rigid_marker_groups.hpp), on
// the default character's performance, whose markers are each fixed to one bone: markers of one
// bone keep their distances exactly, markers across a joint that bends do not.
#include "tetrig/drivers/character_performance.hpp"
#include "tetrig/rigbuild/rigid_marker_groups.hpp"

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include <map>
#include <random>
#include <set>

namespace tetrig::rigbuild {
namespace {

namespace dr = tetrig::drivers;

constexpr std::int64_t kFrames = 1152;  // the performance at 120 Hz

Eigen::Vector3d toVec(const dr::CharacterVec3& p) { return {p[0], p[1], p[2]}; }

// The performance as a clip: frame f at f / 120 s. `noise_mm`: uniform noise on every sample;
// `slide`: a marker whose position slides along a bone axis by up to 40 mm over the clip.
MarkerFrameReader performance(double noise_mm = 0.0, int slide = -1) {
  return [noise_mm, slide](std::int64_t f, std::vector<Eigen::Vector3d>& x, std::vector<std::uint8_t>& valid) {
    std::array<dr::CharacterVec3, dr::kCharacterMarkerCount> m;
    dr::characterMarkersAt(static_cast<double>(f) / 120.0, m);
    std::mt19937 rng(static_cast<std::uint32_t>(f));
    std::uniform_real_distribution<double> u(-noise_mm, noise_mm);
    for (int i = 0; i < dr::kCharacterMarkerCount; ++i) {
      x[static_cast<std::size_t>(i)] = toVec(m[static_cast<std::size_t>(i)]) + Eigen::Vector3d(u(rng), u(rng), u(rng));
      valid[static_cast<std::size_t>(i)] = 1;
    }
    if (slide >= 0) x[static_cast<std::size_t>(slide)].z() += 40.0 * std::sin(static_cast<double>(f) * 0.02);
  };
}

// The largest angle of bone a's rotation relative to bone b's over the performance (degrees).
double largestRelativeTurnDeg(int a, int b) {
  double largest = 0.0;
  dr::CharacterPose pose;
  for (std::int64_t f = 0; f < kFrames; f += 4) {
    dr::characterPoseAt(static_cast<double>(f) / 120.0, pose);
    const Eigen::Matrix3d ra = Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(pose.rotation[static_cast<std::size_t>(a)].data());
    const Eigen::Matrix3d rb = Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(pose.rotation[static_cast<std::size_t>(b)].data());
    const double c = std::clamp(((rb.transpose() * ra).trace() - 1.0) / 2.0, -1.0, 1.0);
    largest = std::max(largest, std::acos(c) * 180.0 / M_PI);
  }
  return largest;
}

std::vector<Eigen::Vector3d> restPositions() {
  std::vector<Eigen::Vector3d> rest;
  for (const dr::CharacterMarker& m : dr::characterMarkers()) rest.push_back(toVec(m.tpose));
  return rest;
}

int markerIndex(std::string_view label) {
  const auto markers = dr::characterMarkers();
  for (int i = 0; i < dr::kCharacterMarkerCount; ++i) {
    if (markers[static_cast<std::size_t>(i)].label == label) return i;
  }
  ADD_FAILURE() << "no marker " << label;
  return -1;
}

TEST(RigidMarkerGroups, MarkersOfOneBoneAreFoundAndNoGroupCrossesAJoint) {
  const auto markers = dr::characterMarkers();
  const std::vector<RigidMarkerGroup> groups = findRigidMarkerGroups(kFrames, dr::kCharacterMarkerCount, performance(), restPositions());
  ASSERT_FALSE(groups.empty());
  // Bones carrying 3+ markers that are not collinear: each must come out as (a superset of) one group.
  std::map<int, std::set<int>> by_bone;
  for (int i = 0; i < dr::kCharacterMarkerCount; ++i) by_bone[markers[static_cast<std::size_t>(i)].bone].insert(i);
  for (const RigidMarkerGroup& g : groups) {
    EXPECT_GE(g.markers.size(), 3u);
    EXPECT_LT(g.spread_mm, 5.0);
    // A group lies on one bone, or on bones that the performance never turns against each other
    // (the wrists stay straight): their relative rotation stays within 1 degree of its T-pose value.
    std::set<int> bones;
    for (const std::int32_t m : g.markers) bones.insert(markers[static_cast<std::size_t>(m)].bone);
    std::string labels;
    for (const std::int32_t m : g.markers) labels += std::string(markers[static_cast<std::size_t>(m)].label) + " ";
    for (const int a : bones) {
      for (const int b : bones) {
        EXPECT_LT(largestRelativeTurnDeg(a, b), 1.0) << labels << "on bones " << a << " and " << b;
      }
    }
  }
  // The head's four markers and the pelvis's four waist markers form groups.
  const auto has_group = [&](std::initializer_list<std::string_view> labels) {
    std::vector<std::int32_t> want;
    for (const std::string_view l : labels) want.push_back(markerIndex(l));
    std::sort(want.begin(), want.end());
    for (const RigidMarkerGroup& g : groups) {
      if (std::includes(g.markers.begin(), g.markers.end(), want.begin(), want.end())) return true;
    }
    return false;
  };
  EXPECT_TRUE(has_group({"LFHD", "RFHD", "LBHD", "RBHD"}));
  EXPECT_TRUE(has_group({"LFWT", "RFWT", "LBWT", "RBWT"}));
  // No group holds markers of a thigh and its shin (the knee bends in the crouch).
  for (const RigidMarkerGroup& g : groups) {
    const bool thigh = std::count(g.markers.begin(), g.markers.end(), markerIndex("LTHI")) > 0;
    const bool shin = std::count(g.markers.begin(), g.markers.end(), markerIndex("LSHN")) > 0;
    EXPECT_FALSE(thigh && shin);
  }
}

TEST(RigidMarkerGroups, NoiseWithinTheToleranceKeepsTheGroupsAndASlidingMarkerLeavesIt) {
  const std::vector<Eigen::Vector3d> rest = restPositions();
  const auto clean = findRigidMarkerGroups(kFrames, dr::kCharacterMarkerCount, performance(), rest);
  // +-1 mm per axis: a pair's distance spread (P95 - P5, about 2.7 mm) stays within the 5 mm tolerance.
  const auto noisy = findRigidMarkerGroups(kFrames, dr::kCharacterMarkerCount, performance(1.0), rest);
  ASSERT_EQ(noisy.size(), clean.size());
  for (std::size_t g = 0; g < clean.size(); ++g) EXPECT_EQ(noisy[g].markers, clean[g].markers);
  // LFHD slides 40 mm on the head: it leaves the head's group, which keeps its other three markers.
  const int lfhd = markerIndex("LFHD");
  const auto slid = findRigidMarkerGroups(kFrames, dr::kCharacterMarkerCount, performance(0.0, lfhd), rest);
  bool head = false;
  for (const RigidMarkerGroup& g : slid) {
    EXPECT_EQ(std::count(g.markers.begin(), g.markers.end(), lfhd), 0);
    if (std::count(g.markers.begin(), g.markers.end(), markerIndex("RFHD")) > 0) {
      head = true;
      EXPECT_EQ(std::count(g.markers.begin(), g.markers.end(), markerIndex("LBHD")), 1);
    }
  }
  EXPECT_TRUE(head);
}

// A static trial (the T-pose held) keeps every distance: one group of all markers, which spans the
// whole body and is left out, reported. The performance itself gives the bones' groups, none left
// out.
TEST(RigidMarkerGroups, AStaticClipGivesNoGroupButReportsWhy) {
  const MarkerFrameReader still = [](std::int64_t, std::vector<Eigen::Vector3d>& x, std::vector<std::uint8_t>& valid) {
    performance()(0, x, valid);
  };
  std::vector<RigidMarkerGroup> too_large;
  EXPECT_TRUE(findRigidMarkerGroups(300, dr::kCharacterMarkerCount, still, restPositions(), {}, &too_large).empty());
  ASSERT_EQ(too_large.size(), 1u);
  EXPECT_EQ(too_large[0].markers.size(), static_cast<std::size_t>(dr::kCharacterMarkerCount));
  EXPECT_GT(too_large[0].extent_mm, 1500.0);
  const std::vector<RigidMarkerGroup> moving = findRigidMarkerGroups(kFrames, dr::kCharacterMarkerCount, performance(), restPositions(), {}, &too_large);
  EXPECT_FALSE(moving.empty());
  EXPECT_TRUE(too_large.empty());
}

TEST(RigidMarkerGroups, CollinearMarkersGiveNoGroupAndGapsAreSkipped) {
  // Three markers on one line move rigidly: no orientation, so no group.
  const MarkerFrameReader line = [](std::int64_t f, std::vector<Eigen::Vector3d>& x, std::vector<std::uint8_t>& valid) {
    const double t = static_cast<double>(f) * 0.01;
    const Eigen::Vector3d d(std::cos(t), std::sin(t), 0.0);
    for (std::size_t i = 0; i < 3; ++i) {
      x[i] = Eigen::Vector3d(10.0 * t, 0, 0) + 100.0 * static_cast<double>(i) * d;
      valid[i] = 1;
    }
  };
  const std::vector<Eigen::Vector3d> rest = {{0, 0, 0}, {100, 0, 0}, {200, 0, 0}};
  EXPECT_TRUE(findRigidMarkerGroups(500, 3, line, rest).empty());
  std::vector<double> median;
  const std::vector<double> spread = markerDistanceSpreads(500, 3, line, {}, &median);
  EXPECT_NEAR(spread[0 * 3 + 2], 0.0, 1e-3);
  EXPECT_NEAR(median[0 * 3 + 2], 200.0, 1e-3);
  // A marker valid in under half the frames has no spread with the others (too few frames together).
  const MarkerFrameReader gappy = [](std::int64_t f, std::vector<Eigen::Vector3d>& x, std::vector<std::uint8_t>& valid) {
    for (std::size_t i = 0; i < 3; ++i) {
      x[i] = Eigen::Vector3d(static_cast<double>(i) * 50.0, static_cast<double>(i * i) * 30.0, 0.0);
      valid[i] = i != 2 || f % 3 == 0;
    }
  };
  const std::vector<double> gap_spread = markerDistanceSpreads(300, 3, gappy);
  EXPECT_TRUE(std::isinf(gap_spread[0 * 3 + 2]));
  EXPECT_EQ(gap_spread[0 * 3 + 1], 0.0);
}

TEST(RigidMarkerGroups, TheSkinOfAGroupStaysNearItsMarkersAndShortOfTheNextMarker) {
  // Markers 0, 1 (the group) at x = 0 and 10, marker 2 (the next body part) at x = 30; vertices
  // along x at -8 -2 4 10 16 22 28.
  const std::vector<Eigen::Vector3d> markers = {{0, 0, 0}, {10, 0, 0}, {30, 0, 0}};
  Vertices v(7, 3);
  for (int i = 0; i < 7; ++i) v.row(i) = Eigen::Vector3d(-8.0 + 6.0 * i, 0.0, 0.0).transpose();
  // Radius 7 (0.7 x extent 10), the next-marker bound at the halfway point (fraction 1): -8 is
  // beyond 7 of marker 0, 22 nearer marker 2.
  EXPECT_EQ(groupSkinMask(v, markers, {0, 1}, 10.0, {.radius_fraction = 0.7, .next_marker_fraction = 1.0}),
            (std::vector<std::uint8_t>{0, 1, 1, 1, 1, 0, 0}));
  // The default fraction 0.25: 16 (6 from marker 1, 14 from marker 2) is more than a quarter of
  // the way; 4 (4 from marker 0, 26 from marker 2) is not.
  EXPECT_EQ(groupSkinMask(v, markers, {0, 1}, 10.0, {.radius_fraction = 0.7}), (std::vector<std::uint8_t>{0, 1, 1, 1, 0, 0, 0}));
  // The next-marker bound alone: -8 (8 from marker 0, 38 from marker 2) is within a quarter.
  EXPECT_EQ(groupSkinMask(v, markers, {0, 1}, 10.0, {.radius_fraction = 100.0}), (std::vector<std::uint8_t>{1, 1, 1, 1, 0, 0, 0}));
  // The defaults: radius 2 (0.2 x 10) around the markers holds -2 and 10, not 4.
  EXPECT_EQ(groupSkinMask(v, markers, {0, 1}, 10.0), (std::vector<std::uint8_t>{0, 1, 0, 1, 0, 0, 0}));
}

}  // namespace
}  // namespace tetrig::rigbuild
