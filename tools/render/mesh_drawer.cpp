// The shaded surface of render/mesh_drawer.hpp (OpenGL 3.3 core). Per-vertex normals are the
// area-weighted sums of the adjacent faces' normals (the cross product of two edges is twice
// the face's area times its normal), recomputed on the CPU from each frame's positions: about
// 0.2 ms for 13k triangles, cheaper than a geometry pass and the same result on every driver.
// Lighting in view space: Lambert key + fill + ambient, a Blinn-Phong highlight and a rim term;
// back faces flip their normal (two-sided) and take their own tint.
#include "tetrig/render/mesh_drawer.hpp"
#include "tetrig/render/gl_program.hpp"

#include <Eigen/Geometry>
#include <epoxy/gl.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace tetrig::render {

namespace {

constexpr const char* kSurfaceVs = R"(#version 330 core
layout(location = 0) in vec3 a_position;
layout(location = 1) in vec3 a_normal;
uniform mat4 u_view;
uniform mat4 u_projection;
out vec3 v_normal;
out vec3 v_position;
void main() {
  vec4 p = u_view * vec4(a_position, 1.0);
  v_position = p.xyz;
  v_normal = mat3(u_view) * a_normal;
  gl_Position = u_projection * p;
}
)";

constexpr const char* kSurfaceFs = R"(#version 330 core
in vec3 v_normal;
in vec3 v_position;
uniform vec3 u_front;
uniform vec3 u_back;
out vec4 o_color;
void main() {
  float len = length(v_normal);
  vec3 n = len > 1e-12 ? v_normal / len : vec3(0.0, 0.0, 1.0);
  vec3 base = u_front;
  if (!gl_FrontFacing) { n = -n; base = u_back; }
  vec3 v = normalize(-v_position);
  vec3 key = normalize(vec3(-0.45, 0.65, 0.62));
  vec3 fill = normalize(vec3(0.7, -0.1, 0.45));
  float diffuse = 0.72 * max(dot(n, key), 0.0) + 0.28 * max(dot(n, fill), 0.0) + 0.16;
  float spec = 0.16 * pow(max(dot(n, normalize(key + v)), 0.0), 40.0);
  float rim = 0.22 * pow(1.0 - max(dot(n, v), 0.0), 3.0);
  o_color = vec4(min(base * diffuse + vec3(spec + rim), vec3(1.0)), 1.0);
}
)";

constexpr const char* kPointVs = R"(#version 330 core
layout(location = 0) in vec3 a_position;
uniform mat4 u_view;
uniform mat4 u_projection;
uniform float u_size;
void main() {
  gl_Position = u_projection * (u_view * vec4(a_position, 1.0));
  gl_PointSize = u_size;
}
)";

constexpr const char* kPointFs = R"(#version 330 core
uniform vec4 u_color;
uniform int u_round;
out vec4 o_color;
void main() {
  if (u_round != 0) {
    vec2 d = gl_PointCoord - vec2(0.5);
    float r2 = dot(d, d);
    if (r2 > 0.25) discard;
    o_color = vec4(u_color.rgb * (r2 > 0.12 ? 0.55 : 1.0), u_color.a);  // dark rim: visible on any background
  } else {
    o_color = u_color;
  }
}
)";

constexpr const char* kBackgroundVs = R"(#version 330 core
out float v_t;
void main() {
  vec2 p = vec2(gl_VertexID == 1 ? 3.0 : -1.0, gl_VertexID == 2 ? 3.0 : -1.0);
  v_t = 0.5 * p.y + 0.5;
  gl_Position = vec4(p, 0.0, 1.0);
}
)";

constexpr const char* kBackgroundFs = R"(#version 330 core
in float v_t;
uniform vec3 u_top;
uniform vec3 u_bottom;
out vec4 o_color;
void main() { o_color = vec4(mix(u_bottom, u_top, clamp(v_t, 0.0, 1.0)), 1.0); }
)";

void setMatrix(GLuint program, const char* name, const Eigen::Matrix4f& m) {
  glUniformMatrix4fv(glGetUniformLocation(program, name), 1, GL_FALSE, m.data());
}

