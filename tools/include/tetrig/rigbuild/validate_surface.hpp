// Validation and safe repair of a surface mesh before it becomes a tetrahedral rig.
//
// The rig builder needs ONE closed, 2-manifold, consistently oriented surface (TetGen's
// face-constrained tetrahedralization and the pose-transfer weights rely on it).
//
//   fixed (safe, reported):   duplicate vertices (welded), faces with a repeated corner (removed),
//                             duplicate faces (removed), unreferenced vertices (removed),
//                             inconsistent face orientation (re-oriented by flood fill),
//                             inward orientation (all faces flipped so the volume is positive),
//                             several components (only with keep_largest_component: the others
//                             are dropped).
//   refused (RigBuildError with what to do): non-finite coordinates, boundary edges (holes),
//                             non-manifold edges or vertices, non-orientable surfaces, several
//                             components (by default), zero enclosed volume, fewer than 4 vertices.
//   reported only:            zero-area faces with three distinct corners (slivers; decimation
//                             usually removes them, TetGen refuses what remains).
//   not checked:              self-intersections (TetGen reports them).
//
// Offline, any thread, allocates.
#pragma once

#include "tetrig/rigbuild/surface_mesh.hpp"

#include <cstdint>
#include <string>
#include <vector>

namespace tetrig::rigbuild {

struct ValidateOptions {
  double weld_tolerance = 1e-7;         // relative to the bounding-box diagonal (see weldVertices)
  double zero_area_tolerance = 1e-12;   // face area <= this * diagonal^2 counts as zero
  bool keep_largest_component = false;  // drop all but the component with the most faces
};

struct SurfaceReport {
  // Input as received.
  std::int32_t input_vertices = 0;
  std::int32_t input_triangles = 0;
  // Repairs made.
  std::int32_t welded_vertices = 0;
  std::int32_t removed_degenerate_faces = 0;  // a corner repeated (after welding)
  std::int32_t removed_duplicate_faces = 0;   // same three corners as an earlier face
  std::int32_t removed_unused_vertices = 0;
  std::int32_t reoriented_faces = 0;          // flipped to agree with their neighbours
  bool flipped_inside_out = false;            // all faces flipped: the volume was negative
  std::int32_t dropped_components = 0;        // with keep_largest_component
  std::int32_t dropped_component_faces = 0;
  // Found (the first three make the surface unusable).
  std::int32_t boundary_edges = 0;            // edges with one face: holes
  std::int32_t non_manifold_edges = 0;        // edges with three or more faces
  std::int32_t non_manifold_vertices = 0;     // vertices whose faces form several fans
  std::int32_t components = 0;
  std::int32_t zero_area_faces = 0;           // distinct corners but no area (kept)
  std::int32_t non_finite_vertices = 0;
  bool non_orientable = false;
  // Result.
  std::int32_t vertices = 0;
  std::int32_t triangles = 0;
  std::int32_t genus = -1;                    // from the Euler characteristic when closed
  double volume = 0.0;                        // signed, after repair
  double bbox_diagonal = 0.0;
  // input_vertices entries: the output vertex each input vertex became (welding, removal of unused
  // vertices and dropped components; survivors keep their relative order), -1 when removed.
  std::vector<std::int32_t> vertex_map;
  // One line per reason the surface is refused; empty when it is usable.
  std::vector<std::string> refusals;

  bool ok() const { return refusals.empty(); }
  std::string summary() const;   // one line with the counts and repairs
};

// Validates `mesh` and repairs it in place as described above; returns what was found and done.
// Never throws for a bad surface: check report.ok() or call requireUsableSurface.
SurfaceReport validateSurface(SurfaceMesh& mesh, const ValidateOptions& options = {});

// Throws RigBuildError naming `what` (e.g. the file name) and the refusal reasons when
// !report.ok(); does nothing otherwise.
void requireUsableSurface(const SurfaceReport& report, const std::string& what);

// Edge counts only (no repair): used to check decimation results.
struct SurfaceTopology {
  std::int32_t boundary_edges = 0;
  std::int32_t non_manifold_edges = 0;
  std::int32_t inconsistent_edges = 0;  // two faces traversing the edge in the same direction
  std::int32_t edges = 0;
  bool closedManifold() const { return boundary_edges == 0 && non_manifold_edges == 0 && inconsistent_edges == 0; }
};
SurfaceTopology surfaceTopology(const SurfaceMesh& mesh);

}  // namespace tetrig::rigbuild
