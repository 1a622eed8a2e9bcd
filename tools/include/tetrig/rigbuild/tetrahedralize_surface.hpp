// Face-constrained Delaunay tetrahedralization of a closed surface with TetGen
// (H. Si, "TetGen, a Delaunay-based quality tetrahedral mesh generator", ACM TOMS 2015),
// switches "pQY": piecewise linear complex input, quiet, boundary preserved (no Steiner points
// on the surface). No quality bound is asked for: per Stoll et al. 2007 section 2.3.1 a coarse
// tessellation, even one without interior vertices, deforms well.
//
// TetGen is AGPL-3: this file belongs to the offline tools and must never enter the runtime.
// TetGen runs in a forked child process (POSIX): TetGen 1.5.0 crashes (double free) while it
// reports input errors such as self-intersections, and the child turns that crash into a
// RigBuildError here. Offline, any thread (glibc makes malloc safe in the child of a
// multi-threaded parent), allocates, throws RigBuildError.
#pragma once

#include "tetrig/rigbuild/decimate_surface.hpp"
#include "tetrig/rigbuild/repair_self_intersections.hpp"
#include "tetrig/rigbuild/surface_mesh.hpp"
#include "tetrig/tet_mesh.hpp"

#include <cstdint>
#include <string>
#include <vector>

namespace tetrig::rigbuild {

struct TetrahedralizeOptions {
  std::string switches = "pQY";  // TetGen command-line switches (without the leading '-')
};

struct TetrahedralizeResult {
  TetMesh mesh;                                     // every tet positively oriented
  // For each tet vertex: the coarse-surface vertex it is (tet vertices 0..#coarse-1 are the
  // coarse vertices in order), or -1 for a point TetGen added inside the volume.
  std::vector<std::int32_t> tet_to_coarse;
  std::int32_t interior_vertices = 0;               // points TetGen added (Steiner points)
  std::int32_t flipped_tets = 0;                    // tets re-ordered to positive orientation
};

// Tetrahedralizes a closed, manifold, outward surface. TetGen's refusals (self-intersection,
// close facets, tiny features) become RigBuildError with TetGen's code and what to do.
// The result passes checkTetMesh (no inverted or zero-volume tet) or RigBuildError is thrown.
TetrahedralizeResult tetrahedralizeSurface(const SurfaceMesh& coarse, const TetrahedralizeOptions& options = {});

// Decimation, self-intersection repair (repairSelfIntersections: the input and the decimation
// may make the surface touch itself) and tetrahedralization together, retrying when a step
// refuses the decimated surface: the vertex target is varied by +3 %, -3 %, +6 %, -6 %, ...
// (up to `retries` extra attempts) before giving up with an explanation of every attempt.
// Coarse vertices moved by the repair are no longer exactly at their fine vertex (repair.moved).
struct CoarseRig {
  DecimationResult decimation;   // decimation.coarse holds the repaired positions
  SelfIntersectionRepair repair;
  TetrahedralizeResult tets;
  // For each tet vertex: its fine-surface vertex (decimation keeps fine vertices), -1 if interior.
  std::vector<std::int32_t> tet_to_fine;
  std::int32_t used_target = 0;
  std::vector<std::string> failed_attempts;  // one line per retried attempt
};
CoarseRig buildCoarseTetMesh(const SurfaceMesh& fine, const DecimateOptions& decimate = {},
                             const TetrahedralizeOptions& tetrahedralize = {}, int retries = 6,
                             const SelfIntersectionOptions& intersections = {});

}  // namespace tetrig::rigbuild
