// Readers for tetrahedral mesh files.
//
// - TetGen: NAME.node + NAME.ele, 0- or 1-based (taken from the first index in .node), optional
//   attributes and boundary markers, '#' comments. Tets with 10 nodes keep the first four.
// - MEDIT: .mesh (ASCII) with Vertices and Tetrahedra sections; other sections (Edges,
//   Triangles, Corners, Ridges, ...) are skipped.
//
// Errors throw tetrig::MeshFileError whose what() names the file, the line and what was
// expected, e.g. "octopus.mesh:1203: expected 4 vertex indices and a reference, found 3 tokens".
// Offline/load-time code: these functions allocate and may throw; never call them per frame.
#pragma once

#include "tetrig/tet_mesh.hpp"

#include <filesystem>
#include <stdexcept>
#include <string>

namespace tetrig {

class MeshFileError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Reads NAME.node and NAME.ele; `path` may name either file or the common stem.
TetMesh readTetGen(const std::filesystem::path& path);

// Reads a MEDIT .mesh file.
TetMesh readMedit(const std::filesystem::path& path);

// Dispatches on the extension (.node/.ele -> TetGen, .mesh -> MEDIT).
TetMesh readTetMesh(const std::filesystem::path& path);

// Parses in-memory text (used by tests and fuzzing; `name` appears in messages).
TetMesh parseTetGen(const std::string& node_text, const std::string& ele_text, const std::string& name);
TetMesh parseMedit(const std::string& text, const std::string& name);

}  // namespace tetrig
