// Face-constrained Delaunay tetrahedralization of a closed surface with TetGen
// (H. Si, "TetGen, a Delaunay-based quality tetrahedral mesh generator", ACM TOMS 2015),
// switches "pq2.0QY": piecewise linear complex input, a radius-edge ratio bound of 2 (TetGen adds
// points inside the volume until every tet meets it), quiet, boundary preserved (no Steiner
// points on the surface). Stoll et al. 2007 (section 2.3.1) use a coarse tessellation without
// interior vertices; measured here, such tets span the whole shape (a long cylinder: median
// radius ratio 0.05-0.1) and fold when it bends (docs/rig-builder.md), so the quality bound is
// on, and the tet-vertex budget is shared between the surface and the interior points
// (buildCoarseTetMesh).
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
  std::string switches = "pq2.0QY";  // TetGen command-line switches (without the leading '-'); "pQY": no interior points
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

// A selection made on the surface (vertex ids, .sel statuses) reaching into the volume, for tet
// selections (region handles, rigid groups, stiffness): an interior tet vertex (one of TetGen's
// points inside, `is_surface[v] == 0`) joins `mask` (one flag per tet vertex) when
//   (b) it is the fourth corner of a tet whose other three corners are selected surface vertices
//       (the tets standing on the selected surface belong to it), or
//   (a) every vertex it shares a tet edge with is selected or joins too (the largest such set:
//       the volume a selected surface encloses).
// Without it a tet under a selected patch could never have four selected corners once the tet
// mesh has interior vertices, and a region handle (min_corners 4) would hold almost no tet.
void extendSelectionInward(const TetMesh& mesh, const std::vector<std::uint8_t>& is_surface, std::vector<std::uint8_t>& mask);

// Decimation, self-intersection repair (repairSelfIntersections: the input and the decimation
// may make the surface touch itself) and tetrahedralization together. decimate.target_vertices
// is the budget of the whole tet mesh: TetGen's interior points count, so when the first round
// ends above the budget (+3 %) the surface is decimated further (progressively, SurfaceDecimator)
// by the ratio found and tetrahedralized again, up to 5 rounds. When a step refuses the
// decimated surface the budget is varied by +3 %, -3 %, +6 %, -6 %, ... (up to `retries` extra
// attempts) before giving up with an explanation of every attempt. Coarse vertices moved by the
// repair are no longer exactly at their fine vertex (repair.moved).
struct CoarseRig {
  DecimationResult decimation;   // decimation.coarse holds the repaired positions
  SelfIntersectionRepair repair;
  TetrahedralizeResult tets;
  // For each tet vertex: its fine-surface vertex (decimation keeps fine vertices), -1 if interior.
  std::vector<std::int32_t> tet_to_fine;
  std::int32_t used_target = 0;     // the tet-vertex budget of the successful attempt
  std::int32_t surface_target = 0;  // the surface's share of it (the rest: TetGen's interior points)
  int budget_rounds = 0;            // decimate-and-tetrahedralize rounds it took
  std::vector<std::string> failed_attempts;  // one line per retried attempt
};
CoarseRig buildCoarseTetMesh(const SurfaceMesh& fine, const DecimateOptions& decimate = {},
                             const TetrahedralizeOptions& tetrahedralize = {}, int retries = 6,
                             const SelfIntersectionOptions& intersections = {});

}  // namespace tetrig::rigbuild
