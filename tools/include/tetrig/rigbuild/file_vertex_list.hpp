// The shared vertex list of a mesh file, in file order: OBJ ("v x y z" lines), OFF (with its
// C/N/ST prefixes) and PLY (ascii, binary little/big endian; the x, y, z properties of element
// "vertex"). importSurface uses it to give the imported surface the file's vertex order (assimp
// emits one vertex per face corner and loses the file's indices).
//
// Offline, any thread, allocates, does not throw (an unreadable or unsupported file gives nullopt).
#pragma once

#include "tetrig/tet_mesh.hpp"

#include <filesystem>
#include <optional>
#include <string_view>

namespace tetrig::rigbuild {

// #V by 3 positions exactly as written in the file (double; float PLY properties widened), vertex
// i = the file's i-th vertex, referenced or not. nullopt for any other format (by extension:
// .obj, .off, .ply, case-insensitive) and for files this small reader cannot parse (then the
// caller keeps the importer's order).
std::optional<Vertices> readFileVertexList(const std::filesystem::path& path);

// The same on the file's bytes in memory; `extension` is lower case with its dot (".off").
std::optional<Vertices> readFileVertexList(std::string_view bytes, std::string_view extension);

}  // namespace tetrig::rigbuild
