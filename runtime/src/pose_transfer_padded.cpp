// Pose transfer x_fine = B x_tet (Stoll et al. 2007, eq. 2.12) from padded tet positions: each tet
// vertex is (x, y, z, pad), so an entry of B costs one vector load and one 4-wide FMA,
//   (x, y, z, pad)_fine_i = sum_k B(i, c_k) (x, y, z, pad)_tet_c_k,
// instead of three scalar loads and three FMAs chained on one running sum per coordinate (the
// stride-3 kernel in pose_transfer.cpp). Two partial sums per row (even and odd entries), in double
// whatever the weights' type. The live rig streams B's compact copy (float weights, 16-bit columns:
// narrowPoseTransfer), half the bytes of the rig's double B.
#include "tetrig/pose_transfer_padded.hpp"

#include <cstdint>

#include "multiversion.hpp"
#include "vector_lanes.hpp"

namespace tetrig {

template <typename W, typename C, typename Out>
TETRIG_MULTIVERSION void applyPoseTransferPaddedRows(const PoseTransferView<W, C>& b, const double* x_tet4, Out* x_fine,
                                                     std::int32_t row_begin, std::int32_t row_end) noexcept {
  using lanes::load4;
  using lanes::Vec4;
  const std::int32_t* offsets = b.row_offsets;
  const C* cols = b.columns;
  const W* w = b.weights;
  for (std::int32_t i = row_begin; i < row_end; ++i) {
    Vec4 s0{}, s1{};
    const std::int32_t end = offsets[i + 1];
    std::int32_t k = offsets[i];
    for (; k + 2 <= end; k += 2) {
      s0 += static_cast<double>(w[k]) * load4(x_tet4 + 4 * static_cast<std::ptrdiff_t>(cols[k]));
      s1 += static_cast<double>(w[k + 1]) * load4(x_tet4 + 4 * static_cast<std::ptrdiff_t>(cols[k + 1]));
    }
    if (k < end) s0 += static_cast<double>(w[k]) * load4(x_tet4 + 4 * static_cast<std::ptrdiff_t>(cols[k]));
    const Vec4 s = s0 + s1;
    Out* out = x_fine + static_cast<std::ptrdiff_t>(i) * 3;
    out[0] = static_cast<Out>(s[0]);
    out[1] = static_cast<Out>(s[1]);
    out[2] = static_cast<Out>(s[2]);
  }
}

// Float tet positions (x, y, z, pad as 4 floats: the tet mesh's 1541 vertices take 25 KB, inside L1,
// where doubles took 49 KB) and float sums, four partial sums per row: an entry is then one column
// load, one weight broadcast and one 4-wide FMA with its position as the memory operand; with four
// independent sums the loads, not the FMA latency, set the pace. Rounding: each of the <= n/4 + 3
// additions on a partial sum's path adds at most 2^-24 of the running magnitude, and the weight and
// the position each one more, so |error| <= (n/4 + 5) 2^-24 sum_k |B_ik| |x_k|, a few micrometres
// on a body of 2 m (tested against the exact product).
TETRIG_MULTIVERSION void applyPoseTransferPaddedRows(const PoseTransferView<float, std::uint16_t>& b, const float* x_tet4,
                                                     float* x_fine, std::int32_t row_begin, std::int32_t row_end) noexcept {
  using lanes::load4f;
  using lanes::Vec4f;
  const std::int32_t* offsets = b.row_offsets;
  const std::uint16_t* cols = b.columns;
  const float* w = b.weights;
  for (std::int32_t i = row_begin; i < row_end; ++i) {
    Vec4f s0{}, s1{}, s2{}, s3{};
    const std::int32_t end = offsets[i + 1];
    std::int32_t k = offsets[i];
    for (; k + 4 <= end; k += 4) {
      s0 += w[k] * load4f(x_tet4 + 4 * static_cast<std::ptrdiff_t>(cols[k]));
      s1 += w[k + 1] * load4f(x_tet4 + 4 * static_cast<std::ptrdiff_t>(cols[k + 1]));
      s2 += w[k + 2] * load4f(x_tet4 + 4 * static_cast<std::ptrdiff_t>(cols[k + 2]));
      s3 += w[k + 3] * load4f(x_tet4 + 4 * static_cast<std::ptrdiff_t>(cols[k + 3]));
    }
    for (; k < end; ++k) s0 += w[k] * load4f(x_tet4 + 4 * static_cast<std::ptrdiff_t>(cols[k]));
    const Vec4f s = (s0 + s1) + (s2 + s3);
    float* out = x_fine + static_cast<std::ptrdiff_t>(i) * 3;
    out[0] = s[0];
    out[1] = s[1];
    out[2] = s[2];
  }
}

#define TETRIG_POSE_TRANSFER_PADDED(W, C, Out)                                                                 \
  template void applyPoseTransferPaddedRows<W, C, Out>(const PoseTransferView<W, C>&, const double*, Out*, std::int32_t, \
                                                       std::int32_t) noexcept;
TETRIG_POSE_TRANSFER_PADDED(float, std::int32_t, float)
TETRIG_POSE_TRANSFER_PADDED(float, std::int32_t, double)
TETRIG_POSE_TRANSFER_PADDED(double, std::int32_t, float)
TETRIG_POSE_TRANSFER_PADDED(double, std::int32_t, double)
TETRIG_POSE_TRANSFER_PADDED(float, std::uint16_t, float)
TETRIG_POSE_TRANSFER_PADDED(float, std::uint16_t, double)
#undef TETRIG_POSE_TRANSFER_PADDED

}  // namespace tetrig
