// Split application of a SimplicialLDLT factor: P, L, D^-1, L^T, P^T, three interleaved columns,
// on a supernodal re-layout of the same factor (dense blocks, built once at load).
#include "tetrig/ldlt_factor.hpp"

#include "multiversion.hpp"

#include <Eigen/SparseCholesky>

#include <algorithm>
#include <cmath>
#include <cstring>
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

  // matrixL() is a unit-lower view of the stored strictly lower factor (CSC, rows ascending).
  const Eigen::SparseMatrix<double>& l = ldlt.matrixL().nestedExpression();
  std::vector<std::int32_t> col_start(n + 1, 0), row;
  std::vector<double> value;
  row.reserve(static_cast<size_t>(l.nonZeros()));
  value.reserve(static_cast<size_t>(l.nonZeros()));
  for (Eigen::Index j = 0; j < l.outerSize(); ++j) {
    for (Eigen::SparseMatrix<double>::InnerIterator it(l, j); it; ++it) {
      if (it.row() > j) {
        row.push_back(static_cast<std::int32_t>(it.row()));
        value.push_back(it.value());
      } else if (it.row() == j && it.value() != 1.0) {
        throw std::logic_error("SimplicialLDLT factor layout changed: stored diagonal entry is not 1");
      }
    }
    col_start[static_cast<size_t>(j) + 1] = static_cast<std::int32_t>(row.size());
  }
  factor_non_zeros_ = static_cast<std::int64_t>(row.size());

  // Fundamental supernodes: column j + 1 joins column j's supernode when rows(j) = {j + 1} + rows(j + 1).
  supernodes_.clear();
  rows_.clear();
  values_.clear();
  const auto ni = static_cast<std::int32_t>(n);
  std::int32_t c0 = 0;
  while (c0 < ni) {
    std::int32_t c1 = c0 + 1;
    while (c1 < ni) {
      const std::int32_t prev = col_start[static_cast<size_t>(c1) - 1], prev_end = col_start[static_cast<size_t>(c1)];
      const std::int32_t b = col_start[static_cast<size_t>(c1)], b_end = col_start[static_cast<size_t>(c1) + 1];
      if (prev_end - prev != b_end - b + 1 || row[static_cast<size_t>(prev)] != c1) break;
      if (!std::equal(row.begin() + prev + 1, row.begin() + prev_end, row.begin() + b)) break;
      ++c1;
    }
    const std::int32_t k = c1 - c0;
    // Rows below the triangle: those of the last column.
    const std::int32_t last = c1 - 1;
    Supernode node{c0, k, static_cast<std::int32_t>(rows_.size()),
                   col_start[static_cast<size_t>(last) + 1] - col_start[static_cast<size_t>(last)],
                   static_cast<std::int64_t>(values_.size())};
    rows_.insert(rows_.end(), row.begin() + col_start[static_cast<size_t>(last)],
                 row.begin() + col_start[static_cast<size_t>(last) + 1]);
    values_.resize(values_.size() + static_cast<size_t>(k) * static_cast<size_t>(k + node.row_count), 0.0);
    double* triangle = values_.data() + node.value_begin;
    double* block = triangle + static_cast<std::int64_t>(k) * k;
    for (std::int32_t c = 0; c < k; ++c) {
      // Column c0 + c holds rows c0 + c + 1 .. c1 - 1 (triangle), then the shared block rows.
      std::int32_t p = col_start[static_cast<size_t>(c0 + c)];
      for (std::int32_t i = c + 1; i < k; ++i, ++p) triangle[static_cast<std::int64_t>(i) * k + c] = value[static_cast<size_t>(p)];
      for (std::int32_t i = 0; i < node.row_count; ++i, ++p) block[static_cast<std::int64_t>(i) * k + c] = value[static_cast<size_t>(p)];
    }
    supernodes_.push_back(node);
    c0 = c1;
  }
  // Eigen applies the ordering as y = P b with (P b)[P.indices()[i]] = b[i].
  const auto& perm = ldlt.permutationP().indices();
  position_.resize(n);
  for (size_t i = 0; i < n; ++i) position_[i] = perm[static_cast<Eigen::Index>(i)];
}

