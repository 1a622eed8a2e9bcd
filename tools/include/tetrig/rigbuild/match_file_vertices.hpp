// Matching of imported (assimp) vertices back to a mesh file's own vertex list, by position:
// importSurface uses it to restore the file's vertex order, which assimp loses (it emits one
// vertex per face corner for OBJ, OFF and PLY).
//
// Offline, any thread, allocates, does not throw (except std::bad_alloc).
#pragma once

#include "tetrig/tet_mesh.hpp"

#include <cstdint>
#include <optional>
#include <vector>

namespace tetrig::rigbuild {

// `imported`: #I by 3 positions (assimp's, single precision widened to double); `file`: #F by 3
// positions in file order (readFileVertexList), same units. Both are only read; the caller keeps
// them. Returns #I file indices, entry v = the file vertex at imported vertex v:
//  - the earliest file vertex whose coordinates, rounded to float, equal v's rounded to float
//    (-0 and +0 alike), else
//  - the nearest file vertex within tolerance = 1e-6 * bounding-box diagonal of `file`
//    + 8 * FLT_EPSILON * max |coordinate of `file`| (Euclidean distance <= tolerance; of equally
//    near ones the lowest index). Importers may round the last bits differently.
// nullopt when any file vertex is non-finite, when some imported vertex has no file vertex within
// tolerance (then the file's order cannot be trusted and the caller keeps the importer's), or
// when #F exceeds the int32 range. An empty `imported` gives an empty vector.
// Cost: O(#F) expected for the hash of float keys; on the first miss a nanoflann k-d tree over
// `file` is built (O(#F log #F)) and each miss costs one radius query.
std::optional<std::vector<std::int32_t>> matchFileVertices(const Vertices& imported, const Vertices& file);

}  // namespace tetrig::rigbuild
