// PoseSensorDriver (runtime/internal/tetrig/pose_sensor.hpp): a Razer Hydra controller driving a
// region handle, with a clutch or absolutely. The input is a RECORDED stream: 52-byte Hydra motion
// reports built with the drivers' encoder (integer mm, quaternions in 1/32768), decoded by
// HydraDecoder into MarkerFrames exactly as a live device's reports are. Expectations are computed
// two ways: (1) the clutch equations written with 4x4 homogeneous matrices from the decoded samples
// (x' = dR (T0 x - c0) + c0 + s (p_c - p_c0), tight tolerance), and (2) the motion the recording
// was made from (the controller's true rotation about a known axis and its whole-mm path; loose
// tolerance for the int16 quaternion quantisation). Then a Deformer on the 4x4x33 bar, driven
// through the clutch, twists beyond 180 degrees and bends as the region targets say.
#include "counting_allocator.hpp"
#include "scenes.hpp"
#include "tetrig/deformer.hpp"
#include "tetrig/drivers/hydra.hpp"
#include "tetrig/marker_frame.hpp"
#include "tetrig/pose_sensor.hpp"
#include "tetrig/rig_file.hpp"

#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <vector>

namespace tetrig {
namespace {

constexpr double kDeg = M_PI / 180.0;

// One controller's state as recorded: whole-mm position (device axes), orientation, buttons.
struct ControllerSample {
  Eigen::Vector3d position_mm = Eigen::Vector3d::Zero();
  Eigen::Quaterniond orientation = Eigen::Quaterniond::Identity();
  std::uint8_t buttons = 0;
  bool tracked = true;  // false: an all-zero quaternion on the wire (the decoder invalidates it)
};

struct RecordedFrame {
  ControllerSample controller[2];
};

// Encodes the recording as Hydra reports and decodes them (one MarkerFrame per report).
std::vector<MarkerFrame> decodeRecording(const std::vector<RecordedFrame>& recording) {
  std::vector<MarkerFrame> frames;
  drivers::HydraDecoder decoder;
  std::uint8_t sequence = 17;
  for (const RecordedFrame& f : recording) {
    drivers::HydraRawReport raw;
    raw.sequence = sequence++;
    for (std::size_t c = 0; c < 2; ++c) {
      const ControllerSample& s = f.controller[c];
      const float p[3] = {static_cast<float>(s.position_mm.x()), static_cast<float>(s.position_mm.y()),
                          static_cast<float>(s.position_mm.z())};
      const float q[4] = {static_cast<float>(s.orientation.w()), static_cast<float>(s.orientation.x()),
                          static_cast<float>(s.orientation.y()), static_cast<float>(s.orientation.z())};
      raw.controllers[c] = drivers::hydraControllerFromPose(p, q);
      if (!s.tracked) {
        for (std::int16_t& v : raw.controllers[c].quaternion) v = 0;
      }
      raw.controllers[c].buttons = s.buttons;
    }
    std::uint8_t bytes[drivers::kHydraReportSize];
    EXPECT_EQ(drivers::encodeHydraReport(raw, bytes), drivers::kHydraReportSize);
    MarkerFrame frame;
    EXPECT_EQ(decoder.decode(bytes, 1000 * static_cast<std::int64_t>(frames.size()), frame), drivers::HydraStatus::kFrame);
    frames.push_back(frame);
  }
  return frames;
}

const Marker* findMarker(const MarkerFrame& frame, std::uint16_t id) {
  for (std::uint16_t i = 0; i < frame.marker_count; ++i) {
    if (frame.markers[i].id == id) return &frame.markers[i];
  }
  return nullptr;
}

Eigen::Matrix4d homogeneous(const Eigen::Matrix3d& r, const Eigen::Vector3d& t) {
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  m.topLeftCorner<3, 3>() = r;
  m.topRightCorner<3, 1>() = t;
  return m;
}
Eigen::Matrix4d homogeneous(const RigidTransform& t) { return homogeneous(t.rotation.normalized().toRotationMatrix(), t.translation); }
Eigen::Matrix4d translation(const Eigen::Vector3d& t) { return homogeneous(Eigen::Matrix3d::Identity(), t); }

// The clutch equations from the task statement in matrix form, evaluated on decoded samples.
// `axes` is the orthogonal factor Q of the alignment (A = scale_units * Q), which may be a
// reflection: controller rotations map as Q R Q^T.
struct ReferenceClutch {
  Eigen::Matrix3d linear;
  Eigen::Vector3d offset;
  Eigen::Matrix3d axes;
  double scale = 1.0;
  // Anchors.
  Eigen::Matrix3d r_c0;
  Eigen::Vector3d p_c0;
  Eigen::Matrix4d t0;
  Eigen::Vector3d c0;

