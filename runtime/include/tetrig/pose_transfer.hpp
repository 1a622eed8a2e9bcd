// Pose transfer at run time (Stoll et al. 2007, section 2.4, eq. 2.12): x_fine = B x_tet, with B
// the sparse pose-transfer matrix (#fine by #tetV, rows summing to 1) built offline by the rig
// builder (tetrig::rigbuild::poseTransferWeights) and stored in compressed sparse row form.
//
// Load time: PoseTransferCsr<W> owns the arrays (allocates once). Per frame: applyPoseTransfer
// reads a PoseTransferView and writes into a caller buffer: no allocation, no lock, no
// exception, no I/O; any thread, concurrent calls on disjoint row ranges are fine.
#pragma once

#include <Eigen/SparseCore>

#include <cstdint>
#include <string>
#include <vector>

namespace tetrig {

// Non-owning view of a CSR matrix; W is float or double, C the column index type (std::int32_t, or
// std::uint16_t for the live rig's compact copy: narrowPoseTransfer below).
template <typename W, typename C = std::int32_t>
struct PoseTransferView {
  const std::int32_t* row_offsets = nullptr;  // rows + 1 entries, row_offsets[0] == 0, non-decreasing
  const C* columns = nullptr;                 // row_offsets[rows] entries, each in [0, cols)
  const W* weights = nullptr;                 // row_offsets[rows] entries
  std::int32_t rows = 0;                      // fine vertices
  std::int32_t cols = 0;                      // tet vertices
};

// Owning CSR storage, prepared at load.
template <typename W, typename C = std::int32_t>
struct PoseTransferCsr {
  std::vector<std::int32_t> row_offsets;
  std::vector<C> columns;
  std::vector<W> weights;
  std::int32_t rows = 0;
  std::int32_t cols = 0;

  using view_type = PoseTransferView<W, C>;
  view_type view() const { return {row_offsets.data(), columns.data(), weights.data(), rows, cols}; }
  std::int64_t nonzeros() const { return static_cast<std::int64_t>(columns.size()); }
  // Bytes of the three arrays.
  std::int64_t bytes() const {
    return static_cast<std::int64_t>(row_offsets.size() * sizeof(std::int32_t) + columns.size() * sizeof(C) +
                                     weights.size() * sizeof(W));
  }
};

// The compact copy the live rig streams every frame: float weights and 16-bit column indices, 6
// bytes per entry of B instead of 12 (docs/live.md, "Latency"). Each weight is rounded to float
// (relative error <= 2^-24), so a fine vertex moves by at most 2^-24 * sum_j |B(i, j)| |x_tet_j|
// against the double product. Load time; allocates; throws std::invalid_argument when B has more
// than 65536 columns (tet vertices) or fails validatePoseTransfer.
using CompactPoseTransfer = PoseTransferCsr<float, std::uint16_t>;
CompactPoseTransfer narrowPoseTransfer(const PoseTransferCsr<double>& b);
// True when narrowPoseTransfer accepts b's size (its columns fit in 16 bits).
constexpr bool fitsCompactPoseTransfer(std::int32_t cols) noexcept { return cols >= 0 && cols <= 65536; }

// Converts an Eigen row-major sparse matrix (weights rounded to W). Load time; allocates.
template <typename W>
PoseTransferCsr<W> makePoseTransferCsr(const Eigen::SparseMatrix<double, Eigen::RowMajor>& b);

// Checks the structure (offsets monotone, columns in range, finite weights). Load time; allocates
// only the message of a fault. Returns an empty string when valid, else a one-line description of the first fault.
template <typename W, typename C>
std::string validatePoseTransfer(const PoseTransferView<W, C>& b);

// x_fine[i] = sum_j B(i, j) x_tet[j] for rows [row_begin, row_end). x_tet: #tetV by 3, row-major
// (x0 y0 z0 x1 ...); x_fine: #fine by 3 row-major, written for the given rows only. Accumulates
// in double unless W, In and Out are all float. Frame path: no allocation, noexcept; B must have
// passed validatePoseTransfer and the buffers must hold cols*3 and rows*3 values.
template <typename W, typename In, typename Out>
void applyPoseTransferRows(const PoseTransferView<W>& b, const In* x_tet, Out* x_fine, std::int32_t row_begin,
                           std::int32_t row_end) noexcept;

// All rows.
template <typename W, typename In, typename Out>
inline void applyPoseTransfer(const PoseTransferView<W>& b, const In* x_tet, Out* x_fine) noexcept {
  applyPoseTransferRows(b, x_tet, x_fine, 0, b.rows);
}

// The same product from padded tet positions: x_tet4 holds #tetV x 4 doubles (x, y, z, pad; the
// pad is read but does not reach x_fine), e.g. Deformer::paddedPositions(). One vector load and
// one 4-wide FMA per entry of B instead of three of each: 0.63-0.70x the time of the stride-3
// kernel on the SMPL rig (82 entries per row; docs/rig-builder.md). x_fine: #fine x 3 as above.
// Frame path: no allocation, noexcept; same preconditions as applyPoseTransferRows.
// Instantiated for double and float weights with 32-bit columns, and for the compact copy.
template <typename W, typename C, typename Out>
void applyPoseTransferPaddedRows(const PoseTransferView<W, C>& b, const double* x_tet4, Out* x_fine,
                                 std::int32_t row_begin, std::int32_t row_end) noexcept;

// The compact copy from float tet positions (#tetV x 4 floats, e.g. Deformer::paddedFloatPositions()),
// summed in float: 0.81-0.85x the time of the double-position kernel on the SMPL rig (the positions
// stay in L1 and four partial sums per row hide the FMA latency), and off the exact product of the
// double positions by |error| <= (n/4 + 5) 2^-24 sum_k |B_ik| |x_k| (n: the row's entries; sums,
// weights and positions rounded; micrometres on a body). Same preconditions.
void applyPoseTransferPaddedRows(const PoseTransferView<float, std::uint16_t>& b, const float* x_tet4, float* x_fine,
                                 std::int32_t row_begin, std::int32_t row_end) noexcept;
inline void applyPoseTransferPadded(const PoseTransferView<float, std::uint16_t>& b, const float* x_tet4,
                                    float* x_fine) noexcept {
  applyPoseTransferPaddedRows(b, x_tet4, x_fine, 0, b.rows);
}

template <typename W, typename C, typename Out>
inline void applyPoseTransferPadded(const PoseTransferView<W, C>& b, const double* x_tet4, Out* x_fine) noexcept {
  applyPoseTransferPaddedRows(b, x_tet4, x_fine, 0, b.rows);
}

}  // namespace tetrig
