// Surface mesh import through assimp (OBJ, PLY, OFF, STL, glTF/GLB, FBX, ... whatever the
// installed assimp reads), reduced to positions and triangles with duplicate vertices welded.
//
// Vertex order. Formats with a shared vertex list (OBJ "v" lines, OFF, PLY) keep the FILE's
// order: imported vertex i is file vertex i, at the file's own (double) coordinates, so a rig's
// fine mesh maps back to the asset vertex by vertex. The exceptions, all reported in ImportStats
// and by validateSurface:
//   - a file vertex at exactly (or within weld_tolerance of) the position of an EARLIER one is
//     merged into the earlier one (faces are re-pointed, it disappears, later ids shift down by one);
//   - vertices no face uses stay in the import but validateSurface removes them (later ids shift);
//   - validateSurface's other repairs (keep_largest_component) may remove more.
// ImportStats::file_to_vertex and SurfaceReport::vertex_map give the exact mapping in every case.
// Other formats (STL, glTF, FBX, ...) get assimp's order with seams welded (first use wins).
//
// Hostile files. A mesh file is input from anyone and assimp trusts it, so: the extension must be
// one assimp reads (its signature guessing for unknown extensions is not used); OFF, PLY, OBJ and
// STL files are read once, checked (checkSurfaceFile: counts against the data, indices, face
// sizes; check_surface_file.hpp) and then parsed by assimp from those same bytes in memory; and
// assimp runs in a child process (runInChildProcess) with a memory and a CPU-time limit, so
// that whatever the check cannot foresee in any format (a crash, an abort, a runaway allocation
// or loop) ends as a RigBuildError, never as a crash of the tool.
//
// Offline, any thread, allocates, throws RigBuildError (file missing, unreadable, refused by the
// check, refused or crashed importer, limits exceeded, no triangles).
#pragma once

#include "tetrig/rigbuild/check_surface_file.hpp"
#include "tetrig/rigbuild/surface_mesh.hpp"

#include <cstdint>
#include <filesystem>
#include <vector>

namespace tetrig::rigbuild {

struct ImportOptions {
  // Vertices closer than weld_tolerance * (bounding-box diagonal) are merged into one (the first
  // one seen keeps its position). 0 merges only bit-identical positions.
  double weld_tolerance = 1e-7;
  // Limits of the pre-import check of OFF, PLY, OBJ and STL files (face size, triangulation work).
  SurfaceFileLimits file_limits;
  // true: assimp runs in a child process with the limits below. false: in this process (for the
  // fuzz target, which must see a crash as a crash; never for files from users).
  bool isolate = true;
  // The child's memory beyond what it inherits, bytes; 0: 2 GiB + 32 x the file size (the file
  // itself: a glTF's external buffers count against the 2 GiB).
  std::uint64_t memory_limit_bytes = 0;
  // The child's CPU time, seconds; 0: 30 s + 2 s per MB of file.
  std::uint64_t cpu_limit_seconds = 0;
};

struct ImportStats {
  bool file_order = false;             // true: vertex i (before welding) is the file's vertex i (see above)
  std::int32_t file_vertices = 0;      // the file's vertex list when file_order, else assimp's vertices (unwelded)
  std::int32_t file_triangles = 0;     // triangles after assimp's triangulation
  std::int32_t skipped_primitives = 0; // points and lines, ignored
  std::int32_t meshes = 0;             // meshes in the scene (all are concatenated, node transforms applied)
  std::int32_t welded_vertices = 0;    // file_vertices - vertices after welding
  std::int32_t unreferenced_vertices = 0;  // file_order only: vertices no face uses after welding (kept; validateSurface removes them)
  // file_vertices entries: the imported vertex each file vertex (file_order) or each assimp vertex
  // became after welding.
  std::vector<std::int32_t> file_to_vertex;
};

// Reads `path`; every mesh of the scene is transformed by its node's transform and concatenated.
// Result: #V by 3 positions (double, file units) and #F by 3 triangles; nothing is validated yet
// (see validateSurface). `stats` may be null.
SurfaceMesh importSurface(const std::filesystem::path& path, const ImportOptions& options = {},
                          ImportStats* stats = nullptr);

}  // namespace tetrig::rigbuild