  Eigen::Matrix3d rotation(const Marker& m) const {
    const Eigen::Quaterniond q(m.orientation[0], m.orientation[1], m.orientation[2], m.orientation[3]);
    return axes * q.normalized().toRotationMatrix() * axes.transpose();
  }
  Eigen::Vector3d position(const Marker& m) const {
    return linear * Eigen::Vector3d(m.position_mm[0], m.position_mm[1], m.position_mm[2]) + offset;
  }
  void anchor(const Marker& m, const Eigen::Matrix4d& region, const Eigen::Vector3d& c_rest) {
    r_c0 = rotation(m);
    p_c0 = position(m);
    t0 = region;
    c0 = (region * c_rest.homogeneous()).head<3>();
  }
  Eigen::Matrix4d expected(const Marker& m) const {
    const Eigen::Matrix3d d_r = rotation(m) * r_c0.transpose();
    return translation(c0 + scale * (position(m) - p_c0)) * homogeneous(d_r, Eigen::Vector3d::Zero()) * translation(-c0) * t0;
  }
};

double rotationAngleBetween(const Eigen::Matrix3d& a, const Eigen::Matrix3d& b) {
  return Eigen::AngleAxisd(a * b.transpose()).angle();
}

// The recording used by the clutch tests (controller 1 = hydra1 does everything; controller 0
// idles, released). Phases, in frames:
struct ClutchRecording {
  std::vector<RecordedFrame> frames;
  int press = 0;             // first held frame (same pose as the frame before)
  int untracked_begin = 0;   // three held frames with an all-zero quaternion
  int release = 0;           // first released frame (the pose moved on)
  int second_press = 0;      // first held frame of the second hold
  int end = 0;
  Eigen::Vector3d axis_device;        // the held rotation's axis (device axes)
  Eigen::Quaterniond start_orientation;
  std::vector<double> held_angle;     // per frame, the controller's rotation since the press (first hold)
};

ClutchRecording makeClutchRecording() {
  ClutchRecording rec;
  rec.axis_device = Eigen::Vector3d(0.2, 1.0, -0.3).normalized();
  rec.start_orientation = Eigen::Quaterniond(Eigen::AngleAxisd(0.4, Eigen::Vector3d(0.3, -0.5, 0.8).normalized()));
  RecordedFrame idle;
  idle.controller[0].position_mm = Eigen::Vector3d(-200, 10, 250);
  idle.controller[0].orientation = Eigen::Quaterniond(Eigen::AngleAxisd(-0.5, Eigen::Vector3d::UnitY()));
  idle.controller[1].position_mm = Eigen::Vector3d(120, -40, 300);
  idle.controller[1].orientation = rec.start_orientation;
  auto push = [&rec](const RecordedFrame& f, double angle) {
    rec.frames.push_back(f);
    rec.held_angle.push_back(angle);
  };
  // Released, at rest, then pressed at the same pose.
  for (int i = 0; i < 5; ++i) push(idle, 0.0);
  rec.press = static_cast<int>(rec.frames.size());
  RecordedFrame f = idle;
  f.controller[1].buttons = 0x01;
  push(f, 0.0);
  // Held: 270 degrees about axis_device in 5-degree steps, moving (3, -2, 5) mm per step; other
  // button bits come and go (the clutch is bit 0 only). Three frames untracked in the middle.
  const Eigen::Vector3d start = idle.controller[1].position_mm;
  for (int k = 1; k <= 54; ++k) {
    const double angle = 5.0 * k * kDeg;
    f.controller[1].orientation = Eigen::AngleAxisd(angle, rec.axis_device) * rec.start_orientation;
    f.controller[1].position_mm = start + k * Eigen::Vector3d(3, -2, 5);
    f.controller[1].buttons = static_cast<std::uint8_t>(0x01 | ((k % 3 == 0) ? 0x40 : 0x00));
    if (k == 30) rec.untracked_begin = static_cast<int>(rec.frames.size());
    f.controller[1].tracked = !(k >= 30 && k < 33);
    push(f, angle);
  }
  f.controller[1].tracked = true;
  // Release after one more step; then the controller moves and turns a lot, released (bit 0x40
  // alone is not the clutch).
  rec.release = static_cast<int>(rec.frames.size());
  for (int k = 0; k < 20; ++k) {
    f.controller[1].orientation = Eigen::AngleAxisd(7.0 * k * kDeg, Eigen::Vector3d::UnitX()) * f.controller[1].orientation;
    f.controller[1].position_mm += Eigen::Vector3d(-9, 4, -6);
    f.controller[1].buttons = (k % 2 == 0) ? 0x00 : 0x40;
    push(f, 0.0);
  }
  // Second press (re-anchor) and a second hold: -100 degrees about device x, moving (-4, 6, 1) mm per step.
  rec.second_press = static_cast<int>(rec.frames.size());
  f.controller[1].buttons = 0x01;
  push(f, 0.0);
  const Eigen::Quaterniond second_start = f.controller[1].orientation;
  const Eigen::Vector3d second_position = f.controller[1].position_mm;
  for (int k = 1; k <= 20; ++k) {
    f.controller[1].orientation = Eigen::AngleAxisd(-5.0 * k * kDeg, Eigen::Vector3d::UnitX()) * second_start;
    f.controller[1].position_mm = second_position + k * Eigen::Vector3d(-4, 6, 1);
    push(f, 0.0);
  }
  rec.end = static_cast<int>(rec.frames.size());
  return rec;
}

// A device -> rig alignment that is neither identity nor axis-aligned: 0.1 rig units per mm,
// rotated, translated.
RigAlignment obliqueAlignment(bool mirror = false) {
  RigAlignment a;
  Eigen::Matrix3d q = Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  if (mirror) q = q * Eigen::Vector3d(1, 1, -1).asDiagonal();
  a.linear = 0.1 * q;
  a.translation = Eigen::Vector3d(5, -3, 2);
  a.rig_units_per_mm = 0.1;
  return a;
}

RigPoseSensor clutchSensor(double scale = 1.5) {
  RigPoseSensor s;
  s.sensor_label = "hydra1";
  s.region_handle = 1;
  s.mode = PoseSensorMode::kClutch;
  s.clutch_buttons = 0x01;
  s.translation_scale = scale;
  return s;
}

bool sameTransform(const RigidTransform& a, const RigidTransform& b) {
  return a.rotation.coeffs() == b.rotation.coeffs() && a.translation == b.translation;
}

TEST(PoseSensor, ClutchFollowsRelativeMotionHoldsOnReleaseAndReanchors) {
  const ClutchRecording rec = makeClutchRecording();
  const std::vector<MarkerFrame> frames = decodeRecording(rec.frames);
  ASSERT_EQ(frames.size(), rec.frames.size());
  // The decoder passes the clutch bit through Marker::buttons (what the driver reads).
  ASSERT_EQ(findMarker(frames[static_cast<std::size_t>(rec.press)], 1)->buttons & 0x01, 0x01)
      << "Marker::buttons not filled by the Hydra decoder";
  ASSERT_EQ(findMarker(frames[static_cast<std::size_t>(rec.untracked_begin)], 1)->valid, 0);

  const RigAlignment alignment = obliqueAlignment();
  const Eigen::Vector3d c_rest(2.0, 2.0, 32.5);
  const RigPoseSensor sensor = clutchSensor(1.5);
  PoseSensorDriver driver(sensor, alignment, c_rest);
  ReferenceClutch ref{alignment.linear, alignment.translation, alignment.linear / 0.1, sensor.translation_scale, {}, {}, {}, {}};

  // The region starts somewhere else than rest: T0 must be the transform at the press.
  RigidTransform target;
  target.rotation = Eigen::Quaterniond(Eigen::AngleAxisd(0.2, Eigen::Vector3d::UnitZ()));
  target.translation = Eigen::Vector3d(1, 0, 0);
  const Eigen::Matrix4d first_t0 = homogeneous(target);
  const Eigen::Vector3d first_c0 = (first_t0 * c_rest.homogeneous()).head<3>();

  double worst_exact = 0.0, worst_truth_angle = 0.0, worst_truth_centroid = 0.0, largest_step = 0.0;
  int held_frames = 0;
  for (int i = 0; i < rec.end; ++i) {
    const Marker* m = findMarker(frames[static_cast<std::size_t>(i)], 1);
    ASSERT_NE(m, nullptr);
    const RigidTransform before = target;
    driver.update(m, target);
    const bool first_hold = i > rec.press && i < rec.release;
    const bool second_hold = i > rec.second_press;
    if (i < rec.press || (i >= rec.release && i < rec.second_press)) {
      // Released: the region does not move.
      EXPECT_TRUE(sameTransform(target, before)) << "frame " << i;
      EXPECT_FALSE(driver.engaged()) << "frame " << i;
    }
    if (i == rec.press || i == rec.second_press) {
      // Press: anchors, no jump.
      EXPECT_TRUE(sameTransform(target, before)) << "press at frame " << i;
      EXPECT_TRUE(driver.engaged());
      ref.anchor(*m, homogeneous(target), c_rest);
    }
    if (i >= rec.untracked_begin && i < rec.untracked_begin + 3) {
      EXPECT_TRUE(sameTransform(target, before)) << "untracked frame " << i;
      EXPECT_TRUE(driver.engaged()) << "a dropout is not a release";
      continue;
    }
    if (!first_hold && !second_hold) continue;
    ++held_frames;
    ASSERT_TRUE(driver.engaged()) << "frame " << i;
    // (1) The equations, on the decoded samples.
    const Eigen::Matrix4d expected = ref.expected(*m);
    worst_exact = std::max(worst_exact, (homogeneous(target) - expected).cwiseAbs().maxCoeff());
    // Consecutive rotations stay in one hemisphere (no sign flip for consumers).
    EXPECT_GT(target.rotation.dot(before.rotation), 0.0) << "frame " << i;
    // No jump: one recorded step moves the region by one step's worth; after the dropout it
    // catches up with the controller (four steps at once), on the same anchor.
    const double step = rotationAngleBetween(target.rotation.toRotationMatrix(), before.rotation.toRotationMatrix());
    if (i == rec.untracked_begin + 3) {
      EXPECT_NEAR(step, 4 * 5.0 * kDeg, 1e-3);
    } else {
      largest_step = std::max(largest_step, step);
    }
    if (first_hold) {
      // (2) The recorded motion: the region turned by the controller's angle about Q a (rig axes),
      // and its centroid moved by scale * A * (p - p0) (whole mm: exact).
      const double angle = rec.held_angle[static_cast<std::size_t>(i)];
      const Eigen::Matrix3d truth =
          Eigen::AngleAxisd(angle, ref.axes * rec.axis_device).toRotationMatrix() * first_t0.topLeftCorner<3, 3>();
      worst_truth_angle = std::max(worst_truth_angle, rotationAngleBetween(target.rotation.toRotationMatrix(), truth));
      const Eigen::Vector3d moved_mm = rec.frames[static_cast<std::size_t>(i)].controller[1].position_mm -
                                       rec.frames[static_cast<std::size_t>(rec.press)].controller[1].position_mm;
      const Eigen::Vector3d centroid = target.rotation * c_rest + target.translation;
      worst_truth_centroid = std::max(worst_truth_centroid, (centroid - (first_c0 + 1.5 * alignment.linear * moved_mm)).norm());
    }
  }
  std::printf("clutch over %d held frames: worst |T - expected| %.3g, worst angle to the recorded motion %.3g rad, "
              "worst centroid error %.3g, largest rotation step %.2f deg\n",
              held_frames, worst_exact, worst_truth_angle, worst_truth_centroid, largest_step / kDeg);
  EXPECT_EQ(held_frames, 54 - 3 + 20);
  EXPECT_LT(worst_exact, 1e-10);
  EXPECT_LT(worst_truth_angle, 5e-4);   // int16 quaternions: ~1e-4 rad
  EXPECT_LT(worst_truth_centroid, 1e-10);
  EXPECT_LT(largest_step, 5.0 * kDeg + 1e-3);  // 5-degree steps
  // The first hold ended 270 degrees away from where it began: beyond a half turn, followed
  // through. Check the state at the last first-hold frame by replaying up to it.
  PoseSensorDriver replay(sensor, alignment, c_rest);
  RigidTransform t;
  t.rotation = Eigen::Quaterniond(first_t0.topLeftCorner<3, 3>());
  t.translation = first_t0.topRightCorner<3, 1>();
  for (int i = 0; i < rec.release; ++i) replay.update(findMarker(frames[static_cast<std::size_t>(i)], 1), t);
  const Eigen::Matrix3d relative = t.rotation.toRotationMatrix() * first_t0.topLeftCorner<3, 3>().transpose();
  const Eigen::AngleAxisd turned(relative);
  // 270 degrees about a is 90 degrees about -a.
  EXPECT_NEAR(turned.angle(), 90.0 * kDeg, 1e-3);
  EXPECT_GT(turned.axis().dot(-(ref.axes * rec.axis_device)), 0.999);
}

TEST(PoseSensor, AbsoluteModeFollowsThePoseFromTheFirstValidSampleIgnoringButtons) {
  const ClutchRecording rec = makeClutchRecording();
  std::vector<RecordedFrame> recording = rec.frames;
  // Controller 1 untracked for the first three frames: the anchor is the first valid sample.
  for (int i = 0; i < 3; ++i) recording[static_cast<std::size_t>(i)].controller[1].tracked = false;
  const std::vector<MarkerFrame> frames = decodeRecording(recording);
  const RigAlignment alignment = obliqueAlignment();
  const Eigen::Vector3d c_rest(2.0, 2.0, 32.5);
  RigPoseSensor sensor = clutchSensor(0.5);
  sensor.mode = PoseSensorMode::kAbsolute;
  PoseSensorDriver driver(sensor, alignment, c_rest);
  ReferenceClutch ref{alignment.linear, alignment.translation, alignment.linear / 0.1, 0.5, {}, {}, {}, {}};

  RigidTransform target;
  target.rotation = Eigen::Quaterniond(Eigen::AngleAxisd(1.0, Eigen::Vector3d::UnitX()));
  target.translation = Eigen::Vector3d(4, 5, 6);
  const RigidTransform initial = target;
  double worst = 0.0;
  for (std::size_t i = 0; i < frames.size(); ++i) {
    const Marker* m = findMarker(frames[i], 1);
    driver.update(m, target);
    if (i < 3) {
      EXPECT_TRUE(sameTransform(target, initial)) << "no valid sample yet, frame " << i;
      EXPECT_FALSE(driver.engaged());
      continue;
    }
    if (i == 3) {
      // Anchored: the region is at rest.
      EXPECT_TRUE(driver.engaged());
      EXPECT_EQ(target.rotation.coeffs(), Eigen::Quaterniond::Identity().coeffs());
      EXPECT_EQ(target.translation, Eigen::Vector3d::Zero());
      ref.anchor(*m, Eigen::Matrix4d::Identity(), c_rest);
      continue;
    }
    if (m->valid == 0) continue;
    worst = std::max(worst, (homogeneous(target) - ref.expected(*m)).cwiseAbs().maxCoeff());
  }
  EXPECT_LT(worst, 1e-10);
  // The last pose: the region's transform is the controller's motion since frame 3, whatever the
  // buttons did in between (released phases included).
  const Marker* last = findMarker(frames.back(), 1);
  const Eigen::Matrix3d d_r = ref.rotation(*last) * ref.r_c0.transpose();
  EXPECT_LT(rotationAngleBetween(target.rotation.toRotationMatrix(), d_r), 1e-12);
  const Eigen::Vector3d moved_mm = recording.back().controller[1].position_mm - recording[3].controller[1].position_mm;
  EXPECT_LT(((target.rotation * c_rest + target.translation) - (c_rest + 0.5 * alignment.linear * moved_mm)).norm(), 1e-10);
  // reset(): the next valid sample re-anchors and puts the region back at rest.
  driver.reset();
  EXPECT_FALSE(driver.engaged());
  driver.update(last, target);
  EXPECT_TRUE(driver.engaged());
  EXPECT_EQ(target.translation, Eigen::Vector3d::Zero());
}

TEST(PoseSensor, UnusableSamplesChangeNothing) {
  const RigAlignment alignment = obliqueAlignment();
  const Eigen::Vector3d c_rest(0.5, 0.5, 0.5);
  for (const bool engaged : {false, true}) {
    PoseSensorDriver driver(clutchSensor(), alignment, c_rest);
    RigidTransform target;
    target.rotation = Eigen::Quaterniond(Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitY()));
    target.translation = Eigen::Vector3d(1, 2, 3);
    Marker good;
    good.id = 1;
    good.valid = 1;
    good.has_orientation = 1;
    good.buttons = 0x01;
    good.position_mm[0] = 10.0f;
    if (engaged) {
      driver.update(&good, target);  // press
      good.position_mm[0] = 60.0f;
      driver.update(&good, target);  // moved while held
      ASSERT_TRUE(driver.engaged());
      ASSERT_GT(target.translation.norm(), 0.0);
    }
    const RigidTransform before = target;
    // Each of these, pressed and at a new pose, leaves target and clutch state as they were.
    std::vector<Marker> bad;
    Marker m = good;
    m.position_mm[1] = 500.0f;
    m.orientation[0] = 0.0f;
    m.orientation[3] = 1.0f;
    Marker v = m;
    v.valid = 0;
    bad.push_back(v);
    v = m;
    v.has_orientation = 0;
    bad.push_back(v);
    v = m;
    v.position_mm[2] = std::numeric_limits<float>::quiet_NaN();
    bad.push_back(v);
    v = m;
    v.position_mm[0] = std::numeric_limits<float>::infinity();
    bad.push_back(v);
    v = m;
    v.orientation[1] = std::numeric_limits<float>::quiet_NaN();
    bad.push_back(v);
    v = m;
    for (float& q : v.orientation) q = 0.0f;
    bad.push_back(v);
    v = m;
    v.orientation[3] = 3.0f;  // |q| = 3
    bad.push_back(v);
    v = m;
    v.orientation[3] = 0.4f;  // |q| = 0.4
    bad.push_back(v);
    driver.update(nullptr, target);
    EXPECT_TRUE(sameTransform(target, before));
    EXPECT_EQ(driver.engaged(), engaged);
    for (std::size_t k = 0; k < bad.size(); ++k) {
      driver.update(&bad[k], target);
      EXPECT_TRUE(sameTransform(target, before)) << "sample " << k << (engaged ? " (engaged)" : " (released)");
      EXPECT_EQ(driver.engaged(), engaged) << "sample " << k;
    }
    // A usable sample at the same pose does move an engaged region (the checks above could fail).
    driver.update(&m, target);
    EXPECT_EQ(sameTransform(target, before), !engaged);
    EXPECT_TRUE(driver.engaged());
  }
}

TEST(PoseSensor, ANegatedQuaternionGivesTheSameTargetWithoutASignFlip) {
  // q and -q are one orientation; the target's quaternion stays in the previous one's hemisphere.
  PoseSensorDriver driver(clutchSensor(), obliqueAlignment(), Eigen::Vector3d(1, 2, 3));
  RigidTransform target;
  Marker m;
  m.valid = 1;
  m.has_orientation = 1;
  m.buttons = 0x01;
  driver.update(&m, target);  // press at identity
  const Eigen::Quaterniond turn(Eigen::AngleAxisd(2.0, Eigen::Vector3d(0.3, 0.9, -0.2).normalized()));
  const float q[4] = {static_cast<float>(turn.w()), static_cast<float>(turn.x()), static_cast<float>(turn.y()), static_cast<float>(turn.z())};
  for (int k = 0; k < 4; ++k) m.orientation[k] = q[k];
  driver.update(&m, target);
  const RigidTransform first = target;
  for (int k = 0; k < 4; ++k) m.orientation[k] = -q[k];
  driver.update(&m, target);
  EXPECT_GT(target.rotation.dot(first.rotation), 0.999999);
  EXPECT_LT((target.rotation.coeffs() - first.rotation.coeffs()).norm(), 1e-12);
  EXPECT_LT((target.translation - first.translation).norm(), 1e-12);
}

TEST(PoseSensor, MirroredAlignmentStillGivesProperRotations) {
  // A device whose axes are a mirror image of the rig's (det A < 0): controller rotations map as
  // Q R Q^T, which is a proper rotation.
  const RigAlignment alignment = obliqueAlignment(true);
  ASSERT_LT(alignment.linear.determinant(), 0.0);
  const Eigen::Matrix3d q = alignment.linear / 0.1;
  PoseSensorDriver driver(clutchSensor(1.0), alignment, Eigen::Vector3d(1, 1, 1));
  RigidTransform target;
  Marker m;
  m.valid = 1;
  m.has_orientation = 1;
  m.buttons = 0x01;
  driver.update(&m, target);  // press at identity
  const Eigen::Vector3d axis = Eigen::Vector3d(0.6, -0.1, 0.4).normalized();
  const Eigen::Quaterniond turn(Eigen::AngleAxisd(2.5, axis));
  m.orientation[0] = static_cast<float>(turn.w());
  m.orientation[1] = static_cast<float>(turn.x());
  m.orientation[2] = static_cast<float>(turn.y());
  m.orientation[3] = static_cast<float>(turn.z());
  driver.update(&m, target);
  const Eigen::Matrix3d got = target.rotation.toRotationMatrix();
  EXPECT_NEAR(got.determinant(), 1.0, 1e-12);
  EXPECT_LT((got - q * turn.toRotationMatrix() * q.transpose()).norm(), 1e-6);  // float input
  // Not the conjugate by the unmirrored rotation.
  const Eigen::Matrix3d unmirrored = obliqueAlignment(false).linear / 0.1;
  EXPECT_GT((got - unmirrored * turn.toRotationMatrix() * unmirrored.transpose()).norm(), 0.1);
}

TEST(PoseSensor, ConstructorRefusesWhatCannotWork) {
  const RigAlignment good = obliqueAlignment();
  RigAlignment singular = good;
  singular.linear.col(2).setZero();
  EXPECT_THROW(PoseSensorDriver(clutchSensor(), singular, Eigen::Vector3d::Zero()), std::invalid_argument);
  EXPECT_THROW(PoseSensorDriver(clutchSensor(0.0), good, Eigen::Vector3d::Zero()), std::invalid_argument);
  EXPECT_THROW(PoseSensorDriver(clutchSensor(), good, Eigen::Vector3d(0, std::nan(""), 0)), std::invalid_argument);
  RigPoseSensor no_button = clutchSensor();
  no_button.clutch_buttons = 0;
  EXPECT_THROW(PoseSensorDriver(no_button, good, Eigen::Vector3d::Zero()), std::invalid_argument);
  no_button.mode = PoseSensorMode::kAbsolute;
  EXPECT_NO_THROW(PoseSensorDriver(no_button, good, Eigen::Vector3d::Zero()));
}

TEST(PoseSensor, RegionRestCentroidAveragesDistinctCorners) {
  const scenes::BarScene bar = scenes::makeBarScene(4, 4, 33);
  RegionHandle far{bar.far_tets, true};
  const Eigen::Vector3d c = regionRestCentroid(bar.mesh, far);
  // The far layer's corners: the 5 x 5 grid at z = 32 and at z = 33.
  EXPECT_LT((c - Eigen::Vector3d(2.0, 2.0, 32.5)).norm(), 1e-12);
  const RegionHandle empty{{}, true};
  const RegionHandle outside{{bar.mesh.tetCount()}, true};
  EXPECT_THROW((void)regionRestCentroid(bar.mesh, empty), std::invalid_argument);
  EXPECT_THROW((void)regionRestCentroid(bar.mesh, outside), std::invalid_argument);
}

TEST(PoseSensor, UpdateDoesNotAllocate) {
  const ClutchRecording rec = makeClutchRecording();
  const std::vector<MarkerFrame> frames = decodeRecording(rec.frames);
  PoseSensorDriver clutch(clutchSensor(), obliqueAlignment(), Eigen::Vector3d(2, 2, 32.5));
  RigPoseSensor abs_sensor = clutchSensor();
  abs_sensor.mode = PoseSensorMode::kAbsolute;
  PoseSensorDriver absolute(abs_sensor, obliqueAlignment(true), Eigen::Vector3d(2, 2, 0.5));
  RigidTransform a, b;
  Eigen::internal::set_is_malloc_allowed(false);
  const std::uint64_t before = test::allocationCount();
  for (const MarkerFrame& f : frames) {
    clutch.update(findMarker(f, 1), a);
    absolute.update(findMarker(f, 1), b);
    clutch.update(nullptr, a);
  }
  const std::uint64_t after = test::allocationCount();
  Eigen::internal::set_is_malloc_allowed(true);
  EXPECT_EQ(after - before, 0u);
  EXPECT_GT(a.translation.norm(), 0.0);  // the updates did run
  // The counter sees allocations (the check above could fail).
  void* probe = ::operator new(32);
  ::operator delete(probe);
  EXPECT_EQ(test::allocationCount() - after, 1u);
}

// Twist angle (radians, unwrapped against `previous`) of vertex v about the bar's long axis.
double twistAngle(const scenes::BarScene& bar, const Deformer& deformer, std::int32_t v, double previous) {
  const Eigen::Vector3d p = deformer.position(v) - bar.axis_point;
  const Eigen::Vector3d r = Eigen::Vector3d(bar.mesh.vertices.row(v).transpose()) - bar.axis_point;
  double angle = std::atan2(p.y(), p.x()) - std::atan2(r.y(), r.x());
  while (angle - previous > M_PI) angle -= 2 * M_PI;
  while (angle - previous < -M_PI) angle += 2 * M_PI;
  return angle;
}

TEST(PoseSensor, DeformerOnTheBarTwistsAndBendsAsTheClutchSays) {
  // The bar (4 x 4 x 33 units) with its two end layers as oriented regions, hydra0 on the near end
  // and hydra1 on the far end, both in clutch mode; device mm -> 0.1 units, same axes. hydra0
  // never presses: the near end stays at rest. hydra1: press, twist 270 degrees about the device
  // z axis (the bar's axis) in 9-degree steps, release; press again, move 60 mm along y (6 units:
  // a bend), release.
  const scenes::BarScene bar = scenes::makeBarScene(4, 4, 33);
  DeformerSetup setup;
  setup.region_handles = {RegionHandle{bar.near_tets, true}, RegionHandle{bar.far_tets, true}};
  Deformer deformer(bar.mesh, setup);
  RigAlignment alignment;
  alignment.linear = 0.1 * Eigen::Matrix3d::Identity();
  alignment.rig_units_per_mm = 0.1;
  RigPoseSensor near_sensor = clutchSensor(1.0), far_sensor = clutchSensor(1.0);
  near_sensor.sensor_label = "hydra0";
  near_sensor.region_handle = 0;
  std::vector<PoseSensorDriver> drivers;
  drivers.emplace_back(near_sensor, alignment, regionRestCentroid(bar.mesh, setup.region_handles[0]));
  drivers.emplace_back(far_sensor, alignment, regionRestCentroid(bar.mesh, setup.region_handles[1]));

  std::vector<RecordedFrame> recording;
  RecordedFrame f;
  f.controller[0].position_mm = Eigen::Vector3d(-150, 0, 200);
  f.controller[1].position_mm = Eigen::Vector3d(150, 0, 200);
  f.controller[1].orientation = Eigen::Quaterniond(Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitX()));
  const Eigen::Quaterniond start = f.controller[1].orientation;
  recording.push_back(f);
  f.controller[1].buttons = 0x01;
  recording.push_back(f);  // press
  const int twist_steps = 30;
  for (int k = 1; k <= twist_steps; ++k) {
    f.controller[1].orientation = Eigen::AngleAxisd(9.0 * k * kDeg, Eigen::Vector3d::UnitZ()) * start;
    recording.push_back(f);
  }
  const std::size_t twist_end = recording.size();
  f.controller[1].buttons = 0;
  f.controller[1].orientation = start;  // turned back while released: must not untwist the bar
  recording.push_back(f);
  f.controller[1].buttons = 0x01;
  recording.push_back(f);  // second press
  for (int k = 1; k <= 12; ++k) {
    f.controller[1].position_mm.y() += 5;
    recording.push_back(f);
  }
  f.controller[1].buttons = 0;
  recording.push_back(f);
  const std::vector<MarkerFrame> frames = decodeRecording(recording);

