// The orbit camera of render/camera.hpp: look-at and perspective matrices (the classic OpenGL
// gluLookAt / gluPerspective forms), distance chosen so a bounding sphere fits the field of view.
#include "tetrig/render/camera.hpp"

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>

namespace tetrig::render {

namespace {

constexpr float kPi = 3.14159265358979f;
float radians(float deg) { return deg * kPi / 180.0f; }

// Unit vector from the target towards the camera at azimuth 0, elevation 0.
Eigen::Vector3f frontDirection(int up_axis) {
  if (up_axis == 2) return {0.0f, -1.0f, 0.0f};
  return {0.0f, 0.0f, 1.0f};
}

}  // namespace

void Bounds::add(std::span<const float> xyz) {
  for (std::size_t i = 0; i + 2 < xyz.size(); i += 3) {
    const Eigen::Vector3f p(xyz[i], xyz[i + 1], xyz[i + 2]);
    if (!p.allFinite()) continue;
    min = min.cwiseMin(p);
    max = max.cwiseMax(p);
  }
}

OrbitCamera OrbitCamera::framing(const Bounds& bounds, int up_axis, float azimuth_deg, float elevation_deg) {
  OrbitCamera c;
  c.target = bounds.empty() ? Eigen::Vector3f::Zero() : bounds.center();
  c.radius = std::max(bounds.radius(), 1e-6f);
  c.up_axis = std::clamp(up_axis, 0, 2);
  c.azimuth_deg = azimuth_deg;
  c.elevation_deg = std::clamp(elevation_deg, -89.0f, 89.0f);
  if (!bounds.empty()) c.half_extent = 0.5f * (bounds.max - bounds.min);
  return c;
}

Eigen::Vector3f OrbitCamera::up() const { return Eigen::Vector3f::Unit(std::clamp(up_axis, 0, 2)); }

Eigen::Vector3f OrbitCamera::direction() const {
  const Eigen::Vector3f u = up();
  const Eigen::Vector3f front = Eigen::AngleAxisf(radians(azimuth_deg), u) * frontDirection(std::clamp(up_axis, 0, 2));
  const float el = radians(std::clamp(elevation_deg, -89.0f, 89.0f));
  return std::cos(el) * front + std::sin(el) * u;
}

float OrbitCamera::distance(float aspect) const {
  const float tan_y = std::tan(0.5f * radians(fov_y_deg));
  const float tan_x = tan_y * std::max(aspect, 1e-3f);
  float d = radius / std::sin(std::atan(std::min(tan_x, tan_y)));  // the sphere
  if (half_extent.maxCoeff() > 0.0f) {
    // The box: corner c (from the target) at depth d - c.w must satisfy |c.s| <= tan_x (d - c.w)
    // and |c.v| <= tan_y (d - c.w), with w towards the eye, s right, v up on screen.
    const Eigen::Vector3f w = direction();
    const Eigen::Vector3f s = up().cross(w).normalized();
    const Eigen::Vector3f v = w.cross(s);
    d = 0.0f;
    for (int k = 0; k < 8; ++k) {
      const Eigen::Vector3f c((k & 1) ? half_extent.x() : -half_extent.x(), (k & 2) ? half_extent.y() : -half_extent.y(),
                              (k & 4) ? half_extent.z() : -half_extent.z());
      d = std::max({d, c.dot(w) + std::abs(c.dot(s)) / tan_x, c.dot(w) + std::abs(c.dot(v)) / tan_y});
    }
  }
  return zoom * d * 1.1f;  // a margin round the figure
}

Eigen::Vector3f OrbitCamera::eye(float aspect) const { return target + distance(aspect) * direction(); }

Eigen::Matrix4f OrbitCamera::view(float aspect) const {
  const Eigen::Vector3f e = eye(aspect);
  const Eigen::Vector3f f = (target - e).normalized();
  const Eigen::Vector3f s = f.cross(up()).normalized();
  const Eigen::Vector3f u = s.cross(f);
  Eigen::Matrix4f m = Eigen::Matrix4f::Identity();
  m.block<1, 3>(0, 0) = s.transpose();
  m.block<1, 3>(1, 0) = u.transpose();
  m.block<1, 3>(2, 0) = -f.transpose();
  m(0, 3) = -s.dot(e);
  m(1, 3) = -u.dot(e);
  m(2, 3) = f.dot(e);
  return m;
}

Eigen::Matrix4f OrbitCamera::projection(float aspect) const {
  const float d = distance(aspect);
  // The floor grid reaches about 2 radii out: keep it inside the depth range.
  const float near_plane = std::max(d - 3.0f * radius, d * 0.02f);
  const float far_plane = d + 3.0f * radius;
  const float t = 1.0f / std::tan(0.5f * radians(fov_y_deg));
  Eigen::Matrix4f p = Eigen::Matrix4f::Zero();
  p(0, 0) = t / std::max(aspect, 1e-3f);
  p(1, 1) = t;
  p(2, 2) = (far_plane + near_plane) / (near_plane - far_plane);
  p(2, 3) = 2.0f * far_plane * near_plane / (near_plane - far_plane);
  p(3, 2) = -1.0f;
  return p;
}

}  // namespace tetrig::render
