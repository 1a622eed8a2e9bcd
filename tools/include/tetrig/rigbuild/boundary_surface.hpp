// Boundary surface of a tetrahedral mesh: the faces that belong to exactly one tet, oriented
// outward (for positively oriented tets). Offline, any thread, allocates, does not throw.
#pragma once

#include "tetrig/tet_mesh.hpp"

namespace tetrig::rigbuild {

// #B by 3 faces, counter-clockwise seen from outside, vertex indices of `mesh`.
Triangles boundaryFaces(const TetMesh& mesh);

}  // namespace tetrig::rigbuild