// 1, 2 or 5 times a power of ten, near `x`.
float niceStep(float x) {
  const float p = std::pow(10.0f, std::floor(std::log10(std::max(x, 1e-12f))));
  const float m = x / p;
  return p * (m < 1.5f ? 1.0f : m < 3.5f ? 2.0f : m < 7.5f ? 5.0f : 10.0f);
}

}  // namespace

MeshDrawer::MeshDrawer(std::span<const std::int32_t> triangles, std::int32_t vertex_count) : vertex_count_(vertex_count) {
  if (vertex_count < 1) throw std::invalid_argument("mesh drawing: no vertices");
  if (triangles.size() % 3 != 0) throw std::invalid_argument("mesh drawing: triangle indices are not a multiple of 3");
  triangles_.reserve(triangles.size());
  for (std::size_t i = 0; i < triangles.size(); ++i) {
    if (triangles[i] < 0 || triangles[i] >= vertex_count) {
      throw std::invalid_argument("mesh drawing: triangle " + std::to_string(i / 3) + " has vertex index " + std::to_string(triangles[i]) +
                                  " outside [0, " + std::to_string(vertex_count) + ")");
    }
    triangles_.push_back(static_cast<std::uint32_t>(triangles[i]));
  }
  vertex_data_.assign(static_cast<std::size_t>(vertex_count) * 6, 0.0f);
  face_normals_.assign(static_cast<std::size_t>(vertex_count) * 3, 0.0f);

  surface_program_ = linkProgram(kSurfaceVs, kSurfaceFs, "surface");
  point_program_ = linkProgram(kPointVs, kPointFs, "points");
  background_program_ = linkProgram(kBackgroundVs, kBackgroundFs, "background");

  glGenVertexArrays(1, &mesh_vao_);
  glGenBuffers(1, &mesh_vbo_);
  glGenBuffers(1, &mesh_ebo_);
  glBindVertexArray(mesh_vao_);
  glBindBuffer(GL_ARRAY_BUFFER, mesh_vbo_);
  glBufferData(GL_ARRAY_BUFFER, static_cast<GLsizeiptr>(vertex_data_.size() * sizeof(float)), vertex_data_.data(), GL_DYNAMIC_DRAW);
  glBindBuffer(GL_ELEMENT_ARRAY_BUFFER, mesh_ebo_);
  glBufferData(GL_ELEMENT_ARRAY_BUFFER, static_cast<GLsizeiptr>(triangles_.size() * sizeof(std::uint32_t)), triangles_.data(),
               GL_STATIC_DRAW);
  glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, 6 * sizeof(float), nullptr);
  glVertexAttribPointer(1, 3, GL_FLOAT, GL_FALSE, 6 * sizeof(float), reinterpret_cast<const void*>(3 * sizeof(float)));
  glEnableVertexAttribArray(0);
  glEnableVertexAttribArray(1);

  glGenVertexArrays(1, &marker_vao_);
  glGenBuffers(1, &marker_vbo_);
  glBindVertexArray(marker_vao_);
  glBindBuffer(GL_ARRAY_BUFFER, marker_vbo_);
  glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, 3 * sizeof(float), nullptr);
  glEnableVertexAttribArray(0);

  glGenVertexArrays(1, &floor_vao_);
  glGenBuffers(1, &floor_vbo_);
  glBindVertexArray(floor_vao_);
  glBindBuffer(GL_ARRAY_BUFFER, floor_vbo_);
  glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, 3 * sizeof(float), nullptr);
  glEnableVertexAttribArray(0);

  glGenVertexArrays(1, &empty_vao_);
  glBindVertexArray(0);
}

MeshDrawer::~MeshDrawer() {
  const GLuint vaos[4] = {mesh_vao_, marker_vao_, floor_vao_, empty_vao_};
  glDeleteVertexArrays(4, vaos);
  const GLuint buffers[4] = {mesh_vbo_, mesh_ebo_, marker_vbo_, floor_vbo_};
  glDeleteBuffers(4, buffers);
  glDeleteProgram(surface_program_);
  glDeleteProgram(point_program_);
  glDeleteProgram(background_program_);
}

