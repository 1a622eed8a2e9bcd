// The default character (character_performance.hpp): skeleton and skin tables, the markers found
// by marching from inside each bone to the skin, and the keyed performance evaluated by forward
// kinematics. Interpolation: cubic Hermite on non-uniform keys, tangent at key i the centred
// difference (p[i+1] - p[i-1]) / (t[i+1] - t[i-1]), set to zero at the ends and where key i is a
// local extremum or a hold (no overshoot past a held value).
#include "tetrig/drivers/character_performance.hpp"

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <stdexcept>
#include <string>

namespace tetrig::drivers {

namespace {

// --- skeleton (T-pose, mm; Z up, facing -Y, left = +X) ---
// clang-format off
constexpr std::array<CharacterBone, kCharacterBoneCount> kBones{{
  {"pelvis",      -1, {0, 0, 960},      {0, 0, 1060}},
  {"spine",        0, {0, 0, 1060},     {0, 0, 1200}},
  {"chest",        1, {0, 0, 1200},     {0, 5, 1420}},
  {"neck",         2, {0, 5, 1420},     {0, 5, 1530}},
  {"head",         3, {0, 5, 1530},     {0, 0, 1750}},
  {"l_clavicle",   2, {25, 10, 1410},   {185, 20, 1440}},
  {"l_upper_arm",  5, {185, 20, 1440},  {470, 20, 1440}},
  {"l_lower_arm",  6, {470, 20, 1440},  {735, 20, 1440}},
  {"l_hand",       7, {735, 20, 1440},  {905, 20, 1440}},
  {"r_clavicle",   2, {-25, 10, 1410},  {-185, 20, 1440}},
  {"r_upper_arm",  9, {-185, 20, 1440}, {-470, 20, 1440}},
  {"r_lower_arm", 10, {-470, 20, 1440}, {-735, 20, 1440}},
  {"r_hand",      11, {-735, 20, 1440}, {-905, 20, 1440}},
  {"l_thigh",      0, {95, 0, 900},     {95, 0, 490}},
  {"l_shin",      13, {95, 0, 490},     {95, 15, 85}},
  {"l_foot",      14, {95, 15, 85},     {95, -110, 25}},
  {"l_toe",       15, {95, -110, 25},   {95, -180, 20}},
  {"r_thigh",      0, {-95, 0, 900},    {-95, 0, 490}},
  {"r_shin",      17, {-95, 0, 490},    {-95, 15, 85}},
  {"r_foot",      18, {-95, 15, 85},    {-95, -110, 25}},
  {"r_toe",       19, {-95, -110, 25},  {-95, -180, 20}},
}};
enum Bone : int {
  kPelvis, kSpine, kChest, kNeck, kHead,
  kLClavicle, kLUpperArm, kLLowerArm, kLHand,
  kRClavicle, kRUpperArm, kRLowerArm, kRHand,
  kLThigh, kLShin, kLFoot, kLToe,
  kRThigh, kRShin, kRFoot, kRToe,
};

// --- skin: tapered capsules (bone, a, b, radius at a, radius at b) ---
constexpr CharacterCapsule kCapsules[] = {
  // hips, belly, chest (two capsules side by side give the trunk its oval section), shoulders
  {kPelvis, {-85, 5, 905}, {85, 5, 905}, 92, 92},
  {kPelvis, {45, 5, 960}, {45, 5, 1080}, 100, 98},
  {kPelvis, {-45, 5, 960}, {-45, 5, 1080}, 100, 98},
  {kSpine, {48, 5, 1080}, {55, 5, 1220}, 98, 100},
  {kSpine, {-48, 5, 1080}, {-55, 5, 1220}, 98, 100},
  {kChest, {58, 5, 1220}, {70, 15, 1375}, 100, 95},
  {kChest, {-58, 5, 1220}, {-70, 15, 1375}, 100, 95},
  {kLClavicle, {20, 15, 1415}, {180, 20, 1435}, 58, 58},
  {kRClavicle, {-20, 15, 1415}, {-180, 20, 1435}, 58, 58},
  // neck and head
  {kNeck, {0, 12, 1400}, {0, 8, 1545}, 55, 50},
  {kHead, {0, 0, 1595}, {0, -5, 1662}, 90, 86},
  // arms
  {kLUpperArm, {185, 20, 1440}, {470, 20, 1440}, 56, 40},
  {kLLowerArm, {470, 20, 1440}, {730, 20, 1440}, 40, 28},
  {kLHand, {745, 20, 1440}, {880, 20, 1438}, 27, 20},
  {kRUpperArm, {-185, 20, 1440}, {-470, 20, 1440}, 56, 40},
  {kRLowerArm, {-470, 20, 1440}, {-730, 20, 1440}, 40, 28},
  {kRHand, {-745, 20, 1440}, {-880, 20, 1438}, 27, 20},
  // legs
  {kLThigh, {95, 0, 905}, {95, 0, 490}, 88, 55},
  {kLShin, {95, 3, 490}, {95, 15, 100}, 52, 36},
  {kLFoot, {95, 50, 48}, {95, -100, 36}, 42, 34},
  {kLToe, {95, -105, 30}, {95, -160, 26}, 28, 23},
  {kRThigh, {-95, 0, 905}, {-95, 0, 490}, 88, 55},
  {kRShin, {-95, 3, 490}, {-95, 15, 100}, 52, 36},
  {kRFoot, {-95, 50, 48}, {-95, -100, 36}, 42, 34},
  {kRToe, {-95, -105, 30}, {-95, -160, 26}, 28, 23},
};

// --- markers: label, bone, a point inside the bone, the direction towards the marker's site ---
struct MarkerSite {
  std::string_view label;
  int bone;
  CharacterVec3 inside;
  CharacterVec3 direction;
};
constexpr std::array<MarkerSite, kCharacterMarkerCount> kSites{{
  {"LFHD", kHead, {0, 0, 1640}, {0.45, -0.8, 0.35}},
  {"RFHD", kHead, {0, 0, 1640}, {-0.45, -0.8, 0.35}},
  {"LBHD", kHead, {0, 0, 1630}, {0.45, 0.8, 0.25}},
  {"RBHD", kHead, {0, 0, 1630}, {-0.45, 0.8, 0.25}},
  {"C7",   kChest, {0, 10, 1440}, {0, 1, 0.3}},
  {"T10",  kChest, {0, 5, 1290}, {0, 1, 0}},
  {"CLAV", kChest, {0, 5, 1410}, {0, -1, 0.15}},
  {"STRN", kChest, {0, 5, 1300}, {0, -1, 0}},
  {"RBAC", kChest, {-85, 10, 1350}, {0, 1, 0}},
  {"LSHO", kLClavicle, {175, 20, 1440}, {0, 0, 1}},
  {"LUPA", kLUpperArm, {330, 20, 1440}, {0, 0.6, 0.8}},
  {"LELB", kLUpperArm, {455, 20, 1440}, {0, 1, 0}},
  {"LFRM", kLLowerArm, {600, 20, 1440}, {0, 0.5, 0.85}},
  {"LWRA", kLLowerArm, {725, 20, 1440}, {0, -1, 0}},
  {"LWRB", kLLowerArm, {725, 20, 1440}, {0, 1, 0}},
  {"LFIN", kLHand, {840, 20, 1440}, {0, 0, 1}},
  {"RSHO", kRClavicle, {-175, 20, 1440}, {0, 0, 1}},
  {"RUPA", kRUpperArm, {-330, 20, 1440}, {0, 0.6, 0.8}},
  {"RELB", kRUpperArm, {-455, 20, 1440}, {0, 1, 0}},
  {"RFRM", kRLowerArm, {-600, 20, 1440}, {0, 0.5, 0.85}},
  {"RWRA", kRLowerArm, {-725, 20, 1440}, {0, -1, 0}},
  {"RWRB", kRLowerArm, {-725, 20, 1440}, {0, 1, 0}},
  {"RFIN", kRHand, {-840, 20, 1440}, {0, 0, 1}},
  {"LFWT", kPelvis, {110, 0, 985}, {0.3, -0.95, 0}},
  {"RFWT", kPelvis, {-110, 0, 985}, {-0.3, -0.95, 0}},
  {"LBWT", kPelvis, {70, 0, 960}, {0.3, 0.95, 0}},
  {"RBWT", kPelvis, {-70, 0, 960}, {-0.3, 0.95, 0}},
  {"LTHI", kLThigh, {95, 0, 700}, {1, 0, 0}},
  {"LKNE", kLThigh, {95, 0, 500}, {1, 0, 0}},
  {"LSHN", kLShin, {95, 5, 300}, {1, -0.3, 0}},
  {"LANK", kLShin, {95, 15, 95}, {1, 0, 0}},
  {"LHEE", kLFoot, {95, 40, 45}, {0, 1, 0}},
  {"LTOE", kLFoot, {95, -95, 35}, {0, 0, 1}},
  {"LMT5", kLFoot, {95, -80, 35}, {1, 0, 0.2}},
  {"RTHI", kRThigh, {-95, 0, 700}, {-1, 0, 0}},
  {"RKNE", kRThigh, {-95, 0, 500}, {-1, 0, 0}},
  {"RSHN", kRShin, {-95, 5, 300}, {-1, -0.3, 0}},
  {"RANK", kRShin, {-95, 15, 95}, {-1, 0, 0}},
  {"RHEE", kRFoot, {-95, 40, 45}, {0, 1, 0}},
  {"RTOE", kRFoot, {-95, -95, 35}, {0, 0, 1}},
  {"RMT5", kRFoot, {-95, -80, 35}, {-1, 0, 0.2}},
}};

// --- performance: degrees of freedom and keys ---
enum Dof : int {
  kRootX, kRootY,          // pelvis translation from the T-pose, mm (its height follows the legs)
  kYaw,                    // whole body about +Z, degrees
  kSpineBend,              // trunk forward (towards the facing direction)
  kTwist,                  // trunk about its vertical axis
  kHeadYaw,
  kLArmRaise, kLArmForward, kLArmSwing, kLElbow,  // raise: up from the T; forward: horizontal, to the front;
  kRArmRaise, kRArmForward, kRArmSwing, kRElbow,  // swing: about the side axis (arms down); elbow: flexion
  kLHip, kLKnee, kLAnkle,  // hip flexion (thigh forward), knee flexion, ankle dorsiflexion (toes up)
  kRHip, kRKnee, kRAnkle,
  kDofCount
};
struct Key {
  double t;
  std::array<double, kDofCount> v;
};

// Poses used by the keys (root translation filled in per key).
using Pose = std::array<double, kDofCount>;
constexpr Pose kTPose{};
constexpr Pose armsDown(Pose p) {
  p[kLArmRaise] = p[kRArmRaise] = -75;
  p[kLElbow] = p[kRElbow] = 12;
  return p;
}
constexpr Pose at(Pose p, double x, double y, double yaw) {
  p[kRootX] = x;
  p[kRootY] = y;
  p[kYaw] = yaw;
  return p;
}
// Double support, `left_front`: one leg 20 degrees forward (heel strike), the other behind
// (toe-off), arms swinging against the legs.
constexpr Pose doubleSupport(bool left_front) {
  Pose p = armsDown(kTPose);
  const Dof front_hip = left_front ? kLHip : kRHip, back_hip = left_front ? kRHip : kLHip;
  p[front_hip] = 20;
  p[front_hip + 1] = 3;
  p[back_hip] = -20;
  p[back_hip + 1] = 15;
  p[back_hip + 2] = 20;
  p[left_front ? kLArmSwing : kRArmSwing] = -15;
  p[left_front ? kRArmSwing : kLArmSwing] = 15;
  return p;
}
// Mid-stance on one leg, the other swinging through with the knee bent.
constexpr Pose midStance(bool left_stance) {
  Pose p = armsDown(kTPose);
  const Dof stance = left_stance ? kLHip : kRHip, swing = left_stance ? kRHip : kLHip;
  p[stance + 1] = 5;
  p[swing] = 10;
  p[swing + 1] = 45;
  p[swing + 2] = 10;
  return p;
}
constexpr Pose armsUp() {
  Pose p = kTPose;
  p[kLArmRaise] = p[kRArmRaise] = 75;
  return p;
}
constexpr Pose twisted(double degrees) {
  Pose p = kTPose;
  p[kTwist] = degrees;
  p[kHeadYaw] = degrees / 4;
  return p;
}
// Crouch: hips 70, knees 110, ankles 40 (feet flat); the pelvis moves back so the ankles stay
// where they stood (and drops with the legs: see characterPoseAt); trunk leaning forward, arms
// reaching forward for balance.
constexpr Pose crouch() {
  Pose p = kTPose;
  p[kLHip] = p[kRHip] = 70;
  p[kLKnee] = p[kRKnee] = 110;
  p[kLAnkle] = p[kRAnkle] = 40;
  p[kSpineBend] = 25;
  p[kLArmForward] = p[kRArmForward] = 80;
  p[kLElbow] = p[kRElbow] = 10;
  return p;
}
constexpr double kHalfStepMm = 290;   // pelvis travel per half step
constexpr double kCrouchBackMm = 141;

constexpr std::array<Key, 22> kKeys{{
  {0.0, kTPose},
  {0.5, kTPose},
  {1.0, armsDown(kTPose)},
  // two steps out, facing -Y
  {1.3, at(doubleSupport(true), 0, -1 * kHalfStepMm, 0)},
  {1.6, at(midStance(true), 0, -2 * kHalfStepMm, 0)},
  {1.9, at(doubleSupport(false), 0, -3 * kHalfStepMm, 0)},
  {2.2, at(armsDown(kTPose), 0, -4 * kHalfStepMm, 0)},
  // half turn on the spot
  {2.9, at(armsDown(kTPose), 0, -4 * kHalfStepMm, 180)},
  // two steps back, facing +Y
  {3.2, at(doubleSupport(true), 0, -3 * kHalfStepMm, 180)},
  {3.5, at(midStance(true), 0, -2 * kHalfStepMm, 180)},
  {3.8, at(doubleSupport(false), 0, -1 * kHalfStepMm, 180)},
  {4.1, at(armsDown(kTPose), 0, 0, 180)},
  // half turn: facing -Y again
  {4.8, at(armsDown(kTPose), 0, 0, 360)},
  // arms raised overhead, back to the T, torso twist left and right
  {5.6, at(armsUp(), 0, 0, 360)},
  {6.2, at(kTPose, 0, 0, 360)},
  {6.7, at(twisted(40), 0, 0, 360)},
  {7.4, at(twisted(-40), 0, 0, 360)},
  {7.8, at(kTPose, 0, 0, 360)},
  // crouch and up
  {8.5, at(crouch(), 0, kCrouchBackMm, 360)},
  {8.7, at(crouch(), 0, kCrouchBackMm, 360)},
  {9.3, at(kTPose, 0, 0, 360)},
  {9.6, at(kTPose, 0, 0, 360)},
}};
// clang-format on

constexpr double kDeg = std::numbers::pi / 180.0;

Eigen::Vector3d vec(const CharacterVec3& a) { return {a[0], a[1], a[2]}; }
Eigen::Matrix3d rx(double deg) { return Eigen::AngleAxisd(deg * kDeg, Eigen::Vector3d::UnitX()).toRotationMatrix(); }
Eigen::Matrix3d ry(double deg) { return Eigen::AngleAxisd(deg * kDeg, Eigen::Vector3d::UnitY()).toRotationMatrix(); }
Eigen::Matrix3d rz(double deg) { return Eigen::AngleAxisd(deg * kDeg, Eigen::Vector3d::UnitZ()).toRotationMatrix(); }

// The performance's degrees of freedom at time t (clamped).
Pose dofsAt(double t) noexcept {
  const std::size_t n = kKeys.size();
  t = std::clamp(t, kKeys.front().t, kKeys.back().t);
  std::size_t i = 0;
  while (i + 2 < n && kKeys[i + 1].t <= t) ++i;
  const Key& k0 = kKeys[i];
  const Key& k1 = kKeys[i + 1];
  const double h = k1.t - k0.t;
  const double s = (t - k0.t) / h;
  const double s2 = s * s, s3 = s2 * s;
  const double h00 = 2 * s3 - 3 * s2 + 1, h10 = s3 - 2 * s2 + s, h01 = -2 * s3 + 3 * s2, h11 = s3 - s2;
  auto tangent = [&](std::size_t j, int d) {
    if (j == 0 || j + 1 >= n) return 0.0;
    const double before = kKeys[j].v[static_cast<std::size_t>(d)] - kKeys[j - 1].v[static_cast<std::size_t>(d)];
    const double after = kKeys[j + 1].v[static_cast<std::size_t>(d)] - kKeys[j].v[static_cast<std::size_t>(d)];
    if (before * after <= 0) return 0.0;  // extremum or hold: no overshoot
    return (before + after) / (kKeys[j + 1].t - kKeys[j - 1].t);
  };
  Pose out{};
  for (int d = 0; d < kDofCount; ++d) {
    const auto du = static_cast<std::size_t>(d);
    out[du] = h00 * k0.v[du] + h10 * h * tangent(i, d) + h01 * k1.v[du] + h11 * h * tangent(i + 1, d);
  }
  return out;
}

// Each bone's rotation relative to its parent for the given degrees of freedom (see the header
// for the axes: +X left, -Y forward, +Z up).
void localRotations(const Pose& p, std::array<Eigen::Matrix3d, kCharacterBoneCount>& r) noexcept {
  for (Eigen::Matrix3d& m : r) m.setIdentity();
  r[kPelvis] = rz(p[kYaw]);
  r[kSpine] = rz(0.4 * p[kTwist]) * rx(0.5 * p[kSpineBend]);
  r[kChest] = rz(0.6 * p[kTwist]) * rx(0.5 * p[kSpineBend]);
  r[kHead] = rz(p[kHeadYaw]);
  // Arms: raise about the forward axis, then forward about the vertical, swing about the side
  // axis; the clavicles follow 15 % of the raise.
  r[kLClavicle] = ry(-0.15 * p[kLArmRaise]);
  r[kRClavicle] = ry(0.15 * p[kRArmRaise]);
  r[kLUpperArm] = rx(-p[kLArmSwing]) * rz(-p[kLArmForward]) * ry(-0.85 * p[kLArmRaise]);
  r[kRUpperArm] = rx(-p[kRArmSwing]) * rz(p[kRArmForward]) * ry(0.85 * p[kRArmRaise]);
  r[kLLowerArm] = rz(-p[kLElbow]);
  r[kRLowerArm] = rz(p[kRElbow]);
  // Legs: flexion about the side axis.
  r[kLThigh] = rx(-p[kLHip]);
  r[kLShin] = rx(p[kLKnee]);
  r[kLFoot] = rx(-p[kLAnkle]);
  r[kRThigh] = rx(-p[kRHip]);
  r[kRShin] = rx(p[kRKnee]);
  r[kRFoot] = rx(-p[kRAnkle]);
}

// Signed distance-like value of one tapered capsule.
double capsuleField(const CharacterCapsule& c, const Eigen::Vector3d& p) noexcept {
  const Eigen::Vector3d a = vec(c.a), ab = vec(c.b) - a;
  const double s = std::clamp((p - a).dot(ab) / ab.squaredNorm(), 0.0, 1.0);
  return (p - (a + s * ab)).norm() - (c.a_radius + s * (c.b_radius - c.a_radius));
}

// Polynomial smooth minimum of width k: equal to min(a, b) when |a - b| >= k, else lowered by
// k/4 (1 - |a - b|/k)^2, which joins the two values with a continuous slope.
double smoothMin(double a, double b, double k) noexcept {
  const double h = std::max(k - std::abs(a - b), 0.0) / k;
  return std::min(a, b) - 0.25 * k * h * h;
}

std::array<CharacterMarker, kCharacterMarkerCount> computeMarkers() {
  std::array<CharacterMarker, kCharacterMarkerCount> out{};
  for (std::size_t i = 0; i < kSites.size(); ++i) {
    const MarkerSite& site = kSites[i];
    const Eigen::Vector3d from = vec(site.inside);
    const Eigen::Vector3d dir = vec(site.direction).normalized();
    if (!(characterSkinField(site.inside) < 0)) {
      throw std::logic_error("character marker " + std::string(site.label) + ": its start point is not inside the skin");
    }
    // March out in 1 mm steps, then bisect the crossing to 1e-6 mm.
    double lo = 0, hi = 0;
    auto field = [&](double s) {
      const Eigen::Vector3d q = from + s * dir;
      return characterSkinField({q.x(), q.y(), q.z()});
    };
    while (field(hi) < 0) {
      lo = hi;
      hi += 1.0;
      if (hi > 500) throw std::logic_error("character marker " + std::string(site.label) + ": no skin within 500 mm");
    }
    for (int it = 0; it < 40; ++it) {
      const double mid = 0.5 * (lo + hi);
      (field(mid) < 0 ? lo : hi) = mid;
    }
    const Eigen::Vector3d m = from + (hi + kCharacterMarkerClearanceMm) * dir;
    out[i] = CharacterMarker{site.label, site.bone, {m.x(), m.y(), m.z()}};
  }
  return out;
}

}  // namespace

std::span<const CharacterBone, kCharacterBoneCount> characterBones() noexcept { return kBones; }

std::span<const CharacterCapsule> characterSkinCapsules() noexcept { return kCapsules; }

double characterSkinField(const CharacterVec3& point) noexcept {
  const Eigen::Vector3d p = vec(point);
  double f = capsuleField(kCapsules[0], p);
  for (std::size_t i = 1; i < std::size(kCapsules); ++i) f = smoothMin(f, capsuleField(kCapsules[i], p), kCharacterSkinBlendMm);
  return f;
}

std::span<const CharacterMarker, kCharacterMarkerCount> characterMarkers() {
  static const std::array<CharacterMarker, kCharacterMarkerCount> markers = computeMarkers();
  return markers;
}

double characterPerformanceSeconds() noexcept { return kKeys.back().t; }

void characterPoseAt(double t, CharacterPose& out) noexcept {
  const Pose p = dofsAt(std::isfinite(t) ? t : 0.0);
  std::array<Eigen::Matrix3d, kCharacterBoneCount> local;
  localRotations(p, local);
  std::array<Eigen::Matrix3d, kCharacterBoneCount> world;
  std::array<Eigen::Vector3d, kCharacterBoneCount> joint;
  for (int b = 0; b < kCharacterBoneCount; ++b) {
    const auto bu = static_cast<std::size_t>(b);
    const CharacterBone& bone = kBones[bu];
    if (bone.parent < 0) {
      world[bu] = local[bu];
      joint[bu] = vec(bone.joint) + Eigen::Vector3d(p[kRootX], p[kRootY], 0.0);
    } else {
      const auto pu = static_cast<std::size_t>(bone.parent);
      world[bu] = world[pu] * local[bu];
      joint[bu] = joint[pu] + world[pu] * (vec(bone.joint) - vec(kBones[pu].joint));
    }
  }
  // The lower foot stands on the floor: the body is lifted or lowered so that the lowest ankle or
  // ball of the foot is at its T-pose height (no foot sinks into the floor or floats when the
  // legs bend or spread).
  double lift = 0.0;
  bool first = true;
  for (const int b : {kLFoot, kRFoot, kLToe, kRToe}) {
    const auto bu = static_cast<std::size_t>(b);
    const double below = kBones[bu].joint[2] - joint[bu].z();
    lift = first ? below : std::max(lift, below);
    first = false;
  }
  for (int b = 0; b < kCharacterBoneCount; ++b) {
    const auto bu = static_cast<std::size_t>(b);
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) out.rotation[bu][static_cast<std::size_t>(3 * r + c)] = world[bu](r, c);
    }
    out.joint[bu] = {joint[bu].x(), joint[bu].y(), joint[bu].z() + lift};
  }
}

