// Surface mesh import through assimp (OBJ, PLY, OFF, STL, glTF/GLB, FBX, ... whatever the
// installed assimp reads), reduced to positions and triangles with duplicate vertices welded.
//
// Offline, any thread, allocates, throws RigBuildError (file missing, unreadable, no triangles).
#pragma once

#include "tetrig/rigbuild/surface_mesh.hpp"

#include <cstdint>
#include <filesystem>

namespace tetrig::rigbuild {

struct ImportOptions {
  // Vertices closer than weld_tolerance * (bounding-box diagonal) are merged into one (the first
  // one seen keeps its position). 0 merges only bit-identical positions.
  double weld_tolerance = 1e-7;
};

struct ImportStats {
  std::int32_t file_vertices = 0;      // vertices as assimp delivered them (all meshes, unwelded)
  std::int32_t file_triangles = 0;     // triangles after assimp's triangulation
  std::int32_t skipped_primitives = 0; // points and lines, ignored
  std::int32_t meshes = 0;             // meshes in the scene (all are concatenated, node transforms applied)
  std::int32_t welded_vertices = 0;    // file_vertices - vertices after welding
};

// Reads `path`; every mesh of the scene is transformed by its node's transform and concatenated.
// Result: #V by 3 positions (double, file units) and #F by 3 triangles; nothing is validated yet
// (see validateSurface). `stats` may be null.
SurfaceMesh importSurface(const std::filesystem::path& path, const ImportOptions& options = {},
                          ImportStats* stats = nullptr);

}  // namespace tetrig::rigbuild
