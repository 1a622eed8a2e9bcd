// Split application of a SimplicialLDLT factor: P, L, D^-1, L^T, P^T, three interleaved columns,
// on a supernodal re-layout of the same factor (dense blocks, built once at load).
#include "tetrig/ldlt_factor.hpp"
#include "tetrig/working_set.hpp"

#include "multiversion.hpp"
#include "vector_lanes.hpp"

#include <Eigen/SparseCholesky>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
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
  buildSupernodes(col_start, row, value);
  // Eigen applies the ordering as y = P b with (P b)[P.indices()[i]] = b[i].
  const auto& perm = ldlt.permutationP().indices();
  position_.resize(n);
  for (size_t i = 0; i < n; ++i) position_[i] = perm[static_cast<Eigen::Index>(i)];
}

namespace {

constexpr std::int32_t kRowPad = lanes::kLanes;  // = the lanes of lanes::Lanes

std::int32_t paddedRows(std::int32_t width, std::int32_t rows) {
  return width == 1 ? rows : (rows + kRowPad - 1) / kRowPad * kRowPad;
}

// Cost of one supernode of w columns and r rows below, forward plus backward, in cycles of this
// machine (Xeon, AVX-512; estimated from timings of the bars' solves by path). The large factor
// (2 MB) streams from L3 at about 25 GB/s, so a stored entry costs its bytes more than its FMAs:
//   w = 1: 5 per entry (value + row index, one read-modify-write or gather each) + 10 per node;
//   w > 1: 2 per stored block entry (zeros and padding rows included), 4 per block row
//          (scatter/gather transposes), 1.5 per triangle entry (row-oriented chains), 6 per
//          column (lane sums), 30 per node.
// The partition it picks solves the large bar in 0.84x the time of the previous layout
// (fundamental supernodes, row-oriented products; same run) and the small one within 2 %. The
// optimum is flat: the variants tried (one weight at a time, x0.5 to x2) were within 3 %.
double nodeCost(std::int32_t w, std::int32_t r) {
  if (w == 1) return 5.0 * r + 10.0;
  const double p = paddedRows(w, r);
  return 2.0 * w * p + 4.0 * p + 1.5 * w * (w - 1) / 2 + 6.0 * w + 30.0;
}

}  // namespace