  std::vector<RigidTransform> regions(2);
  HandleTargets targets;
  targets.region_transforms = regions;
  // Mid-bar corner vertex (0, 0, 16), off the axis; the free part spans z in [1, 32].
  const std::int32_t mid = 16 * 25;
  const double fraction = (16.0 - 1.0) / (32.0 - 1.0);
  double twist = 0.0, worst_lag = 0.0;
  auto driveFrame = [&](const MarkerFrame& frame) {
    for (std::size_t s = 0; s < 2; ++s) drivers[s].update(findMarker(frame, static_cast<std::uint16_t>(s)), regions[s]);
    const StepStats stats = deformer.step(targets, StepBudget{3});
    EXPECT_EQ(stats.flags & (kStepTargetsRejected | kStepTargetsWrongSize), 0u);
  };
  for (std::size_t i = 0; i < twist_end; ++i) {
    driveFrame(frames[i]);
    twist = twistAngle(bar, deformer, mid, twist);
    const double commanded = i >= 2 ? 9.0 * kDeg * static_cast<double>(i - 1) : 0.0;
    worst_lag = std::max(worst_lag, std::abs(fraction * commanded - twist));
  }
  const double far_twist = Eigen::AngleAxisd(regions[1].rotation).angle() *
                           (Eigen::AngleAxisd(regions[1].rotation).axis().z() < 0 ? -1.0 : 1.0);
  std::printf("bar twist through the clutch: far end %.1f deg (as a rotation), mid-bar %.1f deg (expected %.1f), worst lag %.2f deg\n",
              far_twist / kDeg, twist / kDeg, fraction * 270.0, worst_lag / kDeg);
  // The region target is 270 degrees about z (= -90 as a rotation); the mid-bar follows the
  // unwrapped twist, so the twist went the long way round with the controller.
  EXPECT_NEAR(std::abs(far_twist), 90.0 * kDeg, 1e-3);
  EXPECT_NEAR(twist, fraction * 270.0 * kDeg, 10.0 * kDeg);
  EXPECT_LT(worst_lag, 10.0 * kDeg);
  EXPECT_TRUE(sameTransform(regions[0], RigidTransform{}));

