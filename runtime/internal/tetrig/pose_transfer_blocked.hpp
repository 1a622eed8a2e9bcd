// The pose transfer x_fine = B x_tet (Stoll et al. 2007, eq. 2.12) with B stored in blocks of
// kPoseBlockRows fine vertices that lie close together on the rest mesh (docs/live.md, "The pose
// transfer in blocks"). Nearby fine vertices take their weights from nearly the same tet vertices,
// so a block stores the union of its rows' columns once, and for each such column the weights of
// its kPoseBlockRows rows side by side (zero where a row does not use the column):
//
//   (x, y, z)_fine_{r_l} = sum_{c in block} W(c, l) (x, y, z)_tet_c,   l = 0 .. kPoseBlockRows - 1,
//
// one lane per row l. A column then costs one load of its weights, three broadcasts of the tet
// vertex's coordinates and three FMAs across the lanes, for kPoseBlockRows entries of B, where the
// row-by-row CSR kernel (applyPoseTransferPaddedRows) spends a column load, a weight broadcast and
// an FMA on every entry. On the SMPL rigs the blocks hold 1.3x B's entries (the zeros), in about
// the bytes of the compact CSR copy (float weights, 16-bit columns), and the product runs in
// 0.35-0.45x its time with B in the caches, 0.45-0.5x out of them (docs/live.md).
//
// Load time: blockPoseTransfer allocates and may throw. Per frame: applyPoseTransferBlocked reads
// a view and writes a caller buffer: no allocation, no lock, no exception; any thread, concurrent
// calls on disjoint block ranges are fine (each row belongs to exactly one block).
#pragma once

#include "tetrig/aligned_vector.hpp"
#include "tetrig/pose_transfer.hpp"
#include "tetrig/pose_transfer_padded.hpp"

#include <cstdint>
#include <span>
#include <vector>

namespace tetrig {

// Rows (fine vertices) per block: one 8-float vector (an AVX2 register; half an AVX-512 one: 16 lanes
// measured slower, their blocks hold more zeros).
inline constexpr int kPoseBlockRows = 8;

struct BlockedPoseTransferView {
  const std::int32_t* block_offsets = nullptr;  // blocks + 1 entries into columns, [0] == 0
  const std::uint16_t* columns = nullptr;       // the union of each block's columns, ascending within a block
  const float* weights = nullptr;               // kPoseBlockRows per column entry (row lane l at [l]), 32-byte aligned
  const std::int32_t* lane_rows = nullptr;      // kPoseBlockRows per block: the fine vertex of each lane, -1 if none
  std::int32_t blocks = 0;
  std::int32_t rows = 0;                        // fine vertices
  std::int32_t cols = 0;                        // tet vertices
};

struct BlockedPoseTransfer {
  std::vector<std::int32_t> block_offsets;
  std::vector<std::uint16_t> columns;
  AlignedVector<float> weights;
  std::vector<std::int32_t> lane_rows;
  std::int32_t blocks = 0;
  std::int32_t rows = 0;
  std::int32_t cols = 0;

  using view_type = BlockedPoseTransferView;
  view_type view() const noexcept {
    return {block_offsets.data(), columns.data(), weights.data(), lane_rows.data(), blocks, rows, cols};
  }
  // Bytes the product streams: offsets, columns, weights and lane rows.
  std::int64_t bytes() const noexcept {
    return static_cast<std::int64_t>(block_offsets.size() * sizeof(std::int32_t) + columns.size() * sizeof(std::uint16_t) +
                                     weights.size() * sizeof(float) + lane_rows.size() * sizeof(std::int32_t));
  }
  // Stored weights (zeros included) per entry of B: how much the blocking adds.
  double fill(std::int64_t b_nonzeros) const noexcept {
    return b_nonzeros > 0 ? static_cast<double>(weights.size()) / static_cast<double>(b_nonzeros) : 0.0;
  }
};

// Blocks B (validated, at most 65536 columns: fitsCompactPoseTransfer) by the rows' rest positions
// `row_points` (rows x 3 doubles, row-major; the fine mesh at rest): rows are taken in Morton
// (z-curve) order of their position on a 2^21 grid over the points' bounding box, kPoseBlockRows at a
// time, so a block is a compact patch of the surface. Each weight rounded to float (relative error
// <= 2^-24). Load time; allocates; throws std::invalid_argument when B is invalid, has more than
// 65536 columns, or row_points does not hold rows x 3 finite values.
BlockedPoseTransfer blockPoseTransfer(const PoseTransferCsr<double>& b, std::span<const double> row_points);

// x_fine[r] = sum_j B(r, j) x_tet[j] for the rows of blocks [block_begin, block_end). x_tet4: #tetV
// x 4 floats (x, y, z, pad; e.g. Deformer::paddedFloatPositions(); the pad is not read); x_fine: #fine x
// 3 floats, written for those blocks' rows only. Summed in float, two partial sums per lane (even and
// odd columns of the block; a zero weight adds exactly 0): |error| <= (n + 4) 2^-24 sum_k |B_rk| |x_k|
// for a row of n entries. Frame path: no allocation, noexcept; the buffers hold cols*4 and rows*3 floats.
void applyPoseTransferBlocked(const BlockedPoseTransferView& b, const float* x_tet4, float* x_fine, std::int32_t block_begin,
                              std::int32_t block_end) noexcept;
inline void applyPoseTransferBlocked(const BlockedPoseTransferView& b, const float* x_tet4, float* x_fine) noexcept {
  applyPoseTransferBlocked(b, x_tet4, x_fine, 0, b.blocks);
}

}  // namespace tetrig
