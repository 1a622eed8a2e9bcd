// Helpers for deformer tests: volumes, rigidity of deformation gradients, bar set-ups.
#pragma once

#include "scenes.hpp"
#include "tetrig/deformer.hpp"
#include "tetrig/laplacian.hpp"
#include "tetrig/polar.hpp"

#include <algorithm>
#include <cmath>
#include <vector>

namespace tetrig::test {

inline Vertices deformedVertices(const Deformer& deformer) {
  Vertices x(deformer.vertexCount(), 3);
  const auto p = deformer.positions();
  for (std::int32_t v = 0; v < deformer.vertexCount(); ++v)
    for (int c = 0; c < 3; ++c) x(v, c) = p[3 * static_cast<size_t>(v) + static_cast<size_t>(c)];
  return x;
}

inline double totalSignedVolume(const TetMesh& mesh, const Vertices& x) {
  TetMesh deformed{x, mesh.tets};
  double total = 0.0;
  for (std::int32_t t = 0; t < mesh.tetCount(); ++t) total += signedVolume(deformed, t);
  return total;
}

// Distance of each tet's deformation gradient from the nearest rotation, ||F - R(F)||_F.
struct Rigidity {
  double max = 0.0;
  double mean = 0.0;  // volume-weighted
};

inline Rigidity rigidity(const TetMesh& mesh, const Vertices& x) {
  const TetRestFrames frames = computeRestFrames(mesh);
  Rigidity out;
  double volume = 0.0;
  for (std::int32_t t = 0; t < mesh.tetCount(); ++t) {
    const Eigen::Matrix3d f = deformationGradient(mesh, frames, x, t);
    const double error = (f - closestRotation(f).toRotationMatrix()).norm();
    out.max = std::max(out.max, error);
    out.mean += frames.volume[static_cast<size_t>(t)] * error;
    volume += frames.volume[static_cast<size_t>(t)];
  }
  out.mean /= volume;
  return out;
}

// Vertex handles on both bar ends; targets: near at rest, far by `far`.
inline std::vector<Eigen::Vector3d> endTargets(const scenes::BarScene& bar, const Eigen::Isometry3d& far) {
  auto targets = scenes::transformedPositions(bar.mesh, bar.near_vertices, Eigen::Isometry3d::Identity());
  const auto far_targets = scenes::transformedPositions(bar.mesh, bar.far_vertices, far);
  targets.insert(targets.end(), far_targets.begin(), far_targets.end());
  return targets;
}

inline DeformerSetup endVertexHandles(const scenes::BarScene& bar) {
  DeformerSetup setup;
  setup.vertex_handles = bar.near_vertices;
  setup.vertex_handles.insert(setup.vertex_handles.end(), bar.far_vertices.begin(), bar.far_vertices.end());
  return setup;
}

// The exact ARAP energy of the deformer's pose: sum_j vol_j ||F_j - R_j||^2 with R_j the closest
// rotation (double, polar.hpp), not the kernel's float rotations.
inline double exactEnergy(const TetMesh& mesh, const Deformer& deformer) {
  double e = 0.0;
  for (std::int32_t t = 0; t < mesh.tetCount(); ++t) {
    Eigen::Matrix3d rest, now;
    for (int k = 0; k < 3; ++k) {
      rest.col(k) = (mesh.vertices.row(mesh.tets(t, k)) - mesh.vertices.row(mesh.tets(t, 3))).transpose();
      now.col(k) = deformer.position(mesh.tets(t, k)) - deformer.position(mesh.tets(t, 3));
    }
    const Eigen::Matrix3d f = now * rest.inverse();
    e += std::abs(rest.determinant()) / 6.0 * (f - closestRotation(f).toRotationMatrix()).squaredNorm();
  }
  return e;
}

}  // namespace tetrig::test
