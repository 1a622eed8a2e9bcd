// Tetrahedral gradient operators, the Laplacian L = G^T D G and differential coordinates
// delta = G^T D g (Stoll et al. 2007, section 2.2, eq. 2.1-2.5).
//
// Conventions (column vectors; the paper writes the same with row vectors):
//   E_j     = [p1 - p4, p2 - p4, p3 - p4]       rest edge matrix of tet j, 3x3, edges as columns
//   E_j^-1  rows are the gradients of the shape functions phi_1..phi_3; grad phi_4 = -(sum of them)
//   G_j     = [grad phi_1 .. grad phi_4]        3x4 (eq. 2.2-2.3)
//   F_j     = X_j G_j^T = E'_j E_j^-1           deformation gradient (the paper's T_j, transposed)
//   a_j     = stiffness_j * |volume_j|          the diagonal of D (section 2.3.2, end: stiffness)
//   L       = sum_j a_j G_j^T G_j               n x n, symmetric positive semidefinite, L 1 = 0
//   delta_v = sum_{j, corner k = v} a_j R_j grad phi_k     (= G^T D g with g_j = R_j, eq. 2.5)
// With R_j = I, delta = L x_rest: the rest pose is a solution.
// Load-time code: allocates, may throw std::invalid_argument on bad input.
#pragma once

#include "tetrig/tet_mesh.hpp"

#include <Eigen/Core>
#include <Eigen/SparseCore>

#include <span>
#include <vector>

namespace tetrig {

struct TetRestFrames {
  std::vector<Eigen::Matrix3d> edge_inverse;  // E_j^-1 per tet (#T)
  std::vector<double> volume;                 // |signed volume| per tet (#T)
};

// Computes E_j^-1 and volumes. Throws std::invalid_argument naming the first tet whose volume is
// zero (or not finite), since its gradient operator does not exist.
TetRestFrames computeRestFrames(const TetMesh& mesh);

// Per-tet weights a_j = stiffness_j * volume_j. `stiffness` is empty (all 1) or #T positive values.
std::vector<double> tetWeights(const TetRestFrames& frames, std::span<const double> stiffness);

// L = G^T D G, #V by #V (eq. 2.4).
Eigen::SparseMatrix<double> assembleLaplacian(const TetMesh& mesh, const TetRestFrames& frames,
                                              std::span<const double> weights);

// delta = G^T D g(R) (eq. 2.5) for per-tet rotations R_j (#T); returns #V by 3. Reference
// implementation (the frame path uses the fused kernel in rotation_kernel.hpp).
Vertices differentialCoordinates(const TetMesh& mesh, const TetRestFrames& frames, std::span<const double> weights,
                                 std::span<const Eigen::Matrix3d> rotations);

// Deformation gradient F_j = E'_j E_j^-1 of tet t for deformed positions x (#V by 3).
Eigen::Matrix3d deformationGradient(const TetMesh& mesh, const TetRestFrames& frames, const Vertices& x,
                                    std::int32_t t);

}  // namespace tetrig
