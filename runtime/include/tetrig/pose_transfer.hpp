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
// std::uint16_t for the live rig's own compact copy).
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

}  // namespace tetrig
