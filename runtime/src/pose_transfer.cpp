// Pose transfer x_fine = B x_tet (Stoll et al. 2007, eq. 2.12) over a CSR matrix.
#include "tetrig/pose_transfer.hpp"
#include "tetrig/pose_transfer_padded.hpp"

#include <cmath>
#include <limits>
#include <stdexcept>
#include <type_traits>

namespace tetrig {

template <typename W>
PoseTransferCsr<W> makePoseTransferCsr(const Eigen::SparseMatrix<double, Eigen::RowMajor>& b) {
  Eigen::SparseMatrix<double, Eigen::RowMajor> compressed = b;
  compressed.makeCompressed();
  PoseTransferCsr<W> csr;
  csr.rows = static_cast<std::int32_t>(compressed.rows());
  csr.cols = static_cast<std::int32_t>(compressed.cols());
  csr.row_offsets.assign(compressed.outerIndexPtr(), compressed.outerIndexPtr() + compressed.rows() + 1);
  const auto nnz = static_cast<size_t>(compressed.nonZeros());
  csr.columns.assign(compressed.innerIndexPtr(), compressed.innerIndexPtr() + nnz);
  csr.weights.resize(nnz);
  for (size_t k = 0; k < nnz; ++k) csr.weights[k] = static_cast<W>(compressed.valuePtr()[k]);
  return csr;
}

template <typename W, typename C>
std::string validatePoseTransfer(const PoseTransferView<W, C>& b) {
  if (b.rows < 0 || b.cols < 0) return "negative matrix size";
  if (b.row_offsets == nullptr) return "no row offsets";
  if (b.row_offsets[0] != 0) return "row_offsets[0] is not 0";
  for (std::int32_t i = 0; i < b.rows; ++i) {
    if (b.row_offsets[i + 1] < b.row_offsets[i]) return "row offsets decrease at row " + std::to_string(i);
  }
  const std::int32_t nnz = b.row_offsets[b.rows];
  if (nnz > 0 && (b.columns == nullptr || b.weights == nullptr)) return "no column or weight array";
  for (std::int32_t k = 0; k < nnz; ++k) {
    const auto column = static_cast<std::int64_t>(b.columns[k]);
    if (column < 0 || column >= b.cols) return "column index out of range at entry " + std::to_string(k);
    if (!std::isfinite(static_cast<double>(b.weights[k]))) return "non-finite weight at entry " + std::to_string(k);
  }
  return {};
}

CompactPoseTransfer narrowPoseTransfer(const PoseTransferCsr<double>& b) {
  if (!fitsCompactPoseTransfer(b.cols))
    throw std::invalid_argument("pose transfer: " + std::to_string(b.cols) +
                                " tet vertices do not fit 16-bit column indices (at most 65536)");
  if (std::string fault = validatePoseTransfer(b.view()); !fault.empty())
    throw std::invalid_argument("pose transfer: " + fault);
  CompactPoseTransfer compact;
  compact.rows = b.rows;
  compact.cols = b.cols;
  compact.row_offsets = b.row_offsets;
  compact.columns.resize(b.columns.size());
  compact.weights.resize(b.weights.size());
  for (std::size_t k = 0; k < b.columns.size(); ++k) {
    compact.columns[k] = static_cast<std::uint16_t>(b.columns[k]);
    compact.weights[k] = static_cast<float>(b.weights[k]);
  }
  return compact;
}

template <typename W, typename In, typename Out>
void applyPoseTransferRows(const PoseTransferView<W>& b, const In* x_tet, Out* x_fine, std::int32_t row_begin,
                           std::int32_t row_end) noexcept {
  using Acc = std::conditional_t<std::is_same_v<W, float> && std::is_same_v<In, float> && std::is_same_v<Out, float>,
                                 float, double>;
  const std::int32_t* offsets = b.row_offsets;
  const std::int32_t* cols = b.columns;
  const W* w = b.weights;
  for (std::int32_t i = row_begin; i < row_end; ++i) {
    Acc x = 0, y = 0, z = 0;
    const std::int32_t end = offsets[i + 1];
    for (std::int32_t k = offsets[i]; k < end; ++k) {
      const In* p = x_tet + static_cast<std::ptrdiff_t>(cols[k]) * 3;
      const Acc wk = static_cast<Acc>(w[k]);
      x += wk * static_cast<Acc>(p[0]);
      y += wk * static_cast<Acc>(p[1]);
      z += wk * static_cast<Acc>(p[2]);
    }
    Out* out = x_fine + static_cast<std::ptrdiff_t>(i) * 3;
    out[0] = static_cast<Out>(x);
    out[1] = static_cast<Out>(y);
    out[2] = static_cast<Out>(z);
  }
}

#define TETRIG_POSE_TRANSFER_W(W)                                                             \
  template PoseTransferCsr<W> makePoseTransferCsr<W>(const Eigen::SparseMatrix<double, Eigen::RowMajor>&); \
  template std::string validatePoseTransfer<W, std::int32_t>(const PoseTransferView<W, std::int32_t>&);
#define TETRIG_POSE_TRANSFER_APPLY(W, In, Out)                                                  \
  template void applyPoseTransferRows<W, In, Out>(const PoseTransferView<W>&, const In*, Out*, std::int32_t, \
                                                  std::int32_t) noexcept;
TETRIG_POSE_TRANSFER_W(float)
TETRIG_POSE_TRANSFER_W(double)
template std::string validatePoseTransfer<float, std::uint16_t>(const CompactPoseTransfer::view_type&);
TETRIG_POSE_TRANSFER_APPLY(float, float, float)
TETRIG_POSE_TRANSFER_APPLY(float, double, float)
TETRIG_POSE_TRANSFER_APPLY(float, double, double)
TETRIG_POSE_TRANSFER_APPLY(float, float, double)
TETRIG_POSE_TRANSFER_APPLY(double, double, double)
TETRIG_POSE_TRANSFER_APPLY(double, double, float)
TETRIG_POSE_TRANSFER_APPLY(double, float, float)
TETRIG_POSE_TRANSFER_APPLY(double, float, double)
#undef TETRIG_POSE_TRANSFER_W
#undef TETRIG_POSE_TRANSFER_APPLY

}  // namespace tetrig
