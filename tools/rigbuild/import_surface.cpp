// Surface import through the Open Asset Import Library (assimp): the scene's meshes are
// triangulated, pre-transformed by their node transforms and concatenated; only positions and
// triangles are kept. assimp emits one vertex per face corner for OBJ, OFF and PLY and loses the
// file's vertex indices, so for those formats every corner is matched back to the file's own
// vertex list (readFileVertexList) by position (matchFileVertices), and the file's list, in file
// order, becomes the vertex array. Then positions closer than the weld tolerance are welded
// (weldVertices, the earliest vertex wins), which also joins the per-corner vertices of formats
// without a shared list (STL) and the seam splits of others (glTF, FBX).
#include "tetrig/rigbuild/import_surface.hpp"

#include "tetrig/rigbuild/file_vertex_list.hpp"
#include "tetrig/rigbuild/match_file_vertices.hpp"
#include "tetrig/rigbuild/weld_vertices.hpp"

#include <assimp/Importer.hpp>
#include <assimp/postprocess.h>
#include <assimp/scene.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <string>
#include <system_error>

namespace tetrig::rigbuild {

SurfaceMesh importSurface(const std::filesystem::path& path, const ImportOptions& options, ImportStats* stats) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) {
    throw RigBuildError(path.string() + ": no such file (check the path)");
  }
  Assimp::Importer importer;
  // Normals, colours, UVs etc. are not needed: ask assimp to drop them so it does less work.
  importer.SetPropertyInteger(AI_CONFIG_PP_RVC_FLAGS, aiComponent_NORMALS | aiComponent_TANGENTS_AND_BITANGENTS |
                                                          aiComponent_COLORS | aiComponent_TEXCOORDS |
                                                          aiComponent_BONEWEIGHTS | aiComponent_ANIMATIONS |
                                                          aiComponent_TEXTURES | aiComponent_LIGHTS |
                                                          aiComponent_CAMERAS | aiComponent_MATERIALS);
  const unsigned flags = aiProcess_RemoveComponent | aiProcess_Triangulate | aiProcess_PreTransformVertices |
                         aiProcess_SortByPType;
  const aiScene* scene = importer.ReadFile(path.string(), flags);
  if (scene == nullptr) {
    throw RigBuildError(path.string() + ": cannot import: " + importer.GetErrorString() +
                        " (supported: OBJ, PLY, OFF, STL, glTF/GLB and the other formats assimp reads)");
  }
  ImportStats local;
  size_t vertex_total = 0;
  size_t triangle_total = 0;
  for (unsigned m = 0; m < scene->mNumMeshes; ++m) {
    const aiMesh* mesh = scene->mMeshes[m];
    if (mesh == nullptr) continue;
    ++local.meshes;
    for (unsigned f = 0; f < mesh->mNumFaces; ++f) {
      if (mesh->mFaces[f].mNumIndices == 3) {
        ++triangle_total;
      } else {
        ++local.skipped_primitives;
      }
    }
    if (mesh->mPrimitiveTypes & aiPrimitiveType_TRIANGLE) vertex_total += mesh->mNumVertices;
  }
  if (triangle_total == 0) {
    throw RigBuildError(path.string() + ": the file contains no triangles (" + std::to_string(local.meshes) +
                        " meshes, " + std::to_string(local.skipped_primitives) +
                        " points/lines): export the character as a triangle or polygon surface");
  }
  if (vertex_total > static_cast<size_t>(std::numeric_limits<std::int32_t>::max()) ||
      triangle_total > static_cast<size_t>(std::numeric_limits<std::int32_t>::max())) {
    throw RigBuildError(path.string() + ": too many vertices or triangles for 32-bit indices");
  }

  SurfaceMesh out;
  out.vertices.resize(static_cast<Eigen::Index>(vertex_total), 3);
  out.triangles.resize(static_cast<Eigen::Index>(triangle_total), 3);
  Eigen::Index v_base = 0;
  Eigen::Index t = 0;
  for (unsigned m = 0; m < scene->mNumMeshes; ++m) {
    const aiMesh* mesh = scene->mMeshes[m];
    if (mesh == nullptr || !(mesh->mPrimitiveTypes & aiPrimitiveType_TRIANGLE)) continue;
    for (unsigned v = 0; v < mesh->mNumVertices; ++v) {
      const aiVector3D& p = mesh->mVertices[v];
      out.vertices.row(v_base + v) << static_cast<double>(p.x), static_cast<double>(p.y), static_cast<double>(p.z);
    }
    for (unsigned f = 0; f < mesh->mNumFaces; ++f) {
      const aiFace& face = mesh->mFaces[f];
      if (face.mNumIndices != 3) continue;
      for (int k = 0; k < 3; ++k) {
        if (face.mIndices[k] >= mesh->mNumVertices) {
          throw RigBuildError(path.string() + ": face " + std::to_string(f) + " of mesh " + std::to_string(m) +
                              " references vertex " + std::to_string(face.mIndices[k]) + " of " +
                              std::to_string(mesh->mNumVertices) + ": the file is corrupt");
        }
        out.triangles(t, k) = static_cast<std::int32_t>(v_base + face.mIndices[k]);
      }
      ++t;
    }
    v_base += mesh->mNumVertices;
  }
  local.file_vertices = static_cast<std::int32_t>(vertex_total);
  local.file_triangles = static_cast<std::int32_t>(triangle_total);
  // The file's own vertex list and order, where the format has one.
  if (std::optional<Vertices> file = readFileVertexList(path); file && file->rows() > 0 && file->rows() <= std::numeric_limits<std::int32_t>::max()) {
    if (const auto to_file = matchFileVertices(out.vertices, *file)) {
      for (Eigen::Index f = 0; f < out.triangles.rows(); ++f) {
        for (int k = 0; k < 3; ++k) out.triangles(f, k) = (*to_file)[static_cast<std::size_t>(out.triangles(f, k))];
      }
      out.vertices = std::move(*file);
      local.file_order = true;
      local.file_vertices = out.vertexCount();
    }
  }
  const double diagonal = boundingBoxDiagonal(out.vertices);
  local.file_to_vertex = weldVertices(out, std::isfinite(diagonal) ? options.weld_tolerance * diagonal : 0.0);
  local.welded_vertices = local.file_vertices - out.vertexCount();
  if (local.file_order) {
    std::vector<char> used(static_cast<std::size_t>(out.vertexCount()), 0);
    for (Eigen::Index f = 0; f < out.triangles.rows(); ++f) {
      for (int k = 0; k < 3; ++k) used[static_cast<std::size_t>(out.triangles(f, k))] = 1;
    }
    local.unreferenced_vertices = static_cast<std::int32_t>(std::count(used.begin(), used.end(), 0));
  }
  if (stats != nullptr) *stats = local;
  return out;
}

}  // namespace tetrig::rigbuild
