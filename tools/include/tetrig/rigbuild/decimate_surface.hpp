// Quadric-error decimation of a closed surface to a vertex budget, with meshoptimizer's
// meshopt_simplify (edge collapse ordered by Garland-Heckbert quadric error; vertices are never
// moved, so the coarse vertices are a subset of the fine ones).
//
// Offline, any thread, allocates, throws RigBuildError when the result is not closed and manifold.
#pragma once

#include "tetrig/rigbuild/surface_mesh.hpp"

#include <cstdint>
#include <vector>

namespace tetrig::rigbuild {

struct DecimateOptions {
  std::int32_t target_vertices = 2500;  // the tet-vertex budget for the surface
  // Accept a result within this fraction of the target (meshopt_simplify counts triangles and may
  // stop early on topology; the target triangle count is corrected up to max_attempts times).
  double tolerance = 0.03;
  int max_attempts = 6;
  bool lock_border = true;              // meshopt_SimplifyLockBorder (a closed mesh has no border)
};

struct DecimationResult {
  SurfaceMesh coarse;                          // compact: only the kept vertices, same orientation
  std::vector<std::int32_t> coarse_to_fine;    // #coarse V: index of each coarse vertex in the fine mesh
  double relative_error = 0.0;                 // meshopt's error, relative to the mesh extent
  std::int32_t removed_folded_faces = 0;       // face pairs folded onto each other, removed
  int attempts = 0;
};

// Decimates a closed, manifold, outward surface (see validateSurface) to about
// options.target_vertices vertices. When the input already has no more vertices than the
// target it is returned unchanged (identity map). The result is checked to be closed, manifold
// and consistently oriented; otherwise RigBuildError says so.
DecimationResult decimateSurface(const SurfaceMesh& fine, const DecimateOptions& options = {});

}  // namespace tetrig::rigbuild