namespace {

// x, y, z, pad of one vertex: one 256-bit register where available (GCC/Clang vector extension).
using Vec4 = double __attribute__((vector_size(4 * sizeof(double))));
static_assert(kVectorStride == 4);

inline Vec4 load4(const double* p) {
  Vec4 v;
  std::memcpy(&v, p, sizeof v);
  return v;
}
inline void store4(double* p, Vec4 v) { std::memcpy(p, &v, sizeof v); }

}  // namespace

TETRIG_MULTIVERSION
void SplitLdlt::solveInPlace(double* xyzw) const {
  const std::int32_t* rows = rows_.data();
  const double* d_inv = d_inv_.data();
  // Forward, L z = y, supernode by supernode: the dense unit triangle, then the block below
  // (z_R -= B z_block for the shared rows R).
  for (const Supernode& node : supernodes_) {
    const std::int32_t k = node.width;
    const double* triangle = values_.data() + node.value_begin;
    const double* block = triangle + static_cast<std::int64_t>(k) * k;
    double* z = xyzw + kVectorStride * node.first_column;
    for (std::int32_t i = 1; i < k; ++i) {
      const double* t = triangle + static_cast<std::int64_t>(i) * k;
      Vec4 sum = load4(z + kVectorStride * i);
      for (std::int32_t c = 0; c < i; ++c) sum -= t[c] * load4(z + kVectorStride * c);
      store4(z + kVectorStride * i, sum);
    }
    const std::int32_t* r = rows + node.row_begin;
    if (k == 1) {  // a single column: the common case outside separators
      const Vec4 z0 = load4(z);
      for (std::int32_t i = 0; i < node.row_count; ++i) {
        double* target = xyzw + kVectorStride * r[i];
        store4(target, load4(target) - block[i] * z0);
      }
      continue;
    }
    for (std::int32_t i = 0; i < node.row_count; ++i) {
      const double* b = block + static_cast<std::int64_t>(i) * k;
      Vec4 sum = b[0] * load4(z);
      for (std::int32_t c = 1; c < k; ++c) sum += b[c] * load4(z + kVectorStride * c);
      double* target = xyzw + kVectorStride * r[i];
      store4(target, load4(target) - sum);
    }
  }
  // Backward, L^T x = D^-1 z, last supernode first: x_block = D^-1 z_block - B^T x_R, then the
  // triangle from its last column up.
  for (auto it = supernodes_.rbegin(); it != supernodes_.rend(); ++it) {
    const Supernode& node = *it;
    const std::int32_t k = node.width;
    const double* triangle = values_.data() + node.value_begin;
    const double* block = triangle + static_cast<std::int64_t>(k) * k;
    double* x = xyzw + kVectorStride * node.first_column;
    const std::int32_t* r = rows + node.row_begin;
    if (k == 1) {
      Vec4 sum = load4(x) * d_inv[node.first_column];
      for (std::int32_t i = 0; i < node.row_count; ++i) sum -= block[i] * load4(xyzw + kVectorStride * r[i]);
      store4(x, sum);
      continue;
    }
    for (std::int32_t c = 0; c < k; ++c) store4(x + kVectorStride * c, load4(x + kVectorStride * c) * d_inv[node.first_column + c]);
    for (std::int32_t i = 0; i < node.row_count; ++i) {
      const double* b = block + static_cast<std::int64_t>(i) * k;
      const Vec4 source = load4(xyzw + kVectorStride * r[i]);
      for (std::int32_t c = 0; c < k; ++c) store4(x + kVectorStride * c, load4(x + kVectorStride * c) - b[c] * source);
    }
    for (std::int32_t c = k - 2; c >= 0; --c) {
      Vec4 sum = load4(x + kVectorStride * c);
      for (std::int32_t i = c + 1; i < k; ++i) sum -= triangle[static_cast<std::int64_t>(i) * k + c] * load4(x + kVectorStride * i);
      store4(x + kVectorStride * c, sum);
    }
  }
}

}  // namespace tetrig
