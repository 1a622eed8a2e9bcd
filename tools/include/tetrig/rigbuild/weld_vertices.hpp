// Welding of duplicate vertices: vertices within a distance tolerance become one.
//
// Offline, any thread, allocates, does not throw.
#pragma once

#include "tetrig/rigbuild/surface_mesh.hpp"

#include <cstdint>
#include <vector>

namespace tetrig::rigbuild {

// Merges vertices closer than `tolerance` (absolute, mesh units; 0 = identical positions only),
// rewrites the triangles and removes the merged-away vertices; the survivors keep their relative
// order and the first vertex of each cluster keeps its position. Returns, for each input vertex,
// its new index (#V_in entries). Vertices that no triangle references are kept (validateSurface
// removes those). Cost: O(#V) expected, with a hash grid of cell size `tolerance`.
std::vector<std::int32_t> weldVertices(SurfaceMesh& mesh, double tolerance);

}  // namespace tetrig::rigbuild