void MeshDrawer::setPositions(std::span<const float> xyz) {
  const std::size_t n = static_cast<std::size_t>(vertex_count_);
  if (xyz.size() != n * 3) {
    throw std::invalid_argument("mesh drawing: " + std::to_string(xyz.size()) + " coordinates for " + std::to_string(n) + " vertices");
  }
  std::fill(face_normals_.begin(), face_normals_.end(), 0.0f);
  auto at = [&](std::uint32_t v) {
    const float* p = &xyz[std::size_t{v} * 3];
    const Eigen::Vector3f q(p[0], p[1], p[2]);
    return q.allFinite() ? q : Eigen::Vector3f::Zero();
  };
  for (std::size_t t = 0; t + 2 < triangles_.size(); t += 3) {
    const Eigen::Vector3f a = at(triangles_[t]), b = at(triangles_[t + 1]), c = at(triangles_[t + 2]);
    const Eigen::Vector3f area_normal = (b - a).cross(c - a);  // |.| = 2 * area
    for (int k = 0; k < 3; ++k) {
      float* acc = &face_normals_[std::size_t{triangles_[t + static_cast<std::size_t>(k)]} * 3];
      acc[0] += area_normal.x();
      acc[1] += area_normal.y();
      acc[2] += area_normal.z();
    }
  }
  for (std::size_t v = 0; v < n; ++v) {
    const Eigen::Vector3f p = at(static_cast<std::uint32_t>(v));
    Eigen::Vector3f nn(face_normals_[v * 3], face_normals_[v * 3 + 1], face_normals_[v * 3 + 2]);
    const float len = nn.norm();
    nn = len > 1e-30f && std::isfinite(len) ? Eigen::Vector3f(nn / len) : Eigen::Vector3f(0.0f, 0.0f, 1.0f);
    float* out = &vertex_data_[v * 6];
    out[0] = p.x();
    out[1] = p.y();
    out[2] = p.z();
    out[3] = nn.x();
    out[4] = nn.y();
    out[5] = nn.z();
  }
  glBindBuffer(GL_ARRAY_BUFFER, mesh_vbo_);
  glBufferSubData(GL_ARRAY_BUFFER, 0, static_cast<GLsizeiptr>(vertex_data_.size() * sizeof(float)), vertex_data_.data());
}

void MeshDrawer::setMarkers(std::span<const float> xyz) {
  const auto count = static_cast<std::int32_t>(xyz.size() / 3);
  glBindBuffer(GL_ARRAY_BUFFER, marker_vbo_);
  if (count > marker_capacity_) {
    glBufferData(GL_ARRAY_BUFFER, static_cast<GLsizeiptr>(xyz.size() * sizeof(float)), xyz.data(), GL_DYNAMIC_DRAW);
    marker_capacity_ = count;
  } else if (count > 0) {
    glBufferSubData(GL_ARRAY_BUFFER, 0, static_cast<GLsizeiptr>(std::size_t(count) * 3 * sizeof(float)), xyz.data());
  }
  marker_count_ = count;
}

void MeshDrawer::setFloor(const Bounds& bounds, int up_axis) {
  up_axis = std::clamp(up_axis, 0, 2);
  const int a = (up_axis + 1) % 3, b = (up_axis + 2) % 3;
  const Eigen::Vector3f c = bounds.empty() ? Eigen::Vector3f::Zero() : bounds.center();
  const float half = bounds.empty() ? 1.0f
                                    : std::max({0.5f * (bounds.max[a] - bounds.min[a]), 0.5f * (bounds.max[b] - bounds.min[b]),
                                                0.25f * bounds.radius(), 1e-6f});
  const float extent = 1.6f * half;
  const float step = niceStep(extent / 4.0f);
  const int lines = std::min(static_cast<int>(std::ceil(extent / step)), 50);
  const float level = bounds.empty() ? 0.0f : bounds.min[up_axis];
  std::vector<float> v;
  v.reserve(static_cast<std::size_t>(2 * lines + 1) * 12);
  const float ca = std::round(c[a] / step) * step, cb = std::round(c[b] / step) * step;
  const float lo = -static_cast<float>(lines) * step, hi = static_cast<float>(lines) * step;
  auto push = [&](float pa, float pb) {
    Eigen::Vector3f p;
    p[up_axis] = level;
    p[a] = pa;
    p[b] = pb;
    v.insert(v.end(), {p.x(), p.y(), p.z()});
  };
  for (int i = -lines; i <= lines; ++i) {
    const float o = static_cast<float>(i) * step;
    push(ca + o, cb + lo);
    push(ca + o, cb + hi);
    push(ca + lo, cb + o);
    push(ca + hi, cb + o);
  }
  glBindBuffer(GL_ARRAY_BUFFER, floor_vbo_);
  glBufferData(GL_ARRAY_BUFFER, static_cast<GLsizeiptr>(v.size() * sizeof(float)), v.data(), GL_STATIC_DRAW);
  floor_vertices_ = static_cast<std::int32_t>(v.size() / 3);
}

