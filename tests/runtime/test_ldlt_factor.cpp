// The split application of the SimplicialLDLT factor against Eigen's own solve.
#include "scenes.hpp"
#include "tetrig/laplacian.hpp"
#include "tetrig/ldlt_factor.hpp"

#include <Eigen/SparseCholesky>
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <random>
#include <vector>

namespace tetrig {
namespace {

Eigen::SparseMatrix<double> spdFromBar(int nx, int ny, int nz) {
  const TetMesh mesh = scenes::makeBar(nx, ny, nz);
  const TetRestFrames frames = computeRestFrames(mesh);
  Eigen::SparseMatrix<double> l = assembleLaplacian(mesh, frames, tetWeights(frames, {}));
  for (int i = 0; i < l.rows(); i += 7) l.coeffRef(i, i) += 0.5;  // a few "handles" make it definite
  return l;
}

// Three right-hand sides (x, y, z) that are zero but at `nonzero_rows` random rows (every row when
// it is the matrix's size), and the same interleaved in the factor's order (lane 3 kept 0).
Eigen::MatrixXd sparseRightHandSide(Eigen::Index rows, int nonzero_rows, std::mt19937& rng) {
  std::normal_distribution<double> normal;
  Eigen::MatrixXd b = Eigen::MatrixXd::Zero(rows, 3);
  for (int j = 0; j < nonzero_rows; ++j) {
    const auto row = nonzero_rows == rows ? j : std::uniform_int_distribution<int>(0, static_cast<int>(rows) - 1)(rng);
    for (int c = 0; c < 3; ++c) b(row, c) = normal(rng);
  }
  return b;
}

template <typename T>
std::vector<T> interleaved(const SplitLdlt& factor, const Eigen::MatrixXd& b) {
  std::vector<T> xyz(static_cast<size_t>(b.rows()) * kVectorStride, T(0));
  for (std::int32_t i = 0; i < factor.size(); ++i)
    for (int c = 0; c < 3; ++c) xyz[kVectorStride * static_cast<size_t>(factor.position(i)) + static_cast<size_t>(c)] = static_cast<T>(b(i, c));
  return xyz;
}

// Two bars, so every path of the solve runs: single columns, merged and cut supernodes, the
// 16-row forward products and (only the larger bar has it) the 8-row remainder, the four-column
// backward products and the column remainder, the triangles' four-sum loops and their remainders,
// rows padded to a multiple of 8. Each path was broken on purpose once and this test failed.
class SplitLdltBars : public ::testing::TestWithParam<std::array<int, 3>> {};

TEST_P(SplitLdltBars, MatchesEigenSolveForThreeInterleavedColumns) {
  const auto [nx, ny, nz] = GetParam();
  const Eigen::SparseMatrix<double> a = spdFromBar(nx, ny, nz);
  SplitLdlt factor;
  factor.factorize(a);
  ASSERT_EQ(factor.size(), a.rows());
  // The supernodal layout is exercised: far fewer supernodes than columns.
  EXPECT_LT(factor.supernodeCount(), factor.size() * 9 / 10);
  std::mt19937 rng(3);
  std::normal_distribution<double> normal;
  Eigen::MatrixXd b(a.rows(), 3);
  for (Eigen::Index i = 0; i < b.size(); ++i) b.data()[i] = normal(rng);
  constexpr size_t kS = kVectorStride;
  std::vector<double> xyz(static_cast<size_t>(a.rows()) * kS, 0.0);
  for (std::int32_t i = 0; i < factor.size(); ++i)
    for (int c = 0; c < 3; ++c) xyz[kS * static_cast<size_t>(factor.position(i)) + static_cast<size_t>(c)] = b(i, c);
  factor.solveInPlace(xyz.data());
  Eigen::MatrixXd x(a.rows(), 3);
  for (std::int32_t i = 0; i < factor.size(); ++i) {
    for (int c = 0; c < 3; ++c) x(i, c) = xyz[kS * static_cast<size_t>(factor.position(i)) + static_cast<size_t>(c)];
    EXPECT_EQ(xyz[kS * static_cast<size_t>(factor.position(i)) + 3], 0.0);  // the padding lane stays 0
  }
  const Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> reference(a);
  const Eigen::MatrixXd expected = reference.solve(b);
  EXPECT_LT((x - expected).cwiseAbs().maxCoeff(), 1e-10 * expected.cwiseAbs().maxCoeff());
  EXPECT_LT((a * x - b).norm(), 1e-9 * b.norm());
}

// The float copy of the factor (the implicit guard's solve) through the same paths: Eigen's double
// solution to float precision (the worst component within 1e-4 of the largest; a wrong transpose or
// sum would be off by the solution's size), the padding lane 0, and skipping zero nodes the same to
// the bit for a right-hand side with three non-zero rows.
TEST_P(SplitLdltBars, TheFloatCopySolvesToFloatPrecision) {
  const auto [nx, ny, nz] = GetParam();
  const Eigen::SparseMatrix<double> a = spdFromBar(nx, ny, nz);
  SplitLdlt factor;
  factor.factorize(a);
  factor.prepareFloatSolve();
  std::mt19937 rng(11);
  constexpr size_t kS = kVectorStride;
  for (const int nonzero_rows : {static_cast<int>(a.rows()), 3}) {
    const Eigen::MatrixXd b = sparseRightHandSide(a.rows(), nonzero_rows, rng);
    std::vector<float> xyz = interleaved<float>(factor, b);
    std::vector<float> skipping = xyz;
    factor.solveInPlace(xyz.data());
    factor.solveInPlace(skipping.data(), /*skip_zero_nodes=*/true);
    EXPECT_EQ(xyz, skipping) << nonzero_rows << " non-zero rows";
    const Eigen::MatrixXd expected = Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>>(a).solve(b);
    double worst = 0.0;
    for (std::int32_t i = 0; i < factor.size(); ++i) {
      for (int c = 0; c < 3; ++c)
        worst = std::max(worst, std::abs(xyz[kS * static_cast<size_t>(factor.position(i)) + static_cast<size_t>(c)] - expected(i, c)));
      EXPECT_EQ(xyz[kS * static_cast<size_t>(factor.position(i)) + 3], 0.0f);
    }
    EXPECT_LT(worst, 1e-4 * expected.cwiseAbs().maxCoeff()) << nonzero_rows << " non-zero rows";
  }
}

INSTANTIATE_TEST_SUITE_P(Bars, SplitLdltBars,
                         ::testing::Values(std::array<int, 3>{3, 3, 12}, std::array<int, 3>{6, 6, 24}));

// skip_zero_nodes (the implicit guard's first solve, whose right-hand side is zero but at a few
// tets' vertices): the same solution as the full solve, to the bit, and Eigen's to 1e-10, for a
// right-hand side with three non-zero rows (one node's ancestors fill in) and for a dense one.
TEST(SplitLdlt, SkippingZeroNodesSolvesTheSame) {
  const Eigen::SparseMatrix<double> a = spdFromBar(6, 6, 24);
  SplitLdlt factor;
  factor.factorize(a);
  constexpr size_t kS = kVectorStride;
  std::mt19937 rng(5);
  for (const int nonzero_rows : {3, static_cast<int>(a.rows())}) {
    const Eigen::MatrixXd b = sparseRightHandSide(a.rows(), nonzero_rows, rng);
    std::vector<double> full = interleaved<double>(factor, b);
    std::vector<double> skipping = full;
    factor.solveInPlace(full.data());
    factor.solveInPlace(skipping.data(), /*skip_zero_nodes=*/true);
    EXPECT_EQ(full, skipping) << nonzero_rows << " non-zero rows";
    const Eigen::MatrixXd expected = Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>>(a).solve(b);
    double worst = 0.0;
    for (std::int32_t i = 0; i < factor.size(); ++i)
      for (int c = 0; c < 3; ++c)
        worst = std::max(worst, std::abs(skipping[kS * static_cast<size_t>(factor.position(i)) + static_cast<size_t>(c)] - expected(i, c)));
    EXPECT_LT(worst, 1e-10 * expected.cwiseAbs().maxCoeff());
    EXPECT_GT(expected.cwiseAbs().minCoeff(), 0.0) << "the backward pass fills every row, skipped nodes too";
  }
}

TEST(SplitLdlt, PositionsArePermutation) {
  const Eigen::SparseMatrix<double> a = spdFromBar(2, 2, 8);
  SplitLdlt factor;
  factor.factorize(a);
  std::vector<char> seen(static_cast<size_t>(factor.size()), 0);
  for (std::int32_t i = 0; i < factor.size(); ++i) {
    const auto p = factor.position(i);
    ASSERT_GE(p, 0);
    ASSERT_LT(p, factor.size());
    EXPECT_EQ(seen[static_cast<size_t>(p)], 0);
    seen[static_cast<size_t>(p)] = 1;
  }
  EXPECT_GT(factor.factorNonZeros(), a.rows());  // strictly lower part plus fill
}

TEST(SplitLdlt, SingularMatrixIsRefusedWithAHint) {
  const TetMesh mesh = scenes::makeBar(1, 1, 2);
  const TetRestFrames frames = computeRestFrames(mesh);
  const Eigen::SparseMatrix<double> l = assembleLaplacian(mesh, frames, tetWeights(frames, {}));  // no handle
  SplitLdlt factor;
  try {
    factor.factorize(l);
    FAIL() << "a Laplacian without handles is singular";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("handle"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace tetrig