void SplitLdlt::buildSupernodes(const std::vector<std::int32_t>& col_start, const std::vector<std::int32_t>& row,
                                const std::vector<double>& value) {
  const auto n = static_cast<std::int32_t>(col_start.size()) - 1;
  // Partition the columns into supernodes: dynamic programming over contiguous ranges of at most
  // kMaxWidth columns minimising the sum of nodeCost (any partition is valid: a range's rows are
  // the union of its columns' rows past it, with zeros stored where a column has none).
  // best[j]: the cheapest partition of columns 0..j-1; its last range starts at start[j].
  constexpr std::int32_t kMaxWidth = 32;
  std::vector<double> best(static_cast<size_t>(n) + 1, 0.0);
  std::vector<std::int32_t> start(static_cast<size_t>(n) + 1, 0), mark(static_cast<size_t>(n), -1);
  for (std::int32_t j = 1; j <= n; ++j) {
    best[static_cast<size_t>(j)] = std::numeric_limits<double>::infinity();
    std::int32_t count = 0;
    for (std::int32_t w = 1; w <= std::min(kMaxWidth, j); ++w) {
      const std::int32_t i = j - w;
      // Column i's first row is its parent p in the elimination tree, and rows(i) - {p} is a subset
      // of rows(p): with p inside the range (already added), column i adds nothing new.
      const std::int32_t begin = col_start[static_cast<size_t>(i)], end = col_start[static_cast<size_t>(i) + 1];
      const std::int32_t scan_begin = (begin < end && row[static_cast<size_t>(begin)] < j) ? end : begin;
      for (std::int32_t p = scan_begin; p < end; ++p) {
        const std::int32_t r = row[static_cast<size_t>(p)];
        if (r >= j && mark[static_cast<size_t>(r)] != j) {
          mark[static_cast<size_t>(r)] = j;
          ++count;
        }
      }
      const double c = best[static_cast<size_t>(i)] + nodeCost(w, count);
      if (c < best[static_cast<size_t>(j)]) {
        best[static_cast<size_t>(j)] = c;
        start[static_cast<size_t>(j)] = i;
      }
    }
  }
  std::vector<std::pair<std::int32_t, std::int32_t>> ranges;  // [c0, c1)
  for (std::int32_t j = n; j > 0; j = start[static_cast<size_t>(j)]) ranges.emplace_back(start[static_cast<size_t>(j)], j);
  std::reverse(ranges.begin(), ranges.end());

  // Lay each range out: rows below = the union of its columns' rows past the range.
  supernodes_.clear();
  rows_.clear();
  values_.clear();
  std::vector<std::int32_t> slot(static_cast<size_t>(n), -1), below;
  std::int32_t max_padded = 0;
  for (const auto& [c0, c1] : ranges) {
    below.clear();
    for (std::int32_t j = c0; j < c1; ++j) {
      for (std::int32_t p = col_start[static_cast<size_t>(j)]; p < col_start[static_cast<size_t>(j) + 1]; ++p) {
        const std::int32_t r = row[static_cast<size_t>(p)];
        if (r >= c1 && slot[static_cast<size_t>(r)] < 0) {
          slot[static_cast<size_t>(r)] = 0;
          below.push_back(r);
        }
      }
    }
    std::sort(below.begin(), below.end());
    for (size_t i = 0; i < below.size(); ++i) slot[static_cast<size_t>(below[i])] = static_cast<std::int32_t>(i);
    const std::int32_t k = c1 - c0;
    const auto r = static_cast<std::int32_t>(below.size());
    const std::int32_t padded = paddedRows(k, r);
    max_padded = std::max(max_padded, padded);
    Supernode node{c0, k, static_cast<std::int32_t>(rows_.size()), padded, static_cast<std::int64_t>(values_.size()), 0};
    rows_.insert(rows_.end(), below.begin(), below.end());
    rows_.resize(rows_.size() + static_cast<size_t>(padded - r), r > 0 ? below.back() : 0);
    // Triangle, then the block; a column-major block starts on a cache line.
    std::int64_t block_begin = node.value_begin + static_cast<std::int64_t>(k) * k;
    if (k > 1) block_begin = (block_begin + kRowPad - 1) / kRowPad * kRowPad;
    node.block_begin = block_begin;
    values_.resize(static_cast<size_t>(block_begin + static_cast<std::int64_t>(k) * padded), 0.0);
    double* triangle = values_.data() + node.value_begin;
    double* block = values_.data() + block_begin;
    for (std::int32_t c = 0; c < k; ++c) {
      for (std::int32_t p = col_start[static_cast<size_t>(c0 + c)]; p < col_start[static_cast<size_t>(c0 + c) + 1]; ++p) {
        const std::int32_t rr = row[static_cast<size_t>(p)];
        if (rr < c1) {
          triangle[static_cast<std::int64_t>(rr - c0) * k + c] = value[static_cast<size_t>(p)];
        } else {
          block[static_cast<std::int64_t>(c) * padded + slot[static_cast<size_t>(rr)]] = value[static_cast<size_t>(p)];
        }
      }
    }
    for (std::int32_t b : below) slot[static_cast<size_t>(b)] = -1;
    supernodes_.push_back(node);
  }
  gathered_.assign(3 * static_cast<size_t>(max_padded), 0.0);
}

