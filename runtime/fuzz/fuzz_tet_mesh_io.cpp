// libFuzzer target for the tet mesh readers' in-memory entry points (parseMedit, parseTetGen).
// Input: first byte selects the format (even: MEDIT, odd: TetGen); for TetGen the rest is split
// at the first '@' into the .node and the .ele text. Every input must either parse or throw
// MeshFileError; a parsed mesh must have in-range indices and finite vertices.
#include "tetrig/tet_mesh.hpp"
#include "tetrig/tet_mesh_io.hpp"

#include <cstddef>
#include <cstdint>
#include <string>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  const std::string text(reinterpret_cast<const char*>(data) + 1, size - 1);
  try {
    tetrig::TetMesh mesh;
    if (data[0] % 2 == 0) {
      mesh = tetrig::parseMedit(text, "fuzz.mesh");
    } else {
      const size_t split = text.find('@');
      const std::string node = text.substr(0, split);
      const std::string ele = split == std::string::npos ? std::string() : text.substr(split + 1);
      mesh = tetrig::parseTetGen(node, ele, "fuzz");
    }
    const tetrig::TetMeshReport report = tetrig::checkTetMesh(mesh);
    if (report.out_of_range_indices != 0 || report.non_finite_vertices != 0) __builtin_trap();
  } catch (const tetrig::MeshFileError&) {
  }
  return 0;
}
