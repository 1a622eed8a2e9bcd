// The fine mesh's enclosed volume as a linear constraint on the tet-mesh positions, for
// Deformer::setLinearConstraint (docs/deformation.md, "Volume constraint").
//
// The fine mesh is x_fine = B x (the pose transfer, Stoll et al. 2007, eq. 2.12) and encloses
//   V(x_fine) = 1/6 sum_{triangles (a, b, c)} a . (b x c).
// Keeping V at its rest value, linearized at a pose x0, reads
//   g . x = V_rest - V(x_fine0) + g . x0,
// with g a direction along which the volume grows. g is the gradient of the volume the body tet
// mesh's boundary encloses, W(x) = 1/6 sum_{boundary triangles} a . (b x c), at x0: the boundary's
// vertices are fine vertices (the decimated surface), and W and V move together, so g is near
// B^T dV/dx_fine and far cheaper: one pass over the boundary's few thousand triangles instead of a
// gather through B^T. The constraint's value comes from the measured fine volume, so each frame
// restores V itself to first order in the frame's motion, and the converged pose holds V exactly.
// (Keeping W itself instead lets V drift 5 % in HDM05's squats: the fine surface is not the
// boundary's.)
// The rotation term ||F - R||^2 has Poisson's ratio 0: it lets flexion creases lose volume, and a
// volume term per tet converges too slowly to fix that in a frame's few iterations
// (docs/fidelity.md); one constraint with a Lagrange multiplier costs a dot product and an axpy per
// solve, and the solve for its direction (Deformer::setLinearConstraint).
//
// Threads: construct at load (allocates); volume(), value() and linearize() from one thread at a
// time (they share a scratch), no allocation, lock or exception. `fine_triangles` must outlive this object.
#pragma once

#include "tetrig/tet_mesh.hpp"

#include <cstdint>
#include <span>
#include <vector>

namespace tetrig {

// Volume enclosed by a closed triangle mesh (divergence theorem): triangles #F*3 vertex indices,
// x #V*3 positions; negative when the faces point inward. Allocates a scratch (not for the frame path:
// FineVolumeConstraint::volume is).
template <typename T>
double enclosedVolume(std::span<const std::int32_t> triangles, const T* x);

// True when every edge of the triangles is walked once each way, as often as the other: a closed
// (watertight), consistently oriented surface, which FineVolumeConstraint needs. Load time (allocates).
bool closedOrientedSurface(std::span<const std::int32_t> triangles);

class FineVolumeConstraint {
 public:
  // tet_mesh: the rig's tet mesh at rest, whose first body_tets tets are the body's (the boundary,
  // boundaryFaces, is theirs: marker tets take no part); fine_triangles: #F*3 fine-vertex indices,
  // outward; rest_fine: #fine*3 rest positions. Throws std::invalid_argument on sizes that do not
  // match, an index out of range, or fine triangles that do not close (each edge walked once each
  // way: a watertight, consistently oriented surface).
  FineVolumeConstraint(const TetMesh& tet_mesh, std::int32_t body_tets, std::span<const std::int32_t> fine_triangles,
                       std::span<const double> rest_fine);

  // Enclosed volume of a fine pose (#fine*3).
  template <typename T>
  double volume(const T* x_fine) const noexcept;

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
  // The body tets' boundary: the faces of one body tet only, outward (#*3 tet-vertex indices).
  std::span<const std::int32_t> boundaryTriangles() const noexcept {
    return {boundary_.data(), static_cast<std::size_t>(boundary_.size())};
  }

 private:
  std::int32_t tet_vertices_ = 0, fine_vertices_ = 0;
  std::span<const std::int32_t> triangles_;  // the fine mesh's
  Triangles boundary_;                       // the body tets' boundary (row-major: #*3 in a row)
  double rest_volume_ = 0.0;                 // the fine mesh's
  std::vector<double> gradient4_;            // #tetV*4 scratch: 6 dW/dx, padded (x, y, z, 0)
  mutable std::vector<double> points4_;      // #fine*4 scratch: the fine pose widened (volume())
};

}  // namespace tetrig
