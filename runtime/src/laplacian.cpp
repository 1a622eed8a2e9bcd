// Tetrahedral Laplacian and differential coordinates: Stoll et al. 2007, eq. 2.2-2.5.
#include "tetrig/laplacian.hpp"

#include <Eigen/Dense>

#include <cmath>
#include <stdexcept>
#include <string>

namespace tetrig {

namespace {

Eigen::Matrix3d restEdges(const TetMesh& mesh, std::int32_t t) {
  const auto tet = mesh.tets.row(t);
  const Eigen::Vector3d p4 = mesh.vertices.row(tet[3]).transpose();
  Eigen::Matrix3d e;
  for (int k = 0; k < 3; ++k) e.col(k) = mesh.vertices.row(tet[k]).transpose() - p4;
  return e;
}

// Columns: grad phi_1 .. grad phi_4 of tet t.
Eigen::Matrix<double, 3, 4> gradients(const Eigen::Matrix3d& edge_inverse) {
  Eigen::Matrix<double, 3, 4> g;
  g.leftCols<3>() = edge_inverse.transpose();
  g.col(3) = -(g.col(0) + g.col(1) + g.col(2));
  return g;
}

}  // namespace

TetRestFrames computeRestFrames(const TetMesh& mesh) {
  TetRestFrames frames;
  const auto m = static_cast<size_t>(mesh.tetCount());
  frames.edge_inverse.resize(m);
  frames.volume.resize(m);
  for (std::int32_t t = 0; t < mesh.tetCount(); ++t) {
    for (int k = 0; k < 4; ++k) {
      if (mesh.tets(t, k) < 0 || mesh.tets(t, k) >= mesh.vertexCount()) {
        throw std::invalid_argument("tet " + std::to_string(t) + " references vertex " +
                                    std::to_string(mesh.tets(t, k)) + " but the mesh has " +
                                    std::to_string(mesh.vertexCount()) + " vertices");
      }
    }
    const Eigen::Matrix3d e = restEdges(mesh, t);
    const double det = e.determinant();
    const double scale = e.colwise().norm().maxCoeff();
    if (!std::isfinite(det) || std::abs(det) <= 1e-14 * scale * scale * scale) {
      throw std::invalid_argument("tet " + std::to_string(t) +
                                  " has zero volume: its gradient operator does not exist; remove or "
                                  "repair degenerate tets before loading");
    }
    frames.edge_inverse[static_cast<size_t>(t)] = e.inverse();
    frames.volume[static_cast<size_t>(t)] = std::abs(det) / 6.0;
  }
  return frames;
}

std::vector<double> tetWeights(const TetRestFrames& frames, std::span<const double> stiffness) {
  const size_t m = frames.volume.size();
  if (!stiffness.empty() && stiffness.size() != m) {
    throw std::invalid_argument("stiffness has " + std::to_string(stiffness.size()) + " values for " +
                                std::to_string(m) + " tets");
  }
  std::vector<double> weights(m);
  for (size_t t = 0; t < m; ++t) {
    const double s = stiffness.empty() ? 1.0 : stiffness[t];
    if (!(s > 0.0) || !std::isfinite(s)) {
      throw std::invalid_argument("stiffness of tet " + std::to_string(t) + " is " + std::to_string(s) +
                                  "; it must be a positive finite number");
    }
    weights[t] = s * frames.volume[t];
  }
  return weights;
}

Eigen::SparseMatrix<double> assembleLaplacian(const TetMesh& mesh, const TetRestFrames& frames,
                                              std::span<const double> weights) {
  std::vector<Eigen::Triplet<double>> triplets;
  triplets.reserve(static_cast<size_t>(mesh.tetCount()) * 16);
  for (std::int32_t t = 0; t < mesh.tetCount(); ++t) {
    const auto g = gradients(frames.edge_inverse[static_cast<size_t>(t)]);
    const Eigen::Matrix4d local = weights[static_cast<size_t>(t)] * (g.transpose() * g);
    for (int a = 0; a < 4; ++a)
      for (int b = 0; b < 4; ++b) triplets.emplace_back(mesh.tets(t, a), mesh.tets(t, b), local(a, b));
  }
  Eigen::SparseMatrix<double> laplacian(mesh.vertexCount(), mesh.vertexCount());
  laplacian.setFromTriplets(triplets.begin(), triplets.end());
  return laplacian;
}

Vertices differentialCoordinates(const TetMesh& mesh, const TetRestFrames& frames, std::span<const double> weights,
                                 std::span<const Eigen::Matrix3d> rotations) {
  Vertices delta = Vertices::Zero(mesh.vertexCount(), 3);
  for (std::int32_t t = 0; t < mesh.tetCount(); ++t) {
    const auto i = static_cast<size_t>(t);
    const Eigen::Matrix<double, 3, 4> contribution = weights[i] * rotations[i] * gradients(frames.edge_inverse[i]);
    for (int k = 0; k < 4; ++k) delta.row(mesh.tets(t, k)) += contribution.col(k).transpose();
  }
  return delta;
}

Eigen::Matrix3d deformationGradient(const TetMesh& mesh, const TetRestFrames& frames, const Vertices& x,
                                    std::int32_t t) {
  const auto tet = mesh.tets.row(t);
  Eigen::Matrix3d e;
  for (int k = 0; k < 3; ++k) e.col(k) = (x.row(tet[k]) - x.row(tet[3])).transpose();
  return e * frames.edge_inverse[static_cast<size_t>(t)];
}

}  // namespace tetrig
