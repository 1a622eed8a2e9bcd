// A sparse LDL^T factor applied without allocation.
//
// Factorization: Eigen::SimplicialLDLT (AMD ordering), the one sparse factorization tetrig uses.
// Eigen's solve() allocates on every call (measured), so the frame path applies the factor itself:
// for A = P^T L D L^T P, solving A x = b is y = P b, L z = y, w = D^-1 z, L^T v = w, x = P^T v.
// SplitLdlt keeps vectors in the factor's (permuted) order, so the frame path never permutes:
// callers store vertex i at position position(i). Three right-hand sides (x, y, z) are
// interleaved (stride kVectorStride), so each factor entry is read once for all three.
//
// Storage (built once at load from SimplicialLDLT's own CSC factor): supernodes. A supernode is a
// run of consecutive columns c0..c0+k-1 sharing one list of r rows below them: a dense k x k unit
// lower triangle and a dense r x k block (zeros stored where L has none). The partition into
// supernodes is chosen at load by dynamic programming over a cost model of this solve
// (ldlt_factor.cpp): it cuts wide supernodes into panels and merges runs of short leaf columns
// where the stored zeros cost less than the scattered updates they save. One-column nodes keep one
// (x, y, z, pad) vector FMA per entry; wider ones store their block column-major with the rows
// padded to a multiple of 8, so the block products run with the vector lanes over rows (3 FMAs per
// 8 entries) and each row is scattered or gathered once per node. D^-1 is cached.
#pragma once

#include "tetrig/aligned_vector.hpp"

#include <Eigen/SparseCore>

#include <cstdint>
#include <cstddef>
#include <span>
#include <vector>

namespace tetrig {

// Per-vertex vectors on the frame path hold x, y, z and one padding lane (kept 0), so one
// 4-double vector operation updates all three coordinates.
inline constexpr int kVectorStride = 4;

class SplitLdlt {
 public:
  // Factors the symmetric positive definite matrix `a` (only its lower triangle is read).
  // Load-time: allocates; throws std::runtime_error if `a` is not positive definite (for a
  // Laplacian: when some connected part of the mesh has no handle).
  void factorize(const Eigen::SparseMatrix<double>& a);

  std::int32_t size() const { return static_cast<std::int32_t>(d_inv_.size()); }
  std::int64_t factorNonZeros() const { return factor_non_zeros_; }
  std::int32_t supernodeCount() const { return static_cast<std::int32_t>(supernodes_.size()); }

  // Factor position of original index i (y = P b means y[position(i)] = b[i]).
  std::int32_t position(std::int32_t i) const { return position_[static_cast<size_t>(i)]; }
  const std::vector<std::int32_t>& positions() const { return position_; }
  // The memory a solve reads (the factor's values, rows, nodes and 1 / D), appended to `out` from
  // `count` on; returns the new count (ranges past out.size() are left out). No allocation.
  std::size_t workingSet(std::span<std::span<const std::byte>> out, std::size_t count) const noexcept;

  // Solves A x = b in place for 3 interleaved right-hand sides held in factor order:
  // xyzw[kVectorStride * position(i) + c] is component c (0..2) of row i; lane 3 is carried along
  // (keep it 0). No allocation, no exceptions; uses the factor's own scratch, so one SplitLdlt
  // solves on one thread at a time. skip_zero_nodes: the forward pass passes over supernodes whose
  // values are still all zero when reached, for right-hand sides that are zero but at a few rows
  // (only the rows' ancestors in the elimination tree fill in); the result is the same.
  void solveInPlace(double* xyzw, bool skip_zero_nodes = false);
  // The same solve with the factor rounded to float, in float: about 1e-7 of the factor's entries
  // off, for a search direction that need not be exact (the implicit inversion guard's). Needs
  // prepareFloatSolve() once after factorize() (load-time: allocates the float copy).
  void prepareFloatSolve();
  void solveInPlace(float* xyzw, bool skip_zero_nodes = false);

 private:
  void buildSupernodes(const std::vector<std::int32_t>& col_start, const std::vector<std::int32_t>& row,
                       const std::vector<double>& value);

  struct Supernode {
    std::int32_t first_column;  // c0
    std::int32_t width;         // k
    std::int32_t row_begin;     // rows_[row_begin .. row_begin + padded_rows): rows below the triangle
    std::int32_t padded_rows;   // k = 1: r; k > 1: r rounded up to a multiple of 8 (padding rows
                                // repeat the last row, with zero values)
    std::int64_t value_begin;   // values_: k x k triangle (row-major, strict lower used), then the block
    std::int64_t block_begin;   // k = 1: r values; k > 1: k columns of padded_rows values (64-byte aligned)
  };
  template <typename T>
  void solveWith(const T* values, const T* d_inv, T* gathered, std::int64_t max_padded, T* xyzw, bool skip_zero_nodes) const;
  std::vector<Supernode> supernodes_;
  std::vector<std::int32_t> rows_;
  AlignedVector<double> values_;
  AlignedVector<double> gathered_;       // backward solve: x, y, z of one node's rows (3 x max padded_rows)
  std::vector<double> d_inv_;            // 1 / D
  AlignedVector<float> values_f_;        // prepareFloatSolve(): values_, d_inv_ and the scratch in float
  std::vector<float> d_inv_f_;
  AlignedVector<float> gathered_f_;
  std::vector<std::int32_t> position_;   // original index -> factor position
  std::int64_t factor_non_zeros_ = 0;    // strictly lower non-zeros of L
};

}  // namespace tetrig
