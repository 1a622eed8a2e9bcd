// Tests of the default character (drivers/character_performance.hpp) and of the synthetic source
// playing it: HDM05 labels, skeleton proportions, rigid forward kinematics, the performance's
// motions (walk and turns, arms raised, torso twist, crouch), smoothness and a seamless loop, the
// source's noise and dropout statistics against its options, no allocation per frame, and the
// "synthetic:character" spec.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <numbers>
#include <string>
#include <vector>

#include "counting_allocator.hpp"
#include "tetrig/drivers/c3d_reader.hpp"
#include "tetrig/drivers/character_performance.hpp"
#include "tetrig/drivers/source_factory.hpp"
#include "tetrig/drivers/synthetic_source.hpp"
#include "test_data.hpp"

namespace tetrig::drivers {
namespace {

using Markers = std::array<CharacterVec3, kCharacterMarkerCount>;

Markers markersAt(double t) {
  Markers m;
  characterMarkersAt(t, m);
  return m;
}

int index(std::string_view label) {
  const auto markers = characterMarkers();
  for (std::size_t i = 0; i < markers.size(); ++i) {
    if (markers[i].label == label) return static_cast<int>(i);
  }
  ADD_FAILURE() << "no marker " << label;
  return 0;
}

double dist(const CharacterVec3& a, const CharacterVec3& b) {
  return std::hypot(a[0] - b[0], a[1] - b[1], a[2] - b[2]);
}

CharacterVec3 mean(const Markers& m, std::initializer_list<std::string_view> labels) {
  CharacterVec3 c{};
  for (std::string_view l : labels) {
    for (std::size_t k = 0; k < 3; ++k) c[k] += m[static_cast<std::size_t>(index(l))][k] / static_cast<double>(labels.size());
  }
  return c;
}

// Heading (degrees, about +Z) of the horizontal vector from marker b to marker a.
double heading(const Markers& m, std::string_view a, std::string_view b) {
  const CharacterVec3& p = m[static_cast<std::size_t>(index(a))];
  const CharacterVec3& q = m[static_cast<std::size_t>(index(b))];
  return std::atan2(p[1] - q[1], p[0] - q[0]) * 180.0 / std::numbers::pi;
}

TEST(CharacterPerformance, LabelsAreTheHdm05Layout) {
  TETRIG_REQUIRE_DATA(path, "mocap/hdm05/HDM_mm_01-02_03_120.c3d");
  const C3DClip clip = C3DClip::load(path);
  std::vector<std::string> hdm05;
  for (int p = 0; p < clip.pointCount(); ++p) {
    if (clip.pointKind(p) != C3DPointKind::kMarker) continue;
    const std::string& l = clip.labels()[static_cast<std::size_t>(p)];
    hdm05.push_back(l.substr(l.rfind(':') + 1));
  }
  std::vector<std::string> ours;
  for (const CharacterMarker& m : characterMarkers()) ours.emplace_back(m.label);
  EXPECT_EQ(ours, hdm05);
  EXPECT_EQ(SyntheticSource::characterMarkerLabels(), hdm05);
}

TEST(CharacterPerformance, SkeletonHasHumanProportions) {
  const auto bones = characterBones();
  std::map<std::string_view, int> by_name;
  for (int b = 0; b < kCharacterBoneCount; ++b) {
    by_name[bones[static_cast<std::size_t>(b)].name] = b;
    EXPECT_LT(bones[static_cast<std::size_t>(b)].parent, b) << "parents come before children";
  }
  ASSERT_EQ(by_name.size(), static_cast<std::size_t>(kCharacterBoneCount));
  auto length = [&](std::string_view name) {
    const CharacterBone& b = bones[static_cast<std::size_t>(by_name.at(name))];
    return dist(b.joint, b.tip);
  };
  EXPECT_NEAR(bones[static_cast<std::size_t>(by_name.at("head"))].tip[2], 1750.0, 30.0);
  EXPECT_NEAR(length("l_thigh"), 410.0, 40.0);
  EXPECT_NEAR(length("l_shin"), 400.0, 40.0);
  EXPECT_NEAR(length("l_upper_arm"), 290.0, 40.0);
  EXPECT_NEAR(length("l_lower_arm"), 260.0, 40.0);
  // Left and right mirror each other in x.
  for (const char* side : {"clavicle", "upper_arm", "lower_arm", "hand", "thigh", "shin", "foot", "toe"}) {
    const CharacterBone& l = bones[static_cast<std::size_t>(by_name.at(std::string("l_") + side))];
    const CharacterBone& r = bones[static_cast<std::size_t>(by_name.at(std::string("r_") + side))];
    EXPECT_DOUBLE_EQ(l.joint[0], -r.joint[0]) << side;
    EXPECT_DOUBLE_EQ(l.tip[2], r.tip[2]) << side;
  }
  // The skin field is negative at every joint (inside) and positive well outside the body.
  for (const CharacterBone& b : bones) EXPECT_LT(characterSkinField(b.joint), 0.0) << b.name;
  EXPECT_GT(characterSkinField({0, 0, 1900}), 100.0);
  EXPECT_GT(characterSkinField({0, -400, 1000}), 100.0);
}

TEST(CharacterPerformance, MarkersSitOutsideTheSkinAtTheirSites) {
  const auto markers = characterMarkers();
  for (const CharacterMarker& m : markers) {
    // kCharacterMarkerClearanceMm along the site direction: the field there is at most that.
    const double f = characterSkinField(m.tpose);
    EXPECT_GT(f, 5.0) << m.label;
    EXPECT_LE(f, kCharacterMarkerClearanceMm + 1e-6) << m.label;
  }
  // Left markers on +x, right ones on -x; head markers highest, heels and toes lowest.
  for (const CharacterMarker& m : markers) {
    if (m.label[0] == 'L') {
      EXPECT_GT(m.tpose[0], 0.0) << m.label;
    } else if (m.label[0] == 'R') {
      EXPECT_LT(m.tpose[0], 0.0) << m.label;
    }
  }
  EXPECT_GT(markers[static_cast<std::size_t>(index("LFHD"))].tpose[2], 1600.0);
  EXPECT_LT(markers[static_cast<std::size_t>(index("LHEE"))].tpose[2], 100.0);
  EXPECT_LT(markers[static_cast<std::size_t>(index("RTOE"))].tpose[1], markers[static_cast<std::size_t>(index("RHEE"))].tpose[1]);  // faces -Y
}

TEST(CharacterPerformance, StartsAndEndsInTheTPoseAndLoopsSeamlessly) {
  const auto markers = characterMarkers();
  const Markers start = markersAt(0.0);
  const Markers end = markersAt(characterPerformanceSeconds());
  for (std::size_t i = 0; i < markers.size(); ++i) {
    EXPECT_LT(dist(start[i], markers[i].tpose), 1e-9) << markers[i].label;
    EXPECT_LT(dist(end[i], markers[i].tpose), 1e-6) << markers[i].label;  // a full turn: the same pose
  }
  EXPECT_GE(characterPerformanceSeconds(), 8.0);
  EXPECT_LE(characterPerformanceSeconds(), 10.5);
}

TEST(CharacterPerformance, ForwardKinematicsIsRigidPerBone) {
  const auto markers = characterMarkers();
  const auto bones = characterBones();
  // Every pair of markers on one bone, and each marker's distance to its bone's joint.
  std::vector<std::pair<std::size_t, std::size_t>> pairs;
  for (std::size_t i = 0; i < markers.size(); ++i) {
    for (std::size_t j = i + 1; j < markers.size(); ++j) {
      if (markers[i].bone == markers[j].bone) pairs.emplace_back(i, j);
    }
  }
  ASSERT_GE(pairs.size(), 20u);
  double worst = 0, worst_joint = 0, widest_change = 0;
  CharacterPose pose;
  for (double t = 0; t <= characterPerformanceSeconds(); t += 1.0 / 60.0) {
    const Markers m = markersAt(t);
    characterPoseAt(t, pose);
    for (const auto& [i, j] : pairs) {
      worst = std::max(worst, std::abs(dist(m[i], m[j]) - dist(markers[i].tpose, markers[j].tpose)));
    }
    for (std::size_t i = 0; i < markers.size(); ++i) {
      const auto b = static_cast<std::size_t>(markers[i].bone);
      worst_joint = std::max(worst_joint, std::abs(dist(m[i], pose.joint[b]) - dist(markers[i].tpose, bones[b].joint)));
    }
    // Markers of different bones do change their distances (the body does bend).
    widest_change = std::max(widest_change, std::abs(dist(m[static_cast<std::size_t>(index("LFIN"))], m[static_cast<std::size_t>(index("LFWT"))]) -
                                                     dist(markers[static_cast<std::size_t>(index("LFIN"))].tpose,
                                                          markers[static_cast<std::size_t>(index("LFWT"))].tpose)));
  }
  EXPECT_LT(worst, 1e-6);
  EXPECT_LT(worst_joint, 1e-6);
  EXPECT_GT(widest_change, 300.0);
}

// The posed skin: in the T-pose it is the T-pose skin; a point fixed to a bone, beside the middle of
// that bone's capsule and away from every other capsule's blend, keeps its field value in every pose
// (the capsule moves with the bone), while the same point left where it was does not.
TEST(CharacterPerformance, ThePosedSkinMovesEachCapsuleWithItsBone) {
  CharacterPose tpose, pose;
  characterPoseAt(0.0, tpose);
  for (double x = -900; x <= 900; x += 150) {
    for (double z = 0; z <= 1800; z += 150) {
      const CharacterVec3 p{x, 37.0, z};
      EXPECT_NEAR(characterPosedSkinField(tpose, p), characterSkinField(p), 1e-9);
    }
  }
  const auto capsules = characterSkinCapsules();
  int checked = 0, moved = 0;
  for (const CharacterCapsule& c : capsules) {
    // Beside the middle of the segment, 10 mm outside the skin, on a side perpendicular to it.
    const CharacterVec3 ab{c.b[0] - c.a[0], c.b[1] - c.a[1], c.b[2] - c.a[2]};
    // The axis most across the segment, minus its component along it.
    std::size_t across = 0;
    for (std::size_t k = 1; k < 3; ++k) across = std::abs(ab[k]) < std::abs(ab[across]) ? k : across;
    CharacterVec3 side{};
    side[across] = 1.0;
    const double len2 = ab[0] * ab[0] + ab[1] * ab[1] + ab[2] * ab[2];
    const double along = (side[0] * ab[0] + side[1] * ab[1] + side[2] * ab[2]) / len2;
    CharacterVec3 n{side[0] - along * ab[0], side[1] - along * ab[1], side[2] - along * ab[2]};
    const double nn = std::hypot(n[0], n[1], n[2]);
    const double r = 0.5 * (c.a_radius + c.b_radius) + 10.0;
    const CharacterVec3 q{0.5 * (c.a[0] + c.b[0]) + r * n[0] / nn, 0.5 * (c.a[1] + c.b[1]) + r * n[1] / nn,
                          0.5 * (c.a[2] + c.b[2]) + r * n[2] / nn};
    ASSERT_TRUE(std::isfinite(characterSkinField(q)));
    if (std::abs(characterSkinField(q) - 10.0) > 1e-9) continue;  // another capsule's blend reaches it
    ++checked;
    bool left_behind_differs = false;
    for (double t = 0.5; t < characterPerformanceSeconds(); t += 0.75) {
      characterPoseAt(t, pose);
      EXPECT_NEAR(characterPosedSkinField(pose, characterTransformPoint(pose, c.bone, q)), 10.0, 1e-9) << "bone " << c.bone << ", t " << t;
      left_behind_differs = left_behind_differs || std::abs(characterPosedSkinField(pose, q) - 10.0) > 1.0;
    }
    moved += left_behind_differs ? 1 : 0;
  }
  EXPECT_GE(checked, 10);
  EXPECT_EQ(moved, checked);
}

TEST(CharacterPerformance, WalksTurnsRaisesTheArmsTwistsAndCrouches) {
  const Markers rest = markersAt(0.0);
  const CharacterVec3 pelvis_rest = mean(rest, {"LFWT", "RFWT", "LBWT", "RBWT"});
  // Two steps out along -Y (facing -Y), turned round (toes towards +Y), two steps back.
  const Markers out = markersAt(2.2);
  const CharacterVec3 pelvis_out = mean(out, {"LFWT", "RFWT", "LBWT", "RBWT"});
  EXPECT_LT(pelvis_out[1] - pelvis_rest[1], -1000.0);
  const Markers turned = markersAt(2.9);
  EXPECT_GT(turned[static_cast<std::size_t>(index("LTOE"))][1], turned[static_cast<std::size_t>(index("LHEE"))][1] + 100.0);
  CharacterPose back;
  characterPoseAt(4.1, back);
  EXPECT_LT(dist(back.joint[0], characterBones()[0].joint), 1e-6);  // the pelvis is back where it started
  // While walking the feet swing: the left ankle is ahead of the right one at the first heel strike.
  const Markers strike = markersAt(1.3);
  EXPECT_LT(strike[static_cast<std::size_t>(index("LANK"))][1], strike[static_cast<std::size_t>(index("RANK"))][1] - 300.0);
  // Arms raised: the fingers well above the head's markers' height... at least above the T-pose by 0.3 m.
  const Markers up = markersAt(5.6);
  for (const char* fin : {"LFIN", "RFIN"}) {
    EXPECT_GT(up[static_cast<std::size_t>(index(fin))][2], rest[static_cast<std::size_t>(index(fin))][2] + 300.0) << fin;
  }
  // Arms down before the walk: the fingers below the pelvis markers' height + 0.2 m.
  const Markers down = markersAt(1.0);
  EXPECT_LT(down[static_cast<std::size_t>(index("LFIN"))][2], pelvis_rest[2] + 200.0);
  // Torso twist: the shoulder line turns against the pelvis line, both ways.
  const double rest_twist = heading(rest, "LSHO", "RSHO") - heading(rest, "LFWT", "RFWT");
  const double left = heading(markersAt(6.7), "LSHO", "RSHO") - heading(markersAt(6.7), "LFWT", "RFWT");
  const double right = heading(markersAt(7.4), "LSHO", "RSHO") - heading(markersAt(7.4), "LFWT", "RFWT");
  EXPECT_NEAR(rest_twist, 0.0, 1e-6);
  EXPECT_GT(left, 25.0);
  EXPECT_LT(right, -25.0);
  // Crouch: the pelvis lowers by about 0.35 m while the feet stay on the ground.
  const Markers crouch = markersAt(8.6);
  EXPECT_LT(mean(crouch, {"LFWT", "RFWT", "LBWT", "RBWT"})[2], pelvis_rest[2] - 250.0);
  for (const char* foot : {"LHEE", "RHEE", "LTOE", "RTOE"}) {
    EXPECT_NEAR(crouch[static_cast<std::size_t>(index(foot))][2], rest[static_cast<std::size_t>(index(foot))][2], 40.0) << foot;
  }
}

TEST(CharacterPerformance, MotionIsSmoothAndStaysAboveTheFloor) {
  const double dt = 1.0 / 120.0;
  Markers prev = markersAt(0.0), prev2 = prev;
  double max_speed = 0, max_accel = 0, lowest = 1e9;
  for (int k = 1; k * dt <= characterPerformanceSeconds(); ++k) {
    const Markers m = markersAt(k * dt);
    for (std::size_t i = 0; i < m.size(); ++i) {
      max_speed = std::max(max_speed, dist(m[i], prev[i]) / dt);
      if (k >= 2) {
        CharacterVec3 a;
        for (std::size_t c = 0; c < 3; ++c) a[c] = (m[i][c] - 2 * prev[i][c] + prev2[i][c]) / (dt * dt);
        max_accel = std::max(max_accel, std::hypot(a[0], a[1], a[2]));
      }
      lowest = std::min(lowest, m[i][2]);
    }
    prev2 = prev;
    prev = m;
  }
  std::printf("[ measured ] fastest marker %.2f m/s, largest acceleration %.1f m/s^2, lowest marker %.1f mm\n", max_speed / 1000,
              max_accel / 1000, lowest);
  EXPECT_LT(max_speed, 6000.0);     // mm/s: a brisk human limb, not a jump
  EXPECT_LT(max_accel, 150000.0);   // mm/s^2
  EXPECT_GT(lowest, 5.0);           // no marker below the floor (the lower foot stands on it)
}

TEST(CharacterPerformance, PoseAndMarkersAllocateNothing) {
  (void)characterMarkers();  // computed once
  Markers m;
  CharacterPose pose;
  const std::uint64_t before = test::allocationCount();
  for (int k = 0; k < 200; ++k) {
    characterPoseAt(k * 0.05, pose);
    characterMarkersAt(k * 0.05, m);
  }
  EXPECT_EQ(test::allocationCount(), before);
}

TEST(SyntheticCharacter, FramesAreThePerformanceLooped) {
  SyntheticOptions o;
  o.motion = SyntheticMotion::kCharacter;
  const SyntheticSource source(o);
  ASSERT_EQ(source.markerCount(), kCharacterMarkerCount);
  MarkerFrame frame;
  const auto loop = static_cast<std::uint64_t>(std::llround(characterPerformanceSeconds() * 120.0));
  for (const std::uint64_t k : std::array<std::uint64_t, 5>{0, 157, 600, loop - 1, loop + 157}) {
    source.fillFrame(k, frame);
    const Markers m = markersAt(std::fmod(static_cast<double>(k) / 120.0, characterPerformanceSeconds()));
    ASSERT_EQ(frame.marker_count, kCharacterMarkerCount);
    for (std::size_t i = 0; i < m.size(); ++i) {
      ASSERT_TRUE(frame.markers[i].valid);
      for (std::size_t c = 0; c < 3; ++c) EXPECT_NEAR(frame.markers[i].position_mm[c], m[i][c], 1e-3) << k << " " << i;
    }
  }
  // Rest positions belong to the sway motion; noise and dropout options are checked.
  SyntheticOptions bad = o;
  bad.rest_positions_mm = {{0, 0, 0}};
  EXPECT_THROW(SyntheticSource{bad}, std::invalid_argument);
  bad = o;
  bad.noise_sigma_mm = -0.5f;
  EXPECT_THROW(SyntheticSource{bad}, std::invalid_argument);
  bad = o;
  bad.dropout_probability = 1.5f;
  EXPECT_THROW(SyntheticSource{bad}, std::invalid_argument);
}

TEST(SyntheticCharacter, NoiseAndDropoutsMatchTheOptions) {
  const SyntheticOptions o = characterSyntheticOptions();
  EXPECT_EQ(o.rate_hz, 120.0);
  const SyntheticSource noisy(o);
  SyntheticOptions clean_options = o;
  clean_options.noise_sigma_mm = 0.0f;
  clean_options.dropout_probability = 0.0f;
  const SyntheticSource clean(clean_options);
  MarkerFrame a, b;
  const std::uint64_t frames = 12000;  // 100 s: about 1.2 loops
  double sum = 0, sum2 = 0;
  std::uint64_t samples = 0, missing = 0, gaps = 0, longest = 0;
  std::vector<std::uint64_t> run(kCharacterMarkerCount, 0);
  for (std::uint64_t k = 0; k < frames; ++k) {
    noisy.fillFrame(k, a);
    clean.fillFrame(k, b);
    for (std::size_t i = 0; i < kCharacterMarkerCount; ++i) {
      if (!a.markers[i].valid) {
        ++missing;
        if (run[i]++ == 0) ++gaps;
        longest = std::max(longest, run[i]);
        continue;
      }
      run[i] = 0;
      for (std::size_t c = 0; c < 3; ++c) {
        const double e = static_cast<double>(a.markers[i].position_mm[c]) - b.markers[i].position_mm[c];
        sum += e;
        sum2 += e * e;
        ++samples;
      }
    }
  }
  const double marker_frames = static_cast<double>(frames) * kCharacterMarkerCount;
  const double sigma = std::sqrt(sum2 / static_cast<double>(samples));
  // Expected: gaps start at p per marker-frame (about 246 here; overlapping starts merge a few),
  // mean length (1 + 12) / 2, so the missing fraction is about p * 6.5.
  const double p = o.dropout_probability;
  std::printf("[ measured ] noise sigma %.4f mm (mean %.4f); %llu gaps, %.3f %% missing, longest %llu frames\n", sigma,
              sum / static_cast<double>(samples), static_cast<unsigned long long>(gaps), 100.0 * static_cast<double>(missing) / marker_frames,
              static_cast<unsigned long long>(longest));
  EXPECT_NEAR(sigma, o.noise_sigma_mm, 0.01);
  EXPECT_NEAR(sum / static_cast<double>(samples), 0.0, 0.01);
  EXPECT_NEAR(static_cast<double>(gaps), p * marker_frames, 4 * std::sqrt(p * marker_frames));
  EXPECT_NEAR(static_cast<double>(missing) / marker_frames, p * 6.5, 0.3 * p * 6.5);
  EXPECT_LE(longest, 2u * static_cast<std::uint64_t>(o.dropout_max_frames));  // two overlapping gaps at most
  EXPECT_GE(longest, 8u);
}

TEST(SyntheticCharacter, SpecOpensTheCharacterWithItsLabels) {
  devices::SourceOpenOptions open;
  open.pacing = Pacing::kAsFastAsPossible;
  open.max_frames = 5;
  open.synthetic_rest_mm = {{1, 2, 3}};  // a rig's markers: not used by the character
  open.synthetic_labels = {"X"};
  const auto source = devices::openMarkerSource("synthetic:character", open);
  std::vector<std::string> labels;
  ASSERT_TRUE(source->waitForLabels(std::chrono::milliseconds(0), labels));
  EXPECT_EQ(labels, SyntheticSource::characterMarkerLabels());
  EXPECT_EQ(source->nominalRateHz(), 120.0);
  EXPECT_THROW((void)devices::openMarkerSource("synthetic:charactr", open), std::invalid_argument);
}

}  // namespace
}  // namespace tetrig::drivers
