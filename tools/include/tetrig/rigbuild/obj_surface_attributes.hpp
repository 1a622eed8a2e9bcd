// The texture coordinates and materials of a Wavefront OBJ asset, carried onto the rig's fine mesh
// (Rig::surface, the rig file's UVMT section; docs/rig-format.md "Texture coordinates and
// materials"). assimp gives one uv per vertex after splitting vertices at uv seams, which the
// fine mesh (the file's vertex list) does not do, so the builder reads the OBJ's own `vt`,
// `f v/vt/vn`, `usemtl` and `mtllib` lines here, in file order, and its .mtl files (`newmtl`,
// `Kd`, `map_Kd`). Other formats carry no texture coordinates into the rig.
//
// Offline, any thread, allocates; the readers never throw on a malformed file (they give up:
// nullopt, or an entry left out).
#pragma once

#include "tetrig/rig_file.hpp"

#include <Eigen/Core>

#include <array>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace tetrig::rigbuild {

// One `f` line of the file.
struct ObjFace {
  std::int32_t first_corner = 0;  // into ObjSurfaceData::corner_vertex and corner_uv
  std::int32_t corners = 0;       // 3 or more
  std::int32_t material = -1;     // into ObjSurfaceData::materials; -1 before the first `usemtl`
};

struct ObjSurfaceData {
  std::int32_t vertices = 0;                     // `v` lines
  std::vector<std::array<double, 2>> uvs;        // `vt` lines in file order (u, v; a missing v is 0, w is dropped)
  std::vector<std::int32_t> corner_vertex;       // per face corner: 0-based file vertex
  std::vector<std::int32_t> corner_uv;           // per face corner: 0-based `vt`, -1 when the corner has none
  std::vector<ObjFace> faces;                    // the faces of 3 or more corners, in file order
  std::vector<std::string> material_libraries;   // `mtllib` files as written, in order, each once
  std::vector<std::string> materials;            // `usemtl` names in order of first use
};

// Parses the OBJ text (negative, relative indices resolved; `\` line continuations joined; lines
// other than v, vt, f, usemtl and mtllib ignored). nullopt, with *why, when an `f` index is zero,
// malformed or out of range, or a `vt` has no number.
std::optional<ObjSurfaceData> readObjSurfaceData(std::string_view text, std::string* why = nullptr);

// One `newmtl` of a .mtl file: its Kd (when given as three numbers) and map_Kd (the file name as
// written, options such as `-s 1 1 1` skipped, backslashes turned into slashes).
struct MtlMaterial {
  std::string name;
  std::optional<Eigen::Vector3d> diffuse_color;
  std::string diffuse_texture;
};
std::vector<MtlMaterial> readMtl(std::string_view text);

// Rig::surface for a fine mesh imported from the OBJ file `path`: `file_to_fine` maps each file
// vertex to its fine vertex (-1: removed). Each fine triangle is matched to the file face holding
// its three vertices (the first in file order); each corner takes that face's `vt` at that vertex
// and the triangle the face's material. The fine triangles are then put in the file's face order
// (stable: triangles of one face keep their order), in place, so exports list faces as the asset
// does, whatever order the importer and the surface repair left them in. A `mtllib` line names
// files separated by blanks (or one file whose name has blanks, when that file exists); materials
// take Kd and map_Kd from the first of them naming them (map_Kd made relative to the OBJ's
// folder). nullopt when the file has neither `vt` nor `usemtl` lines, cannot be read or parsed, or
// some fine triangle matches no face (then `fine_triangles` is unchanged). `note` (may be null)
// receives one line for the build summary: what was kept, or why nothing was.
std::optional<RigSurfaceAttributes> objSurfaceAttributes(const std::filesystem::path& path, std::span<const std::int32_t> file_to_fine,
                                                         Triangles& fine_triangles, std::string* note = nullptr);

}  // namespace tetrig::rigbuild
