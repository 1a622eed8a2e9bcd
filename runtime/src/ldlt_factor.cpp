// Split application of a SimplicialLDLT factor: P, L, D^-1, L^T, P^T, three interleaved columns.
#include "tetrig/ldlt_factor.hpp"

#include <Eigen/SparseCholesky>

#include <cmath>
#include <stdexcept>
#include <string>

namespace tetrig {

void SplitLdlt::factorize(const Eigen::SparseMatrix<double>& a) {
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>, Eigen::Lower, Eigen::AMDOrdering<int>> ldlt;
  ldlt.compute(a);
  if (ldlt.info() != Eigen::Success) {
    throw std::runtime_error("the constrained Laplacian could not be factored (" + std::to_string(a.rows()) +
                             " unknowns): every connected part of the mesh needs at least one handle");
  }
  // A singular Laplacian (a part with no handle) factors with a pivot at rounding level, not
  // exactly zero: pivots below 1e-10 of the largest diagonal entry count as zero.
  const auto& d = ldlt.vectorD();
  const double pivot_floor = 1e-10 * a.diagonal().cwiseAbs().maxCoeff();
  for (Eigen::Index i = 0; i < d.size(); ++i) {
    if (!(d[i] > pivot_floor) || !std::isfinite(d[i])) {
      throw std::runtime_error("the constrained Laplacian is not positive definite (pivot " + std::to_string(i) +
                               " = " + std::to_string(d[i]) +
                               "): every connected part of the mesh needs at least one handle");
    }
  }
  const auto n = static_cast<size_t>(a.rows());
  d_inv_.resize(n);
  for (size_t i = 0; i < n; ++i) d_inv_[i] = 1.0 / d[static_cast<Eigen::Index>(i)];

  // matrixL() is a unit-lower view of the stored strictly lower factor.
  const Eigen::SparseMatrix<double>& l = ldlt.matrixL().nestedExpression();
  col_start_.assign(n + 1, 0);
  row_.clear();
  values_.clear();
  row_.reserve(static_cast<size_t>(l.nonZeros()));
  values_.reserve(static_cast<size_t>(l.nonZeros()));
  for (Eigen::Index j = 0; j < l.outerSize(); ++j) {
    for (Eigen::SparseMatrix<double>::InnerIterator it(l, j); it; ++it) {
      if (it.row() > j) {
        row_.push_back(static_cast<std::int32_t>(it.row()));
        values_.push_back(it.value());
      } else if (it.row() == j && it.value() != 1.0) {
        throw std::logic_error("SimplicialLDLT factor layout changed: stored diagonal entry is not 1");
      }
    }
    col_start_[static_cast<size_t>(j) + 1] = static_cast<std::int32_t>(row_.size());
  }
  // Eigen applies the ordering as y = P b with (P b)[P.indices()[i]] = b[i].
  const auto& p = ldlt.permutationP().indices();
  position_.resize(n);
  for (size_t i = 0; i < n; ++i) position_[i] = p[static_cast<Eigen::Index>(i)];
}

void SplitLdlt::solveInPlace(double* xyz) const {
  const std::int32_t n = size();
  const std::int32_t* col_start = col_start_.data();
  const std::int32_t* row = row_.data();
  const double* value = values_.data();
  // L z = y, column by column: once z_j is final, subtract L(i, j) z_j from every row i > j.
  for (std::int32_t j = 0; j < n; ++j) {
    const double z0 = xyz[3 * j], z1 = xyz[3 * j + 1], z2 = xyz[3 * j + 2];
    for (std::int32_t p = col_start[j]; p < col_start[j + 1]; ++p) {
      double* target = xyz + 3 * row[p];
      const double l = value[p];
      target[0] -= l * z0;
      target[1] -= l * z1;
      target[2] -= l * z2;
    }
  }
  // w = D^-1 z, then L^T v = w, column j gives v_j = w_j - sum_i L(i, j) v_i, last row first.
  const double* d_inv = d_inv_.data();
  for (std::int32_t j = n - 1; j >= 0; --j) {
    double s0 = 0.0, s1 = 0.0, s2 = 0.0;
    for (std::int32_t p = col_start[j]; p < col_start[j + 1]; ++p) {
      const double* source = xyz + 3 * row[p];
      const double l = value[p];
      s0 += l * source[0];
      s1 += l * source[1];
      s2 += l * source[2];
    }
    xyz[3 * j] = xyz[3 * j] * d_inv[j] - s0;
    xyz[3 * j + 1] = xyz[3 * j + 1] * d_inv[j] - s1;
    xyz[3 * j + 2] = xyz[3 * j + 2] * d_inv[j] - s2;
  }
}

}  // namespace tetrig