void MeshDrawer::draw(const OrbitCamera& camera, int width, int height, const DrawStyle& style) {
  glViewport(0, 0, width, height);
  glDisable(GL_DEPTH_TEST);
  glDisable(GL_BLEND);
  glDisable(GL_CULL_FACE);
  glUseProgram(background_program_);
  glUniform3fv(glGetUniformLocation(background_program_, "u_top"), 1, kBackgroundTop);
  glUniform3fv(glGetUniformLocation(background_program_, "u_bottom"), 1, kBackgroundBottom);
  glBindVertexArray(empty_vao_);
  glDrawArrays(GL_TRIANGLES, 0, 3);
  glClear(GL_DEPTH_BUFFER_BIT);

  const float aspect = static_cast<float>(width) / static_cast<float>(std::max(height, 1));
  const Eigen::Matrix4f view = camera.view(aspect), projection = camera.projection(aspect);
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_LESS);

  if (style.floor_grid && floor_vertices_ > 0) {
    glEnable(GL_BLEND);
    glBlendFunc(GL_SRC_ALPHA, GL_ONE_MINUS_SRC_ALPHA);
    glDepthMask(GL_FALSE);
    glUseProgram(point_program_);
    setMatrix(point_program_, "u_view", view);
    setMatrix(point_program_, "u_projection", projection);
    glUniform1i(glGetUniformLocation(point_program_, "u_round"), 0);
    glUniform4f(glGetUniformLocation(point_program_, "u_color"), 0.62f, 0.65f, 0.70f, 0.45f);
    glBindVertexArray(floor_vao_);
    glDrawArrays(GL_LINES, 0, floor_vertices_);
    glDepthMask(GL_TRUE);
    glDisable(GL_BLEND);
  }

  glUseProgram(surface_program_);
  setMatrix(surface_program_, "u_view", view);
  setMatrix(surface_program_, "u_projection", projection);
  glUniform3fv(glGetUniformLocation(surface_program_, "u_front"), 1, style.surface_rgb);
  glUniform3fv(glGetUniformLocation(surface_program_, "u_back"), 1, style.back_rgb);
  glBindVertexArray(mesh_vao_);
  glDrawElements(GL_TRIANGLES, static_cast<GLsizei>(triangles_.size()), GL_UNSIGNED_INT, nullptr);

  if (marker_count_ > 0) {
    glEnable(GL_PROGRAM_POINT_SIZE);
    glUseProgram(point_program_);
    setMatrix(point_program_, "u_view", view);
    setMatrix(point_program_, "u_projection", projection);
    glUniform1i(glGetUniformLocation(point_program_, "u_round"), 1);
    glUniform1f(glGetUniformLocation(point_program_, "u_size"), style.marker_px);
    glUniform4f(glGetUniformLocation(point_program_, "u_color"), style.marker_rgb[0], style.marker_rgb[1], style.marker_rgb[2], 1.0f);
    glBindVertexArray(marker_vao_);
    glDrawArrays(GL_POINTS, 0, marker_count_);
  }
  glBindVertexArray(0);
  glUseProgram(0);
}

}  // namespace tetrig::render
