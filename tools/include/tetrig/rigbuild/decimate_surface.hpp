// Quadric-error decimation of a closed surface to a vertex budget, with OpenMesh's decimater
// (halfedge collapses ordered by the Garland-Heckbert quadric error; vertices are never moved, so
// the coarse vertices are a subset of the fine ones), guarded so that the result tetrahedralizes
// into tets fit for deformation:
//   - an edge-length bound: no collapse may create an edge longer than max_edge_factor times the
//     edge of an even triangulation of the surface at the target, h = sqrt(2 A / (sqrt(3) V))
//     for area A and V target vertices. Pure quadric decimation has zero error along straight
//     generators (a cylinder keeps a few rings, its triangles and then its tets run the whole
//     length, and they invert when it bends);
//   - an aspect-ratio guard: no collapse may create a triangle whose aspect ratio
//     (longest edge^2 / twice the area; 1.155 for an equilateral triangle) exceeds max_aspect,
//     unless it improves the worst triangle around the collapsed vertex;
//   - a normal guard: no collapse may turn a face's normal by more than max_normal_deviation.
// When no legal collapse is left above the target, the edge bound grows by 25 % and decimation
// continues (at most max_relaxations times); the result then says how far it was relaxed.
//
// Offline, any thread, allocates, throws RigBuildError when the result is not closed and manifold.
#pragma once

#include "tetrig/rigbuild/surface_mesh.hpp"

#include <cstdint>
#include <memory>
#include <vector>

namespace tetrig::rigbuild {

struct DecimateOptions {
  std::int32_t target_vertices = 2500;  // surface vertices to keep
  double max_edge_factor = 2.0;         // edge bound = this x the even edge length at the target
  double max_aspect = 4.0;              // triangle aspect-ratio guard (longest edge^2 / (2 area))
  double max_normal_deviation = 60.0;   // degrees a face normal may turn in one collapse
  int max_relaxations = 12;             // edge-bound growths (x1.25 each) before stopping short
};

struct DecimationResult {
  SurfaceMesh coarse;                          // compact: only the kept vertices, same orientation
  std::vector<std::int32_t> coarse_to_fine;    // #coarse V: index of each coarse vertex in the fine mesh
  double even_edge_length = 0.0;               // h at the target (see above), in mesh units
  double edge_bound = 0.0;                     // the edge bound finally used (>= max_edge_factor h)
  int relaxations = 0;                         // how often the edge bound grew
  double longest_edge = 0.0;                   // longest edge of the result, in mesh units
  double worst_aspect = 0.0;                   // largest triangle aspect ratio of the result
  std::int32_t removed_folded_faces = 0;       // face pairs folded onto each other, removed (safety net)
};

// Decimates a closed, manifold, outward surface (see validateSurface) to about
// options.target_vertices vertices. When the input already has no more vertices than the
// target it is returned unchanged (identity map). The result is checked to be closed, manifold
// and consistently oriented; otherwise RigBuildError says so. Deterministic.
DecimationResult decimateSurface(const SurfaceMesh& fine, const DecimateOptions& options = {});

// The same, progressively: each decimateTo(n) continues from the previous result (n must not
// grow), so a caller that searches for the surface budget (buildCoarseTetMesh: surface vertices
// + TetGen's interior points = the tet-vertex budget) pays for the long first pass once. The
// edge bound follows the current target. `fine` must outlive the decimator.
class SurfaceDecimator {
 public:
  SurfaceDecimator(const SurfaceMesh& fine, const DecimateOptions& options);
  ~SurfaceDecimator();
  SurfaceDecimator(const SurfaceDecimator&) = delete;
  SurfaceDecimator& operator=(const SurfaceDecimator&) = delete;

  // Throws RigBuildError when target_vertices < 4 or exceeds the previous target.
  DecimationResult decimateTo(std::int32_t target_vertices);

 private:
  struct State;
  std::unique_ptr<State> state_;
};

// Aspect ratio of a triangle as the guard measures it: longest edge^2 / (2 area) (1.155 when
// equilateral, infinite when degenerate).
double triangleAspect(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c);

}  // namespace tetrig::rigbuild
