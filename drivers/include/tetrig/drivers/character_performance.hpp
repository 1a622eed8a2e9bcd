// The project's default character: a humanoid skeleton in a T-pose, the implicit shape of its
// skin, a full-body marker set and a scripted performance, all pure functions (docs/character.md).
//
// Axes and units are those of a C3D clip (device space): millimetres, Z up, the character facing
// -Y with its left side towards +X, feet on z = 0, about 1.75 m tall - the axes of the HDM05 clips.
//
// Skeleton: 21 bones (pelvis, spine, chest, neck, head; clavicle, upper arm, lower arm and hand
// per side; thigh, shin, foot and toe per side). In the T-pose every bone's frame is the world
// frame placed at its joint, so a pose is one rotation per bone (relative to its parent) plus
// the pelvis's horizontal translation; its height follows the legs (the whole body is lifted or
// lowered so that the lower foot's ankle or ball is at its T-pose height: feet on the floor while
// walking and crouching). Forward kinematics gives each bone's world rotation R_b and joint
// position j_b, and a point fixed to bone b at T-pose position q moves to R_b (q - J_b) + j_b
// (J_b: the bone's T-pose joint).
//
// Skin: a smooth union (polynomial smooth minimum, blend width kCharacterSkinBlendMm) of tapered
// capsules along the bones, each the set of points within a linearly varying radius of a
// segment. characterSkinField() is that implicit function in the T-pose: negative inside,
// positive outside, close to a signed distance in mm near the surface. tools/character samples
// it into a level set and meshes it (assets/character/character.obj).
//
// Markers: the 41 labels of the HDM05 (Vicon full-body) layout, each fixed to one bone; its
// T-pose position is found by walking from a point inside the bone along a direction at the
// standard site until the skin field crosses zero, then kCharacterMarkerClearanceMm further.
//
// Performance (characterPerformanceSeconds() long): keyed joint angles (degrees)
// and pelvis translation interpolated by a cubic Hermite spline whose tangents are centred
// differences (Catmull-Rom on non-uniform keys; zero at the first and last key): T-pose, arms
// down, two steps out, a half turn, two steps back, a half turn, arms raised overhead, back to the
// T, torso twisted left and right, a crouch with the arms forward, back to the T-pose (9.6 s). It ends
// where it started (position and pose: the second half turn completes a full turn), so looping
// it is seamless.
//
// Threads and memory: every function is pure and may be called from any thread. The marker table
// is computed once, on first use (a function-local static, thread-safe initialisation); the
// per-frame functions allocate nothing.
#pragma once

#include <array>
#include <cstddef>
#include <span>
#include <string_view>

namespace tetrig::drivers {

inline constexpr int kCharacterBoneCount = 21;
inline constexpr int kCharacterMarkerCount = 41;
inline constexpr double kCharacterMarkerClearanceMm = 15.0;  // marker centre above the skin
inline constexpr double kCharacterSkinBlendMm = 30.0;        // smooth-union width

using CharacterVec3 = std::array<double, 3>;

struct CharacterBone {
  std::string_view name;  // "pelvis", "l_upper_arm", ...
  int parent;             // index of the parent bone; -1 for the pelvis (the root)
  CharacterVec3 joint;    // T-pose joint (the bone's origin), mm
  CharacterVec3 tip;      // T-pose end of the bone (the child's joint, or the end of a limb), mm
};

// A tapered capsule of the skin: points within radius a_radius + s (b_radius - a_radius) of the
// segment a-b, s in 0..1 the position of the closest segment point. T-pose, mm.
struct CharacterCapsule {
  int bone;
  CharacterVec3 a, b;
  double a_radius, b_radius;
};

struct CharacterMarker {
  std::string_view label;  // HDM05 label without the subject prefix ("LFHD")
  int bone;                // the bone it is fixed to
  CharacterVec3 tpose;     // T-pose position, mm
};

// World transforms of every bone for one instant: rotation (row-major 3x3) and joint position.
struct CharacterPose {
  std::array<std::array<double, 9>, kCharacterBoneCount> rotation;
  std::array<CharacterVec3, kCharacterBoneCount> joint;
};

// The skeleton (kCharacterBoneCount bones, parents before children) and the skin's capsules.
[[nodiscard]] std::span<const CharacterBone, kCharacterBoneCount> characterBones() noexcept;
[[nodiscard]] std::span<const CharacterCapsule> characterSkinCapsules() noexcept;

// The skin's implicit function at `p` (T-pose, mm): < 0 inside, > 0 outside. No allocation.
[[nodiscard]] double characterSkinField(const CharacterVec3& p) noexcept;

// The 41 markers in the HDM05 label order, with their T-pose positions. Computed on first call.
[[nodiscard]] std::span<const CharacterMarker, kCharacterMarkerCount> characterMarkers();

// Length of the performance in seconds (its last key).
[[nodiscard]] double characterPerformanceSeconds() noexcept;

// The pose at time `t` seconds (clamped to 0..characterPerformanceSeconds()). No allocation.
void characterPoseAt(double t, CharacterPose& out) noexcept;

// Every marker's position (mm) at time `t`, in characterMarkers() order. No allocation once
// characterMarkers() has been computed (the first call computes it).
void characterMarkersAt(double t, std::span<CharacterVec3, kCharacterMarkerCount> out);

// Moves a T-pose point fixed to `bone` by `pose`. No allocation.
[[nodiscard]] CharacterVec3 characterTransformPoint(const CharacterPose& pose, int bone, const CharacterVec3& tpose) noexcept;

// The skin's implicit function at `p` (mm) in `pose`: every capsule carried rigidly by its bone,
// joined by the same smooth union as in the T-pose. The character's true skin in that pose (where
// the skeleton bends, the union of the moved capsules; no flesh model), against which a deformed
// mesh is measured. Equals characterSkinField() in the T-pose. No allocation.
[[nodiscard]] double characterPosedSkinField(const CharacterPose& pose, const CharacterVec3& p) noexcept;

}  // namespace tetrig::drivers
