// The fine mesh's enclosed volume as a linear constraint on the tet-mesh positions, for
// Deformer::setLinearConstraint (docs/deformation.md, "Volume constraint").
//
// The fine mesh is x_fine = B x (the pose transfer, Stoll et al. 2007, eq. 2.12) and encloses
//   V(x_fine) = 1/6 sum_{triangles (a, b, c)} a . (b x c),   dV/da = 1/6 (b x c) (and cyclically).
// Linearized at a pose x0 (x_fine0 = B x0), with g = B^T dV/dx_fine (x_fine0), keeping V at its
// rest value reads
//   g . x = V_rest - V(x_fine0) + g . x0.
// The rotation term ||F - R||^2 has Poisson's ratio 0: it lets flexion creases lose volume, and a
// volume term per tet converges too slowly to fix that in a frame's few iterations
// (docs/fidelity.md); one constraint with a Lagrange multiplier costs one solve per frame.
//
// Threads: construct at load (allocates; B is copied, transposed); linearize() from one thread at a
// time, no allocation, lock or exception. `triangles` must outlive this object.
#pragma once

#include "tetrig/pose_transfer.hpp"
#include "tetrig/pose_transfer_blocked.hpp"

#include <cstdint>
#include <span>
#include <vector>

namespace tetrig {

// Volume enclosed by a closed triangle mesh (divergence theorem): triangles #F*3 vertex indices,
// x #V*3 positions; negative when the faces point inward.
template <typename T>
double enclosedVolume(std::span<const std::int32_t> triangles, const T* x) noexcept;

// True when every edge of the triangles is walked once each way, as often as the other: a closed
// (watertight), consistently oriented surface, which FineVolumeConstraint needs. Load time (allocates).
bool closedOrientedSurface(std::span<const std::int32_t> triangles);

class FineVolumeConstraint {
 public:
  // b: #fine x #tetV; triangles: #F*3 fine-vertex indices, outward; rest_fine: #fine*3 rest positions.
  // gradient_entries > 0 builds g from B with each row cut to its gradient_entries largest weights,
  // rescaled to the row's sum (g is then a direction near the exact one, far cheaper to gather: the
  // constraint's value c still comes from the measured volume, so it holds the volume to first
  // order in the frame's own motion; docs/deformation.md). 0: the exact B^T.
  // Throws std::invalid_argument on sizes that do not match, an index out of range, or triangles that
  // do not close (each edge walked once each way: a watertight, consistently oriented surface).
  FineVolumeConstraint(const PoseTransferView<double>& b, std::span<const std::int32_t> triangles,
                       std::span<const double> rest_fine, std::int32_t gradient_entries = 0);

  // Enclosed volume of a fine pose (#fine*3).
  template <typename T>
  double volume(const T* x_fine) const noexcept {
    return enclosedVolume(triangles_, x_fine);
  }

  // At the pose x_tet (#tetV*3, mesh order) whose fine pose is x_fine (= B x_tet, #fine*3): writes
  // g (#tetV*3) and returns c, so that g . x = c keeps the rest volume to first order. Returns the
  // fine pose's volume in *volume_now when not null.
  template <typename T>
  double linearize(std::span<const double> x_tet, const T* x_fine, std::span<double> g, double* volume_now = nullptr) noexcept;

  // The c of a g from an earlier linearize() at a new pose (x_tet, x_fine = B x_tet): the measured
  // volume sets it, V_rest - V(x_fine) + g . x_tet, without building g again.
  template <typename T>
  double value(std::span<const double> x_tet, const T* x_fine, std::span<const double> g) const noexcept;

  double restVolume() const noexcept { return rest_volume_; }
  std::int32_t tetVertexCount() const noexcept { return tet_vertices_; }
  std::int32_t fineVertexCount() const noexcept { return fine_vertices_; }

 private:
  std::int32_t tet_vertices_ = 0, fine_vertices_ = 0;  // B's columns and rows
  // B^T (a row per tet vertex: the fine vertices it moves), built at load, so that g = B^T dV/dx_fine
  // gathers instead of scattering (the scatter over B's rows took about four times the forward pose
  // transfer), with the pose transfer's own kernels: in blocks of 8 nearby tet vertices (each placed
  // at the |B|-weighted mean of the fine vertices it moves), half-precision weights (BlockedPoseTransfer::
  // toHalfWeights: g is a direction, 2^-11 of each weight tilts it by as little) and float sums, when there are
  // at most 65536 fine vertices (bt_blocked_), else row by row with float weights and double sums
  // (bt_wide_); the other is empty.
  BlockedPoseTransfer bt_blocked_;
  PoseTransferCsr<float> bt_wide_;
  std::span<const std::int32_t> triangles_;
  double rest_volume_ = 0.0;
  std::vector<double> fine_gradient4_;  // #fine*4 scratch: 6 dV/dx_fine, padded (x, y, z, 0), in double
  std::vector<float> fine_gradient4f_;  // #fine*4 scratch: the same in float (bt_blocked_ gathers it)
  std::vector<float> tet_gradient3f_;   // #tetV*3 scratch for bt_blocked_: B^T of it
};

}  // namespace tetrig
