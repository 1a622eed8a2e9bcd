// The pose transfer in blocks of nearby fine vertices (tetrig/pose_transfer_blocked.hpp):
//
//   (x, y, z)_fine_{r_l} = sum_{c in block} W(c, l) (x, y, z)_tet_c,   one lane l per row of the block,
//
// W(c, l) = B(r_l, c), zero where row r_l does not use column c.
#include "tetrig/pose_transfer_blocked.hpp"
#include "tetrig/pose_transfer_padded.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <numeric>
#include <stdexcept>
#include <string>

#include "multiversion.hpp"

namespace tetrig {
namespace {

using Lanes8f = float __attribute__((vector_size(kPoseBlockRows * sizeof(float))));
static_assert(sizeof(Lanes8f) == kPoseBlockRows * sizeof(float));

// 21 bits of each coordinate interleaved: x in bits 0, 3, 6, ..., y in 1, 4, ..., z in 2, 5, ...
std::uint64_t spreadBits(std::uint64_t v) {
  std::uint64_t r = 0;
  for (int bit = 0; bit < 21; ++bit) r |= ((v >> bit) & 1u) << (3 * bit);
  return r;
}

// Rows in Morton order of their points on a 2^21 grid over the bounding box (ties by row index).
std::vector<std::int32_t> mortonOrder(std::span<const double> points, std::int32_t rows) {
  double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
  for (std::int32_t i = 0; i < rows; ++i) {
    for (int d = 0; d < 3; ++d) {
      lo[d] = std::min(lo[d], points[3 * static_cast<std::size_t>(i) + d]);
      hi[d] = std::max(hi[d], points[3 * static_cast<std::size_t>(i) + d]);
    }
  }
  const double extent = std::max({hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2], 0.0});
  constexpr double kCells = (1 << 21) - 1;
  const double scale = extent > 0.0 ? kCells / extent : 0.0;
  std::vector<std::uint64_t> key(static_cast<std::size_t>(rows));
  for (std::int32_t i = 0; i < rows; ++i) {
    std::uint64_t k = 0;
    for (int d = 0; d < 3; ++d) {
      const double cell = std::clamp((points[3 * static_cast<std::size_t>(i) + d] - lo[d]) * scale, 0.0, kCells);
      k |= spreadBits(static_cast<std::uint64_t>(cell)) << d;
    }
    key[static_cast<std::size_t>(i)] = k;
  }
  std::vector<std::int32_t> order(static_cast<std::size_t>(rows));
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(),
                   [&](std::int32_t a, std::int32_t b) { return key[static_cast<std::size_t>(a)] < key[static_cast<std::size_t>(b)]; });
  return order;
}

}  // namespace

BlockedPoseTransfer blockPoseTransfer(const PoseTransferCsr<double>& b, std::span<const double> row_points) {
  if (std::string e = validatePoseTransfer(b.view()); !e.empty()) throw std::invalid_argument("pose transfer: " + e);
  if (!fitsCompactPoseTransfer(b.cols))
    throw std::invalid_argument("pose transfer: " + std::to_string(b.cols) + " tet vertices, more than the 65536 the blocked copy indexes");
  if (row_points.size() != 3 * static_cast<std::size_t>(b.rows))
    throw std::invalid_argument("pose transfer: " + std::to_string(row_points.size()) + " rest coordinates for " +
                                std::to_string(b.rows) + " fine vertices (3 each expected)");
  for (const double v : row_points)
    if (!std::isfinite(v)) throw std::invalid_argument("pose transfer: a fine vertex's rest position is not finite");

  const std::vector<std::int32_t> order = mortonOrder(row_points, b.rows);
  BlockedPoseTransfer out;
  out.rows = b.rows;
  out.cols = b.cols;
  out.blocks = (b.rows + kPoseBlockRows - 1) / kPoseBlockRows;
  out.block_offsets.reserve(static_cast<std::size_t>(out.blocks) + 1);
  out.block_offsets.push_back(0);
  out.lane_rows.assign(static_cast<std::size_t>(out.blocks) * kPoseBlockRows, -1);
  std::vector<std::int32_t> slot(static_cast<std::size_t>(b.cols), -1);  // column -> its index in the block
  std::vector<std::int32_t> block_columns;
  for (std::int32_t block = 0; block < out.blocks; ++block) {
    const std::int32_t first = block * kPoseBlockRows;
    const std::int32_t last = std::min(b.rows, first + kPoseBlockRows);
    block_columns.clear();
    for (std::int32_t t = first; t < last; ++t) {
      const std::int32_t row = order[static_cast<std::size_t>(t)];
      out.lane_rows[static_cast<std::size_t>(t)] = row;
      for (std::int32_t k = b.row_offsets[static_cast<std::size_t>(row)]; k < b.row_offsets[static_cast<std::size_t>(row) + 1]; ++k)
        block_columns.push_back(b.columns[static_cast<std::size_t>(k)]);
    }
    std::sort(block_columns.begin(), block_columns.end());
    block_columns.erase(std::unique(block_columns.begin(), block_columns.end()), block_columns.end());
    const std::size_t base = out.columns.size();
    for (std::size_t s = 0; s < block_columns.size(); ++s) {
      slot[static_cast<std::size_t>(block_columns[s])] = static_cast<std::int32_t>(s);
      out.columns.push_back(static_cast<std::uint16_t>(block_columns[s]));
    }
    out.weights.resize(out.columns.size() * kPoseBlockRows, 0.0f);
    for (std::int32_t t = first; t < last; ++t) {
      const std::int32_t row = order[static_cast<std::size_t>(t)];
      for (std::int32_t k = b.row_offsets[static_cast<std::size_t>(row)]; k < b.row_offsets[static_cast<std::size_t>(row) + 1]; ++k) {
        const auto s = static_cast<std::size_t>(slot[static_cast<std::size_t>(b.columns[static_cast<std::size_t>(k)])]);
        // A column repeated within a row (CSR allows it) adds up, as the product would.
        out.weights[(base + s) * kPoseBlockRows + static_cast<std::size_t>(t - first)] +=
            static_cast<float>(b.weights[static_cast<std::size_t>(k)]);
      }
    }
    for (const std::int32_t c : block_columns) slot[static_cast<std::size_t>(c)] = -1;
    out.block_offsets.push_back(static_cast<std::int32_t>(out.columns.size()));
  }
  return out;
}