  // Released and turned back, then the bend.
  const RigidTransform after_twist = regions[1];
  for (std::size_t i = twist_end; i < frames.size(); ++i) {
    driveFrame(frames[i]);
    if (i == twist_end) {
      EXPECT_TRUE(sameTransform(regions[1], after_twist)) << "released: no change";
    }
  }
  for (int extra = 0; extra < 20; ++extra) deformer.step(targets, StepBudget{3});
  // The far end moved 6 units along y and kept its twist; the region's vertices sit exactly where
  // its target transform puts them, the near end's at rest.
  EXPECT_LT((regions[1].translation - after_twist.translation - Eigen::Vector3d(0, 6, 0)).norm(), 1e-9);
  EXPECT_LT(regions[1].rotation.angularDistance(after_twist.rotation), 1e-12);
  double far_error = 0.0, near_error = 0.0;
  for (const std::int32_t v : bar.far_vertices) {
    const Eigen::Vector3d rest = bar.mesh.vertices.row(v).transpose();
    far_error = std::max(far_error, (deformer.position(v) - (regions[1].rotation * rest + regions[1].translation)).norm());
  }
  for (const std::int32_t v : bar.near_vertices) {
    near_error = std::max(near_error, (deformer.position(v) - Eigen::Vector3d(bar.mesh.vertices.row(v).transpose())).norm());
  }
  EXPECT_LT(far_error, 1e-9 * bar.length);
  EXPECT_LT(near_error, 1e-9 * bar.length);
  // The bend: the middle of the bar moved part of the way (between the fixed and the moved end).
  Eigen::Vector3d mid_shift = Eigen::Vector3d::Zero();
  int count = 0;
  for (std::int32_t v = 0; v < bar.mesh.vertexCount(); ++v) {
    if (std::abs(bar.mesh.vertices(v, 2) - 16.0) > 1e-9) continue;
    mid_shift += deformer.position(v) - Eigen::Vector3d(bar.mesh.vertices.row(v).transpose());
    ++count;
  }
  mid_shift /= count;
  std::printf("bend: far end +6 in y, mid-bar cross-section moved %.2f in y\n", mid_shift.y());
  EXPECT_GT(mid_shift.y(), 1.0);
  EXPECT_LT(mid_shift.y(), 5.0);
}

}  // namespace
}  // namespace tetrig
