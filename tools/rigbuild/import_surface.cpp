// Surface import through the Open Asset Import Library (assimp): the scene's meshes are
// triangulated, pre-transformed by their node transforms and concatenated; only positions and
// triangles are kept. assimp emits one vertex per face corner for OBJ, OFF and PLY and loses the
// file's vertex indices, so for those formats every corner is matched back to the file's own
// vertex list (readFileVertexList) by position, and the file's list, in file order, becomes the
// vertex array. Then positions closer than the weld tolerance are welded (weldVertices, the
// earliest vertex wins), which also joins the per-corner vertices of formats without a shared
// list (STL) and the seam splits of others (glTF, FBX).
#include "tetrig/rigbuild/import_surface.hpp"

#include "tetrig/rigbuild/cell_key.hpp"
#include "tetrig/rigbuild/file_vertex_list.hpp"
#include "tetrig/rigbuild/weld_vertices.hpp"

#include <assimp/Importer.hpp>
#include <assimp/postprocess.h>
#include <assimp/scene.h>

#include <algorithm>
#include <bit>
#include <cfloat>
#include <cmath>
#include <limits>
#include <optional>
#include <string>
#include <system_error>
#include <unordered_map>

namespace tetrig::rigbuild {
namespace {

// assimp keeps single precision: a file vertex is found by its coordinates rounded to float
// (-0 and +0 alike).
CellKey floatKey(const Eigen::RowVector3d& p) {
  auto bits = [](double x) -> std::int64_t { return std::bit_cast<std::uint32_t>(static_cast<float>(x) + 0.0f); };
  return CellKey{bits(p[0]), bits(p[1]), bits(p[2])};
}

// For each imported (assimp) vertex, the file vertex at its position: the earliest file vertex with
// the same float-rounded coordinates, else (importers may round the last bits differently) the
// nearest file vertex within 1e-6 of the diagonal plus a few float ulps. nullopt when a vertex
// has no file vertex there (then the file's order cannot be trusted: the caller keeps assimp's).
std::optional<std::vector<std::int32_t>> matchFileVertices(const Vertices& imported, const Vertices& file) {
  std::unordered_map<CellKey, std::int32_t, CellHash> exact;
  exact.reserve(static_cast<std::size_t>(file.rows()));
  for (Eigen::Index i = 0; i < file.rows(); ++i) {
    if (!file.row(i).allFinite()) return std::nullopt;
    exact.emplace(floatKey(file.row(i)), static_cast<std::int32_t>(i));
  }
  const double tolerance = 1e-6 * boundingBoxDiagonal(file) + 8.0 * FLT_EPSILON * file.cwiseAbs().maxCoeff();
  std::unordered_map<CellKey, std::vector<std::int32_t>, CellHash> grid;  // built on the first miss
  auto cellOf = [tolerance](const Eigen::RowVector3d& p) {
    auto cell = [tolerance](double x) { return static_cast<std::int64_t>(std::floor(x / tolerance)); };
    return CellKey{cell(p[0]), cell(p[1]), cell(p[2])};
  };
  std::vector<std::int32_t> out(static_cast<std::size_t>(imported.rows()), -1);
  for (Eigen::Index v = 0; v < imported.rows(); ++v) {
    const Eigen::RowVector3d p = imported.row(v);
    if (const auto it = exact.find(floatKey(p)); it != exact.end()) {
      out[static_cast<std::size_t>(v)] = it->second;
      continue;
    }
    if (!(tolerance > 0.0) || !p.allFinite()) return std::nullopt;
    if (grid.empty()) {
      for (Eigen::Index i = 0; i < file.rows(); ++i) grid[cellOf(file.row(i))].push_back(static_cast<std::int32_t>(i));
    }
    const CellKey home = cellOf(p);
    std::int32_t best = -1;
    double best_d = tolerance;
    for (std::int64_t dx = -1; dx <= 1; ++dx) {
      for (std::int64_t dy = -1; dy <= 1; ++dy) {
        for (std::int64_t dz = -1; dz <= 1; ++dz) {
          const auto it = grid.find(CellKey{home.x + dx, home.y + dy, home.z + dz});
          if (it == grid.end()) continue;
          for (const std::int32_t i : it->second) {  // ascending: ties go to the earliest
            const double d = (file.row(i) - p).norm();
            if (d < best_d || (d == best_d && best < 0)) {
              best_d = d;
              best = i;
            }
          }
        }
      }
    }
    if (best < 0) return std::nullopt;
    out[static_cast<std::size_t>(v)] = best;
  }
  return out;
}

}  // namespace

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