namespace {

// Column entry k's kPoseBlockRows weights (from w) as float lanes.
__attribute__((always_inline)) inline Lanes8f weightsOf(const float* w, std::int32_t k) noexcept {
  Lanes8f lanes;
  std::memcpy(&lanes, w + static_cast<std::ptrdiff_t>(k) * kPoseBlockRows, sizeof lanes);
  return lanes;
}

// Sums W(c, l) x_tet[c] over `count` column entries of a block (weights w, columns cols) into two
// partial sums per coordinate (even and odd entries): the FMA chains' latency, not the loads, would
// set the pace with one.
struct BlockSums {
  Lanes8f x0{}, y0{}, z0{}, x1{}, y1{}, z1{};
};
__attribute__((always_inline)) inline void accumulate(const float* w, const std::uint16_t* cols, std::int32_t count,
                                                      const float* x_tet4, BlockSums& s) noexcept {
  std::int32_t k = 0;
  for (; k + 2 <= count; k += 2) {
    const Lanes8f w0 = weightsOf(w, k), w1 = weightsOf(w, k + 1);
    const float* p = x_tet4 + 4 * static_cast<std::ptrdiff_t>(cols[k]);
    const float* q = x_tet4 + 4 * static_cast<std::ptrdiff_t>(cols[k + 1]);
    s.x0 += w0 * p[0];
    s.y0 += w0 * p[1];
    s.z0 += w0 * p[2];
    s.x1 += w1 * q[0];
    s.y1 += w1 * q[1];
    s.z1 += w1 * q[2];
  }
  if (k < count) {
    const Lanes8f w0 = weightsOf(w, k);
    const float* p = x_tet4 + 4 * static_cast<std::ptrdiff_t>(cols[k]);
    s.x0 += w0 * p[0];
    s.y0 += w0 * p[1];
    s.z0 += w0 * p[2];
  }
}

__attribute__((always_inline)) inline void storeBlock(const BlockSums& s, const std::int32_t* rows, float* x_fine) {
  const Lanes8f x = s.x0 + s.x1, y = s.y0 + s.y1, z = s.z0 + s.z1;
  for (int l = 0; l < kPoseBlockRows; ++l) {
    const std::int32_t r = rows[l];
    if (r < 0) continue;
    float* out = x_fine + 3 * static_cast<std::ptrdiff_t>(r);
    out[0] = x[l];
    out[1] = y[l];
    out[2] = z[l];
  }
}

// Blocks [block_begin, block_end), each summed whole.
TETRIG_MULTIVERSION void applyFloatWeights(const BlockedPoseTransferView& b, const float* x_tet4, float* x_fine,
                                           std::int32_t block_begin, std::int32_t block_end) noexcept {
  for (std::int32_t block = block_begin; block < block_end; ++block) {
    BlockSums sums;
    const std::int32_t begin = b.block_offsets[block];
    accumulate(b.weights + static_cast<std::ptrdiff_t>(begin) * kPoseBlockRows, b.columns + begin, b.block_offsets[block + 1] - begin,
               x_tet4, sums);
    storeBlock(sums, b.lane_rows + static_cast<std::ptrdiff_t>(block) * kPoseBlockRows, x_fine);
  }
}

}  // namespace

void applyPoseTransferBlocked(const BlockedPoseTransferView& b, const float* x_tet4, float* x_fine, std::int32_t block_begin,
                              std::int32_t block_end) noexcept {
  applyFloatWeights(b, x_tet4, x_fine, block_begin, block_end);
}

}  // namespace tetrig