namespace {

constexpr std::int64_t kS = kVectorStride;

// The solve's vector types by scalar: kLanes rows of a block (Lanes or Float8), one vertex's
// (x, y, z, pad) (Vec4 or Vec4f). GCC takes no vector attribute on a dependent type.
template <typename T>
struct SolveVectors;
template <>
struct SolveVectors<double> {
  using L = lanes::Lanes;
  using V = lanes::Vec4;
};
template <>
struct SolveVectors<float> {
  using L = lanes::Float8;
  using V = lanes::Vec4f;
};

// Forward block product of C consecutive 8-row chunks: xyzw[rows[l]] -= (B z_block)_l. A padding
// row repeats the row before it with zero values; each read-modify-write completes before the
// next, so that is harmless.
template <int C, typename T>
TETRIG_INLINE void subtractBlockProduct(T* xyzw, const std::int32_t* rows, const T* block, std::int32_t np, std::int32_t k,
                                        const T* z) {
  using L = typename SolveVectors<T>::L;
  using V = typename SolveVectors<T>::V;
  L x[C]{}, y[C]{}, zz[C]{};
  for (std::int32_t c = 0; c < k; ++c, block += np, z += kS) {
#pragma GCC unroll 2
    for (int q = 0; q < C; ++q) {
      const L b = lanes::loadAs<L>(block + kRowPad * q);
      x[q] += b * z[0];
      y[q] += b * z[1];
      zz[q] += b * z[2];
    }
  }
  for (int q = 0; q < C; ++q) {
    V v[lanes::kLanes];
    lanes::transposeOut(x[q], y[q], zz[q], v);
    for (int l = 0; l < lanes::kLanes; ++l) {
      T* target = xyzw + kS * rows[kRowPad * q + l];
      lanes::storeAs(target, lanes::loadAs<V>(target) - v[l]);
    }
  }
}

// (sum of x's lanes, sum of y's, sum of z's, 0).
template <class L>
TETRIG_INLINE auto sumLanes(L x, L y, L z) {
  const auto low4 = [](L v) { return __builtin_shufflevector(v, v, 0, 1, 2, 3); };
  const auto high4 = [](L v) { return __builtin_shufflevector(v, v, 4, 5, 6, 7); };
  using V = decltype(low4(x));
  const V zero{};
  const V x4 = low4(x) + high4(x), y4 = low4(y) + high4(y), z4 = low4(z) + high4(z);
  const V xy = __builtin_shufflevector(x4, y4, 0, 4, 2, 6) + __builtin_shufflevector(x4, y4, 1, 5, 3, 7);
  const V zz = __builtin_shufflevector(z4, zero, 0, 4, 2, 6) + __builtin_shufflevector(z4, zero, 1, 5, 3, 7);
  return __builtin_shufflevector(xy, zz, 0, 1, 4, 5) + __builtin_shufflevector(xy, zz, 2, 3, 6, 7);
}

// Backward block product for Q consecutive columns c: x_c = D^-1_c x_c - (B^T x_R)_c, with x_R
// gathered into gx, gy, gz.
template <int Q, typename T>
TETRIG_INLINE void columnsMinusBlockProduct(T* x, const T* dk, const T* block, std::int32_t np, const T* gx, const T* gy,
                                            const T* gz) {
  using L = typename SolveVectors<T>::L;
  using V = typename SolveVectors<T>::V;
  L sx[Q]{}, sy[Q]{}, sz[Q]{};
  for (std::int32_t i = 0; i < np; i += kRowPad) {
    const L vx = lanes::loadAs<L>(gx + i), vy = lanes::loadAs<L>(gy + i), vz = lanes::loadAs<L>(gz + i);
#pragma GCC unroll 4
    for (int q = 0; q < Q; ++q) {
      const L b = lanes::loadAs<L>(block + static_cast<std::int64_t>(q) * np + i);
      sx[q] += b * vx;
      sy[q] += b * vy;
      sz[q] += b * vz;
    }
  }
#pragma GCC unroll 4
  for (int q = 0; q < Q; ++q) lanes::storeAs(x + kS * q, lanes::loadAs<V>(x + kS * q) * dk[q] - sumLanes(sx[q], sy[q], sz[q]));
}

// Whether n values are all (plus or minus) zero.
template <typename T>
TETRIG_INLINE bool allZero(const T* x, std::int32_t n) {
  for (std::int32_t i = 0; i < n; ++i)
    if (x[i] != T(0)) return false;
  return true;
}

}  // namespace

