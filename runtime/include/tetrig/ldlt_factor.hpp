// A sparse LDL^T factor applied without allocation.
//
// Factorization: Eigen::SimplicialLDLT (AMD ordering), the one sparse factorization tetrig uses.
// Eigen's solve() allocates on every call (measured), so the frame path applies the factor itself:
// for A = P^T L D L^T P, solving A x = b is y = P b, L z = y, w = D^-1 z, L^T v = w, x = P^T v.
// SplitLdlt keeps vectors in the factor's (permuted) order, so the frame path never permutes:
// callers store vertex i at position position(i). Three right-hand sides (x, y, z) are
// interleaved, so each factor entry is read once for all three.
//
// Storage: L strictly lower, compressed by column (CSC), unit diagonal implied; D^-1 cached.
#pragma once

#include <Eigen/SparseCore>

#include <cstdint>
#include <vector>

namespace tetrig {

class SplitLdlt {
 public:
  // Factors the symmetric positive definite matrix `a` (only its lower triangle is read).
  // Load-time: allocates; throws std::runtime_error if `a` is not positive definite (for a
  // Laplacian: when some connected part of the mesh has no handle).
  void factorize(const Eigen::SparseMatrix<double>& a);

  std::int32_t size() const { return static_cast<std::int32_t>(d_inv_.size()); }
  std::int64_t factorNonZeros() const { return static_cast<std::int64_t>(values_.size()); }

  // Factor position of original index i (y = P b means y[position(i)] = b[i]).
  std::int32_t position(std::int32_t i) const { return position_[static_cast<size_t>(i)]; }
  const std::vector<std::int32_t>& positions() const { return position_; }

  // Solves A x = b in place for 3 interleaved right-hand sides held in factor order:
  // xyz[3 * position(i) + c] is component c of row i. No allocation, no exceptions.
  void solveInPlace(double* xyz) const;

 private:
  std::vector<std::int32_t> col_start_;  // n + 1
  std::vector<std::int32_t> row_;        // row index of each stored entry (row > column)
  std::vector<double> values_;           // L entries
  std::vector<double> d_inv_;            // 1 / D
  std::vector<std::int32_t> position_;   // original index -> factor position
};

}  // namespace tetrig
