// The pose transfer's padded and compact variants, the live rig's frame-path forms of
// x_fine = B x_tet (tetrig/pose_transfer.hpp has B's storage and the plain product; Stoll et al.
// 2007, eq. 2.12). Internal to the runtime: the live rig chooses among them.
#pragma once

#include "tetrig/pose_transfer.hpp"

#include <cstdint>

namespace tetrig {

// The compact copy the live rig streams every frame: float weights and 16-bit column indices, 6
// bytes per entry of B instead of 12 (docs/live.md, "Latency"). Each weight is rounded to float
// (relative error <= 2^-24), so a fine vertex moves by at most 2^-24 * sum_j |B(i, j)| |x_tet_j|
// against the double product. Load time; allocates; throws std::invalid_argument when B has more
// than 65536 columns (tet vertices) or fails validatePoseTransfer.
using CompactPoseTransfer = PoseTransferCsr<float, std::uint16_t>;
CompactPoseTransfer narrowPoseTransfer(const PoseTransferCsr<double>& b);
// True when narrowPoseTransfer accepts b's size (its columns fit in 16 bits).
constexpr bool fitsCompactPoseTransfer(std::int32_t cols) noexcept { return cols >= 0 && cols <= 65536; }

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
