// The camera shared by the picture sheet and `tetrig view`: a perspective camera orbiting a
// target, framing a bounding sphere. Column-major 4x4 matrices (OpenGL's layout). The "front"
// of a rig depends on its up axis: Z up looks from -Y (the C3D / motion-capture convention),
// Y up from +Z (the OBJ / glTF convention), X up from +Z; screen right is +X for Z and Y up.
//
// Tools only; no GL calls, no allocation.
#pragma once

#include <Eigen/Core>

#include <span>

namespace tetrig::render {

// Axis-aligned bounds of x, y, z triples; empty() while nothing finite was added.
struct Bounds {
  Eigen::Vector3f min{1e30f, 1e30f, 1e30f};
  Eigen::Vector3f max{-1e30f, -1e30f, -1e30f};
  void add(std::span<const float> xyz);  // skips non-finite points
  bool empty() const { return min.x() > max.x(); }
  Eigen::Vector3f center() const { return 0.5f * (min + max); }
  float radius() const { return empty() ? 1.0f : 0.5f * (max - min).norm(); }
};

struct OrbitCamera {
  Eigen::Vector3f target{0.0f, 0.0f, 0.0f};
  float radius = 1.0f;          // of the sphere around `target` that fills the view at zoom 1
  float azimuth_deg = 30.0f;    // turn about the up axis, from the front
  float elevation_deg = 10.0f;  // above the horizon, [-89, 89]
  float zoom = 1.0f;            // distance factor: < 1 nearer
  int up_axis = 2;              // 0, 1 or 2
  float fov_y_deg = 30.0f;
  // Half the size of the box around `target` to frame (all zero: frame the sphere only). A box
  // frames tighter than its sphere: a T-pose fills the picture instead of a third of it.
  Eigen::Vector3f half_extent{0.0f, 0.0f, 0.0f};

  // Frames `bounds` (its box, within its bounding sphere's depth range).
  static OrbitCamera framing(const Bounds& bounds, int up_axis, float azimuth_deg, float elevation_deg);

  Eigen::Vector3f up() const;
  Eigen::Vector3f direction() const;  // unit vector from the target towards the eye
  Eigen::Vector3f eye(float aspect) const;
  Eigen::Matrix4f view(float aspect) const;
  Eigen::Matrix4f projection(float aspect) const;
  // Distance from the target at which the box (else the sphere) fits both fields of view, times zoom.
  float distance(float aspect) const;
};

}  // namespace tetrig::render