// Per supernode of k columns with r rows below: forward z_block = T^-1 z_block, then
// z_R -= B z_block; backward x_block = D^-1 x_block - B^T x_R, then x_block = T^-T x_block.
// For k > 1 the block products run with the vector lanes over B's rows (column-major B, 3 FMAs
// per 8 entries, rows scattered or gathered once per node); single columns (most of them, short)
// keep one vector (x, y, z, pad) per entry. T: double (the factor as computed) or float (its
// rounded copy, half the bytes to read).
template <typename T>
TETRIG_INLINE void SplitLdlt::solveWith(const T* values, const T* d_inv, T* gathered, std::int64_t max_padded, T* xyzw,
                                        bool skip_zero_nodes) const {
  using L = typename SolveVectors<T>::L;
  using V = typename SolveVectors<T>::V;
  const std::int32_t* rows = rows_.data();
  for (const Supernode& node : supernodes_) {
    const std::int32_t k = node.width;
    const std::int32_t np = node.padded_rows;
    const T* block = values + node.block_begin;
    const std::int32_t* r = rows + node.row_begin;
    T* z = xyzw + kS * node.first_column;
    if (skip_zero_nodes && allZero(z, kS * k)) continue;  // T^-1 0 = 0, and nothing to subtract
    if (k == 1) {
      const V z0 = lanes::loadAs<V>(z);
      for (std::int32_t i = 0; i < np; ++i) {
        T* target = xyzw + kS * r[i];
        lanes::storeAs(target, lanes::loadAs<V>(target) - block[i] * z0);
      }
      continue;
    }
    const T* triangle = values + node.value_begin;
    for (std::int32_t i = 1; i < k; ++i) {  // four sums per row: chains of i / 4 FMAs
      const T* t = triangle + static_cast<std::int64_t>(i) * k;
      V s0 = lanes::loadAs<V>(z + kS * i), s1{}, s2{}, s3{};
      std::int32_t c = 0;
      for (; c + 4 <= i; c += 4) {
        s0 -= t[c] * lanes::loadAs<V>(z + kS * c);
        s1 -= t[c + 1] * lanes::loadAs<V>(z + kS * (c + 1));
        s2 -= t[c + 2] * lanes::loadAs<V>(z + kS * (c + 2));
        s3 -= t[c + 3] * lanes::loadAs<V>(z + kS * (c + 3));
      }
      for (; c < i; ++c) s0 -= t[c] * lanes::loadAs<V>(z + kS * c);
      lanes::storeAs(z + kS * i, (s0 + s1) + (s2 + s3));
    }
    std::int32_t i = 0;
    for (; i + 2 * kRowPad <= np; i += 2 * kRowPad) subtractBlockProduct<2>(xyzw, r + i, block + i, np, k, z);
    if (i < np) subtractBlockProduct<1>(xyzw, r + i, block + i, np, k, z);
  }

  T* gx = gathered;
  T* gy = gx + max_padded;
  T* gz = gy + max_padded;
  for (auto it = supernodes_.rbegin(); it != supernodes_.rend(); ++it) {
    const Supernode& node = *it;
    const std::int32_t k = node.width;
    const std::int32_t np = node.padded_rows;
    const T* block = values + node.block_begin;
    const std::int32_t* r = rows + node.row_begin;
    T* x = xyzw + kS * node.first_column;
    const T* dk = d_inv + node.first_column;
    if (k == 1) {
      // Two sums, alternating rows, from the last row down: the lowest row was solved last, just
      // before this node (often its parent), so its term enters at the end of the chain.
      V s0 = lanes::loadAs<V>(x) * dk[0], s1{};
      std::int32_t i = np - 1;
      for (; i >= 1; i -= 2) {
        s1 -= block[i] * lanes::loadAs<V>(xyzw + kS * r[i]);
        s0 -= block[i - 1] * lanes::loadAs<V>(xyzw + kS * r[i - 1]);
      }
      if (i == 0) s0 -= block[0] * lanes::loadAs<V>(xyzw + kS * r[0]);
      lanes::storeAs(x, s0 + s1);
      continue;
    }
    for (std::int32_t i = 0; i < np; i += kRowPad) {
      V v[lanes::kLanes];
      for (int l = 0; l < lanes::kLanes; ++l) v[l] = lanes::loadAs<V>(xyzw + kS * r[i + l]);
      L vx, vy, vz;
      lanes::transposeIn(v, vx, vy, vz);
      lanes::storeAs(gx + i, vx);
      lanes::storeAs(gy + i, vy);
      lanes::storeAs(gz + i, vz);
    }
    std::int32_t c = 0;
    for (; c + 4 <= k; c += 4) columnsMinusBlockProduct<4>(x + kS * c, dk + c, block + static_cast<std::int64_t>(c) * np, np, gx, gy, gz);
    for (; c < k; ++c) columnsMinusBlockProduct<1>(x + kS * c, dk + c, block + static_cast<std::int64_t>(c) * np, np, gx, gy, gz);
    const T* triangle = values + node.value_begin;
    for (c = k - 2; c >= 0; --c) {  // four sums, from the last row down (the latest solved enters last)
      V s0 = lanes::loadAs<V>(x + kS * c), s1{}, s2{}, s3{};
      const T* t = triangle + c;
      std::int32_t i = k - 1;
      for (; i - 3 > c; i -= 4) {
        s0 -= t[static_cast<std::int64_t>(i) * k] * lanes::loadAs<V>(x + kS * i);
        s1 -= t[static_cast<std::int64_t>(i - 1) * k] * lanes::loadAs<V>(x + kS * (i - 1));
        s2 -= t[static_cast<std::int64_t>(i - 2) * k] * lanes::loadAs<V>(x + kS * (i - 2));
        s3 -= t[static_cast<std::int64_t>(i - 3) * k] * lanes::loadAs<V>(x + kS * (i - 3));
      }
      for (; i > c; --i) s0 -= t[static_cast<std::int64_t>(i) * k] * lanes::loadAs<V>(x + kS * i);
      lanes::storeAs(x + kS * c, (s0 + s1) + (s2 + s3));
    }
  }
}

