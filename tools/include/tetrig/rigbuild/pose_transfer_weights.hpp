// Pose-transfer weights B (Stoll et al. 2007, section 2.4, eq. 2.9-2.12): every fine-surface
// vertex as a fixed linear combination of tet-mesh vertices, x_fine = B x_tet.
//
// For fine vertex v: the set T_r(v) holds every tet that has a boundary face (a face of the tet
// mesh's surface) whose centre lies within r of v. A tet with several boundary faces counts ONCE,
// at the distance d of its nearest boundary-face centre (the paper's T_r is a set of tets and
// phi a function of (v, t)). Each tet contributes the barycentric coordinates of v with respect to
// its four corners (extrapolated when v is outside the tet), weighted by Wendland's
// phi(d) = (1 - d/r)^4 (4 d/r + 1); the weights are normalised (eq. 2.9). Every tet's barycentric
// coordinates reproduce v exactly and sum to 1, so rows of B sum to 1 and B x_tet(rest) = x_fine
// (rest) up to rounding. A vertex with no tet in range uses the tet that contains it, else the tet
// of the nearest boundary-face centre.
// Spatial queries go through a nanoflann k-d tree over boundary-face centres (and tet centroids
// for the containing-tet fallback).
//
// Offline, any thread, allocates, throws RigBuildError on an empty or mismatched input.
#pragma once

#include "tetrig/tet_mesh.hpp"

#include <Eigen/SparseCore>

#include <cstdint>

namespace tetrig::rigbuild {

enum class WeightCap {
  // Keep whole tets, nearest first, while the row's distinct columns stay <= max_nonzeros_per_row
  // (at least one tet). Renormalised over the kept tets: still exact at rest.
  kDropFarTets,
  // Build the full row, then keep the max_nonzeros_per_row entries of largest magnitude and
  // rescale them to sum to 1. Not exact at rest (measured by restReconstructionError).
  kDropSmallEntries,
};

struct PoseTransferOptions {
  double radius_fraction = 0.05;        // r = radius_fraction * bounding-box diagonal of the fine mesh
  std::int32_t max_nonzeros_per_row = 0;  // 0 = no cap
  WeightCap cap_mode = WeightCap::kDropFarTets;
};

struct PoseTransferStats {
  double radius = 0.0;                 // r in mesh units
  std::int64_t nonzeros = 0;
  double mean_nonzeros_per_row = 0.0;
  std::int32_t max_nonzeros_per_row = 0;
  double mean_tets_per_row = 0.0;
  std::int32_t fallback_containing = 0;  // rows with no tet in range, inside a tet
  std::int32_t fallback_nearest = 0;     // rows with no tet in range, outside every tet
  std::int32_t capped_rows = 0;
  double max_abs_coefficient = 0.0;      // large values mean extrapolation through thin tets
  std::int32_t boundary_faces = 0;
};

// fine_vertices: #fine by 3 rest positions; tets: the tet mesh at rest (positively oriented).
// Returns B, #fine by #tetV, row-major, rows summing to 1. `stats` may be null.
Eigen::SparseMatrix<double, Eigen::RowMajor> poseTransferWeights(const Vertices& fine_vertices, const TetMesh& tets,
                                                                 const PoseTransferOptions& options = {},
                                                                 PoseTransferStats* stats = nullptr);

// max_i || (B x_tet)_i - fine_i || / bbox diagonal of fine_vertices: 0 up to rounding for an
// uncapped B at rest.
double restReconstructionError(const Eigen::SparseMatrix<double, Eigen::RowMajor>& b, const Vertices& fine_vertices,
                               const Vertices& tet_vertices);

}  // namespace tetrig::rigbuild
