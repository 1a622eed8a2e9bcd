#include "scenes.hpp"

#include <algorithm>
#include <cmath>
#include <utility>

namespace tetrig::scenes {

TetMesh makeBar(int nx, int ny, int nz) {
  TetMesh mesh;
  const int vx = nx + 1, vy = ny + 1, vz = nz + 1;
  mesh.vertices.resize(static_cast<Eigen::Index>(vx) * vy * vz, 3);
  auto id = [&](int i, int j, int k) { return static_cast<std::int32_t>((k * vy + j) * vx + i); };
  for (int k = 0; k < vz; ++k)
    for (int j = 0; j < vy; ++j)
      for (int i = 0; i < vx; ++i) mesh.vertices.row(id(i, j, k)) << i, j, k;

  // Corner c of a cube has offset bits (c & 1, c >> 1 & 1, c >> 2 & 1).
  // Even cubes: central tet on the odd-bit-count corners {1, 2, 4, 7}, corner tets at 0, 3, 5, 6.
  // Odd cubes: the mirror image, central tet {0, 3, 5, 6}, corner tets at 1, 2, 4, 7.
  static constexpr int kEven[5][4] = {{1, 2, 4, 7}, {0, 1, 2, 4}, {3, 1, 2, 7}, {5, 1, 4, 7}, {6, 2, 4, 7}};
  static constexpr int kOdd[5][4] = {{0, 3, 5, 6}, {1, 0, 3, 5}, {2, 0, 3, 6}, {4, 0, 5, 6}, {7, 3, 5, 6}};
  mesh.tets.resize(static_cast<Eigen::Index>(nx) * ny * nz * 5, 4);
  Eigen::Index t = 0;
  for (int k = 0; k < nz; ++k)
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i) {
        const auto& split = ((i + j + k) % 2 == 0) ? kEven : kOdd;
        for (const auto& tet : split) {
          for (int c = 0; c < 4; ++c) {
            const int b = tet[c];
            mesh.tets(t, c) = id(i + (b & 1), j + ((b >> 1) & 1), k + ((b >> 2) & 1));
          }
          if (signedVolume(mesh, static_cast<std::int32_t>(t)) < 0.0) std::swap(mesh.tets(t, 2), mesh.tets(t, 3));
          ++t;
        }
      }
  return mesh;
}

BarScene makeBarScene(int nx, int ny, int nz) {
  BarScene bar;
  bar.mesh = makeBar(nx, ny, nz);
  bar.nx = nx;
  bar.ny = ny;
  bar.nz = nz;
  bar.length = nz;
  bar.axis_point = Eigen::Vector3d(0.5 * nx, 0.5 * ny, 0.0);
  const double eps = 1e-9;
  std::vector<char> near(static_cast<size_t>(bar.mesh.vertexCount())), far(near.size());
  for (std::int32_t v = 0; v < bar.mesh.vertexCount(); ++v) {
    const double z = bar.mesh.vertices(v, 2);
    if (z <= 0.05 * bar.length + eps) {
      bar.near_vertices.push_back(v);
      near[static_cast<size_t>(v)] = 1;
    }
    if (z >= 0.95 * bar.length - eps) {
      bar.far_vertices.push_back(v);
      far[static_cast<size_t>(v)] = 1;
    }
  }
  for (std::int32_t t = 0; t < bar.mesh.tetCount(); ++t) {
    bool all_near = true, all_far = true;
    for (int c = 0; c < 4; ++c) {
      all_near = all_near && near[static_cast<size_t>(bar.mesh.tets(t, c))];
      all_far = all_far && far[static_cast<size_t>(bar.mesh.tets(t, c))];
    }
    if (all_near) bar.near_tets.push_back(t);
    if (all_far) bar.far_tets.push_back(t);
  }
  return bar;
}

Eigen::Isometry3d barAxisTransform(const BarScene& bar, double angle, const Eigen::Vector3d& shift) {
  Eigen::Isometry3d transform = Eigen::Isometry3d::Identity();
  transform.translate(bar.axis_point + shift);
  transform.rotate(Eigen::AngleAxisd(angle, Eigen::Vector3d::UnitZ()));
  transform.translate(-bar.axis_point);
  return transform;
}

Eigen::Isometry3d barBendTransform(const BarScene& bar, double angle) {
  // The far region starts at s0 (its lowest z); the free part runs from the near region's top
  // s_near to s0 and bends into an arc of radius rho = (s0 - s_near) / angle.
  double s_near = 0.0, s0 = bar.length;
  for (auto v : bar.near_vertices) s_near = std::max(s_near, bar.mesh.vertices(v, 2));
  for (auto v : bar.far_vertices) s0 = std::min(s0, bar.mesh.vertices(v, 2));
  Eigen::Isometry3d transform = Eigen::Isometry3d::Identity();
  if (std::abs(angle) < 1e-12) return transform;
  const double rho = (s0 - s_near) / angle;
  // Arc point at s0 (bending towards +y) and the end's rotation about x by -angle (z turns to +y).
  const Eigen::Vector3d pivot_rest = bar.axis_point + Eigen::Vector3d(0.0, 0.0, s0);
  const Eigen::Vector3d pivot_bent =
      bar.axis_point + Eigen::Vector3d(0.0, rho * (1.0 - std::cos(angle)), s_near + rho * std::sin(angle));
  transform.translate(pivot_bent);
  transform.rotate(Eigen::AngleAxisd(-angle, Eigen::Vector3d::UnitX()));
  transform.translate(-pivot_rest);
  return transform;
}

std::vector<Eigen::Vector3d> transformedPositions(const TetMesh& mesh, const std::vector<std::int32_t>& vertices,
                                                  const Eigen::Isometry3d& transform) {
  std::vector<Eigen::Vector3d> out;
  out.reserve(vertices.size());
  for (auto v : vertices) out.push_back(transform * Eigen::Vector3d(mesh.vertices.row(v).transpose()));
  return out;
}

}  // namespace tetrig::scenes