TETRIG_MULTIVERSION
void SplitLdlt::solveInPlace(double* xyzw, bool skip_zero_nodes) {
  solveWith(values_.data(), d_inv_.data(), gathered_.data(), static_cast<std::int64_t>(gathered_.size()) / 3, xyzw, skip_zero_nodes);
}

void SplitLdlt::prepareFloatSolve() {
  values_f_.assign(values_.begin(), values_.end());
  d_inv_f_.assign(d_inv_.begin(), d_inv_.end());
  gathered_f_.assign(gathered_.size(), 0.0f);
}

TETRIG_MULTIVERSION
void SplitLdlt::solveInPlace(float* xyzw, bool skip_zero_nodes) {
  solveWith(values_f_.data(), d_inv_f_.data(), gathered_f_.data(), static_cast<std::int64_t>(gathered_f_.size()) / 3, xyzw,
            skip_zero_nodes);
}

std::size_t SplitLdlt::workingSet(std::span<std::span<const std::byte>> out, std::size_t count) const noexcept {
  count = appendWorkingSet(out, count, values_);
  count = appendWorkingSet(out, count, rows_);
  count = appendWorkingSet(out, count, supernodes_);
  count = appendWorkingSet(out, count, d_inv_);
  count = appendWorkingSet(out, count, values_f_);
  return appendWorkingSet(out, count, d_inv_f_);
}

}  // namespace tetrig
