// Local repair of self-intersections of a closed surface before tetrahedralization.
//
// Real scans and decimated surfaces often touch themselves (SMPL's thighs at the crotch and its
// toes, the Stanford dragon's scales; quadric decimation adds more). TetGen refuses such input.
// The coarse surface is only the deformation proxy (the fine mesh follows it through B), so small
// local changes are acceptable: the faces TetGen reports as intersecting (switch 'd') and their
// neighbourhood (`rings` vertex rings) are smoothed with the umbrella operator
// (x += lambda * (mean of neighbours - x)), which pulls touching bulges apart; repeated until
// TetGen finds no intersection or `max_rounds` is reached.
//
// Offline, any thread, allocates, throws RigBuildError when TetGen's check itself fails.
#pragma once

#include "tetrig/rigbuild/surface_mesh.hpp"

#include <cstdint>
#include <vector>

namespace tetrig::rigbuild {

struct SelfIntersectionOptions {
  int max_rounds = 12;
  int rings = 2;                 // neighbourhood smoothed around each intersecting face
  int smoothing_steps = 3;       // umbrella steps per round
  double lambda = 0.5;
};

struct SelfIntersectionRepair {
  std::int32_t initial_faces = 0;     // faces TetGen reported before any repair
  std::int32_t remaining_faces = 0;   // after the last round (0 = repaired)
  int rounds = 0;
  std::int32_t moved_vertices = 0;    // distinct vertices moved
  double max_displacement = 0.0;      // largest vertex move, mesh units
  std::vector<std::int32_t> moved;    // indices of the moved vertices
  bool repaired() const { return remaining_faces == 0; }
};

// Faces of `surface` that intersect another face, by TetGen's detection (tetrahedralize with
// switches "pdQ", run in a child process). Sorted, unique face indices.
std::vector<std::int32_t> findSelfIntersections(const SurfaceMesh& surface);

// Moves vertices of `surface` in place (connectivity unchanged) as described above.
SelfIntersectionRepair repairSelfIntersections(SurfaceMesh& surface, const SelfIntersectionOptions& options = {});

}  // namespace tetrig::rigbuild