CharacterVec3 characterTransformPoint(const CharacterPose& pose, int bone, const CharacterVec3& tpose) noexcept {
  const auto bu = static_cast<std::size_t>(bone);
  const auto& r = pose.rotation[bu];
  const CharacterVec3 d{tpose[0] - kBones[bu].joint[0], tpose[1] - kBones[bu].joint[1], tpose[2] - kBones[bu].joint[2]};
  CharacterVec3 out{};
  for (std::size_t k = 0; k < 3; ++k) out[k] = pose.joint[bu][k] + r[3 * k] * d[0] + r[3 * k + 1] * d[1] + r[3 * k + 2] * d[2];
  return out;
}

void characterMarkersAt(double t, std::span<CharacterVec3, kCharacterMarkerCount> out) {
  const auto markers = characterMarkers();
  CharacterPose pose;
  characterPoseAt(t, pose);
  for (std::size_t i = 0; i < markers.size(); ++i) out[i] = characterTransformPoint(pose, markers[i].bone, markers[i].tpose);
}

double characterPosedSkinField(const CharacterPose& pose, const CharacterVec3& point) noexcept {
  const Eigen::Vector3d p = vec(point);
  double f = 0.0;
  for (std::size_t i = 0; i < std::size(kCapsules); ++i) {
    CharacterCapsule c = kCapsules[i];
    c.a = characterTransformPoint(pose, c.bone, c.a);
    c.b = characterTransformPoint(pose, c.bone, c.b);
    const double fi = capsuleField(c, p);
    f = i == 0 ? fi : smoothMin(f, fi, kCharacterSkinBlendMm);
  }
  return f;
}

}  // namespace tetrig::drivers
