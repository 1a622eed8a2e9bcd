// The shaded-surface drawing shared by the picture sheet and `tetrig view` (OpenGL 3.3 core,
// through libepoxy): a triangle mesh whose positions change every frame, smooth per-vertex
// normals recomputed from those positions (area-weighted face normals), two-sided lighting (a
// key light over the camera's shoulder, a fill and a rim, back faces tinted), a floor grid
// under the figure and markers as round dots.
//
// Needs a current OpenGL 3.3 core context for its whole life. The constructor allocates every
// buffer (CPU and GPU); setPositions() and draw() allocate nothing (setMarkers() only when the
// marker count grows). Not thread-safe (GL contexts are per thread anyway).
#pragma once

#include "tetrig/render/camera.hpp"

#include <cstdint>
#include <span>
#include <vector>

namespace tetrig::render {

struct DrawStyle {
  float surface_rgb[3] = {0.80f, 0.74f, 0.66f};
  float back_rgb[3] = {0.55f, 0.42f, 0.40f};   // inside faces (holes, open meshes)
  float marker_rgb[3] = {1.00f, 0.45f, 0.10f};
  float marker_px = 7.0f;                       // dot diameter, pixels
  bool floor_grid = true;
};

// The background both use (neutral grey, a little lighter at the top).
inline constexpr float kBackgroundTop[3] = {0.36f, 0.38f, 0.41f};
inline constexpr float kBackgroundBottom[3] = {0.20f, 0.21f, 0.23f};

class MeshDrawer {
 public:
  // `triangles`: 3 vertex indices each, counter-clockwise from outside; throws
  // std::invalid_argument when an index is outside [0, vertex_count) or vertex_count < 1.
  MeshDrawer(std::span<const std::int32_t> triangles, std::int32_t vertex_count);
  MeshDrawer(const MeshDrawer&) = delete;
  MeshDrawer& operator=(const MeshDrawer&) = delete;
  ~MeshDrawer();

  // vertex_count x 3 floats. Non-finite coordinates are drawn at the origin (never NaN normals).
  void setPositions(std::span<const float> xyz);
  // Marker positions (x, y, z each); empty: no dots.
  void setMarkers(std::span<const float> xyz);
  // Floor grid on the plane through `bounds`' lowest point along `up_axis`, around its footprint.
  void setFloor(const Bounds& bounds, int up_axis);

  // Clears the bound framebuffer's viewport (0, 0, width, height) to the background and draws.
  void draw(const OrbitCamera& camera, int width, int height, const DrawStyle& style = {});

  std::int32_t vertexCount() const { return vertex_count_; }

 private:
  std::int32_t vertex_count_;
  std::vector<std::uint32_t> triangles_;
  std::vector<float> vertex_data_;  // per vertex: position xyz, normal xyz
  std::vector<float> face_normals_; // scratch: per vertex accumulated normals
  std::int32_t marker_count_ = 0, marker_capacity_ = 0;
  std::int32_t floor_vertices_ = 0;
  unsigned surface_program_ = 0, point_program_ = 0, background_program_ = 0;
  unsigned mesh_vao_ = 0, mesh_vbo_ = 0, mesh_ebo_ = 0;
  unsigned marker_vao_ = 0, marker_vbo_ = 0;
  unsigned floor_vao_ = 0, floor_vbo_ = 0;
  unsigned empty_vao_ = 0;
};

}  // namespace tetrig::render
