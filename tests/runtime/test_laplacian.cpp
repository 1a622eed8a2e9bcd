// L = G^T D G (eq. 2.4) and delta = G^T D g (eq. 2.5) on bar meshes.
#include "scenes.hpp"
#include "tetrig/laplacian.hpp"

#include <Eigen/Dense>
#include <gtest/gtest.h>

#include <random>

namespace tetrig {
namespace {

TEST(Laplacian, ConstantVectorsAreInTheNullSpace) {
  const TetMesh mesh = scenes::makeBar(2, 3, 5);
  const TetRestFrames frames = computeRestFrames(mesh);
  const auto weights = tetWeights(frames, {});
  const Eigen::SparseMatrix<double> l = assembleLaplacian(mesh, frames, weights);
  const Eigen::VectorXd ones = Eigen::VectorXd::Constant(mesh.vertexCount(), 3.7);
  EXPECT_LT((l * ones).cwiseAbs().maxCoeff(), 1e-12);
  // ...and only them: a non-constant vector has positive energy.
  Eigen::VectorXd ramp(mesh.vertexCount());
  for (int v = 0; v < mesh.vertexCount(); ++v) ramp[v] = mesh.vertices(v, 2);
  EXPECT_GT(ramp.dot(l * ramp), 1.0);
}

TEST(Laplacian, IsSymmetricPositiveSemidefinite) {
  const TetMesh mesh = scenes::makeBar(2, 2, 4);
  const TetRestFrames frames = computeRestFrames(mesh);
  std::vector<double> stiffness(static_cast<size_t>(mesh.tetCount()));
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> uniform(0.5, 4.0);
  for (auto& s : stiffness) s = uniform(rng);
  const auto weights = tetWeights(frames, stiffness);
  const Eigen::MatrixXd l = Eigen::MatrixXd(assembleLaplacian(mesh, frames, weights));
  EXPECT_LT((l - l.transpose()).cwiseAbs().maxCoeff(), 1e-12);
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eigen(l);
  EXPECT_GT(eigen.eigenvalues()[0], -1e-10);
  EXPECT_LT(std::abs(eigen.eigenvalues()[0]), 1e-10);  // exactly one zero mode (connected mesh)
  EXPECT_GT(eigen.eigenvalues()[1], 1e-6);
}

TEST(Laplacian, GradientOfLinearFieldIsExact) {
  // For x = A p + b the deformation gradient of every tet is A.
  const TetMesh mesh = scenes::makeBar(2, 2, 3);
  const TetRestFrames frames = computeRestFrames(mesh);
  Eigen::Matrix3d a;
  a << 1.1, 0.2, -0.3, 0.05, 0.9, 0.4, -0.2, 0.1, 1.3;
  Vertices x = (mesh.vertices * a.transpose()).rowwise() + Eigen::RowVector3d(1, 2, 3);
  for (std::int32_t t = 0; t < mesh.tetCount(); ++t) {
    EXPECT_LT((deformationGradient(mesh, frames, x, t) - a).norm(), 1e-12) << "tet " << t;
  }
}

TEST(Laplacian, RestDifferentialCoordinatesReproduceTheRestPose) {
  // With R_j = I, delta = G^T D G x_rest = L x_rest (eq. 2.5 with g_j = G_j p_j).
  const TetMesh mesh = scenes::makeBar(3, 2, 6);
  const TetRestFrames frames = computeRestFrames(mesh);
  const auto weights = tetWeights(frames, {});
  const Eigen::SparseMatrix<double> l = assembleLaplacian(mesh, frames, weights);
  const std::vector<Eigen::Matrix3d> identity(static_cast<size_t>(mesh.tetCount()), Eigen::Matrix3d::Identity());
  const Vertices delta = differentialCoordinates(mesh, frames, weights, identity);
  const Eigen::MatrixXd expected = l * Eigen::MatrixXd(mesh.vertices);
  EXPECT_LT((Eigen::MatrixXd(delta) - expected).cwiseAbs().maxCoeff(), 1e-12);
}

TEST(Laplacian, VolumesAndStiffnessScaleTheWeights) {
  const TetMesh mesh = scenes::makeBar(1, 1, 1);
  const TetRestFrames frames = computeRestFrames(mesh);
  double total = 0.0;
  for (double v : frames.volume) total += v;
  EXPECT_NEAR(total, 1.0, 1e-12);  // five tets fill the unit cube
  const std::vector<double> stiffness = {1, 2, 3, 4, 5};
  const auto weights = tetWeights(frames, stiffness);
  for (size_t t = 0; t < 5; ++t) EXPECT_DOUBLE_EQ(weights[t], stiffness[t] * frames.volume[t]);
  EXPECT_THROW(tetWeights(frames, std::vector<double>{1, 2}), std::invalid_argument);
  EXPECT_THROW(tetWeights(frames, std::vector<double>{1, 2, 0, 4, 5}), std::invalid_argument);
}

TEST(Laplacian, ZeroVolumeTetIsRefusedWithItsIndex) {
  TetMesh mesh = scenes::makeBar(1, 1, 1);
  mesh.vertices.row(mesh.tets(3, 0)) = mesh.vertices.row(mesh.tets(3, 1));  // collapse an edge
  try {
    computeRestFrames(mesh);
    FAIL() << "expected std::invalid_argument";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("zero volume"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace tetrig
