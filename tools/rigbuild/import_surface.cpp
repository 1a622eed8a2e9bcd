// Surface import through the Open Asset Import Library (assimp): the scene's meshes are
// triangulated, pre-transformed by their node transforms and concatenated; only positions and
// triangles are kept. assimp emits one vertex per face corner for OBJ, OFF and PLY and loses the
// file's vertex indices, so for those formats every corner is matched back to the file's own
// vertex list (readFileVertexList) by position (matchFileVertices), and the file's list, in file
// order, becomes the vertex array. Then positions closer than the weld tolerance are welded
// (weldVertices, the earliest vertex wins), which also joins the per-corner vertices of formats
// without a shared list (STL) and the seam splits of others (glTF, FBX).
//
// Hostile input: OFF, PLY, OBJ and STL are read into memory once and checked (checkSurfaceBytes);
// assimp then parses those bytes (ReadFileFromMemory), in a child process with memory and CPU
// limits (runInChildProcess), which sends the triangles back through a pipe.
#include "tetrig/rigbuild/import_surface.hpp"

#include "tetrig/printable_text.hpp"
#include "tetrig/rigbuild/file_vertex_list.hpp"
#include "tetrig/rigbuild/match_file_vertices.hpp"
#include "tetrig/rigbuild/run_in_child_process.hpp"
#include "tetrig/rigbuild/weld_vertices.hpp"

#include <assimp/Importer.hpp>
#include <assimp/postprocess.h>
#include <assimp/scene.h>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <limits>
#include <optional>
#include <string>
#include <system_error>

namespace tetrig::rigbuild {
namespace {

// The triangles of every mesh of assimp's scene, concatenated (assimp's vertex order).
struct AssimpMesh {
  SurfaceMesh mesh;
  std::int32_t meshes = 0;
  std::int32_t skipped_primitives = 0;
};

// Runs assimp on `bytes` (the checked formats; `hint` is the extension without its dot) or, when
// `bytes` is null, on the file itself. Throws RigBuildError.
AssimpMesh readWithAssimp(const std::filesystem::path& path, const std::string* bytes, const std::string& hint) {
  Assimp::Importer importer;
  // Normals, colours, UVs etc. are not needed: ask assimp to drop them so it does less work.
  importer.SetPropertyInteger(AI_CONFIG_PP_RVC_FLAGS, aiComponent_NORMALS | aiComponent_TANGENTS_AND_BITANGENTS |
                                                          aiComponent_COLORS | aiComponent_TEXCOORDS |
                                                          aiComponent_BONEWEIGHTS | aiComponent_ANIMATIONS |
                                                          aiComponent_TEXTURES | aiComponent_LIGHTS |
                                                          aiComponent_CAMERAS | aiComponent_MATERIALS);
  const unsigned flags = aiProcess_RemoveComponent | aiProcess_Triangulate | aiProcess_PreTransformVertices |
                         aiProcess_SortByPType;
  const aiScene* scene = bytes != nullptr ? importer.ReadFileFromMemory(bytes->data(), bytes->size(), flags, hint.c_str())
                                          : importer.ReadFile(path.string(), flags);
  if (scene == nullptr) {
    // assimp's message may quote the file: escaped and cut short.
    throw RigBuildError(path.string() + ": cannot import: " + printableText(importer.GetErrorString(), 200) +
                        " (supported: OBJ, PLY, OFF, STL, glTF/GLB and the other formats assimp reads)");
  }
  AssimpMesh out;
  size_t vertex_total = 0;
  size_t triangle_total = 0;
  for (unsigned m = 0; m < scene->mNumMeshes; ++m) {
    const aiMesh* mesh = scene->mMeshes[m];
    if (mesh == nullptr) continue;
    ++out.meshes;
    for (unsigned f = 0; f < mesh->mNumFaces; ++f) {
      if (mesh->mFaces[f].mNumIndices == 3) {
        ++triangle_total;
      } else {
        ++out.skipped_primitives;
      }
    }
    if (mesh->mPrimitiveTypes & aiPrimitiveType_TRIANGLE) vertex_total += mesh->mNumVertices;
  }
  if (triangle_total == 0) {
    throw RigBuildError(path.string() + ": the file contains no triangles (" + std::to_string(out.meshes) +
                        " meshes, " + std::to_string(out.skipped_primitives) +
                        " points/lines): export the character as a triangle or polygon surface");
  }
  if (vertex_total > static_cast<size_t>(std::numeric_limits<std::int32_t>::max()) ||
      triangle_total > static_cast<size_t>(std::numeric_limits<std::int32_t>::max())) {
    throw RigBuildError(path.string() + ": too many vertices or triangles for 32-bit indices");
  }
  SurfaceMesh& m_out = out.mesh;
  m_out.vertices.resize(static_cast<Eigen::Index>(vertex_total), 3);
  m_out.triangles.resize(static_cast<Eigen::Index>(triangle_total), 3);
  Eigen::Index v_base = 0;
  Eigen::Index t = 0;
  for (unsigned m = 0; m < scene->mNumMeshes; ++m) {
    const aiMesh* mesh = scene->mMeshes[m];
    if (mesh == nullptr || !(mesh->mPrimitiveTypes & aiPrimitiveType_TRIANGLE)) continue;
    for (unsigned v = 0; v < mesh->mNumVertices; ++v) {
      const aiVector3D& p = mesh->mVertices[v];
      m_out.vertices.row(v_base + v) << static_cast<double>(p.x), static_cast<double>(p.y), static_cast<double>(p.z);
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
        m_out.triangles(t, k) = static_cast<std::int32_t>(v_base + face.mIndices[k]);
      }
      ++t;
    }
    v_base += mesh->mNumVertices;
  }
  return out;
}

// ---- the child's answer: "TIMP", status; then the error text or the mesh (host byte order:
// the same program reads it) ----

constexpr char kResultMagic[4] = {'T', 'I', 'M', 'P'};
struct ResultHead {
  char magic[4];
  std::int32_t status;        // 0: mesh follows; 1: error text follows
  std::int64_t a;             // status 0: vertices; 1: text bytes
  std::int64_t b;             // status 0: triangles
  std::int32_t meshes;
  std::int32_t skipped_primitives;
};

bool sendResult(int fd, const AssimpMesh* mesh, const std::string& error) {
  ResultHead head{};
  std::memcpy(head.magic, kResultMagic, 4);
  if (mesh == nullptr) {
    head.status = 1;
    head.a = static_cast<std::int64_t>(error.size());
    return writeAllToFd(fd, &head, sizeof head) && writeAllToFd(fd, error.data(), error.size());
  }
  head.a = mesh->mesh.vertices.rows();
  head.b = mesh->mesh.triangles.rows();
  head.meshes = mesh->meshes;
  head.skipped_primitives = mesh->skipped_primitives;
  return writeAllToFd(fd, &head, sizeof head) &&
         writeAllToFd(fd, mesh->mesh.vertices.data(), sizeof(double) * 3 * static_cast<std::size_t>(head.a)) &&
         writeAllToFd(fd, mesh->mesh.triangles.data(), sizeof(std::int32_t) * 3 * static_cast<std::size_t>(head.b));
}

AssimpMesh receiveResult(const std::vector<std::uint8_t>& bytes, const std::string& name) {
  const RigBuildError malformed(name + ": the import process returned a malformed result (an importer bug): check the file in a mesh editor and export it again");
  ResultHead head{};
  if (bytes.size() < sizeof head) throw malformed;
  std::memcpy(&head, bytes.data(), sizeof head);
  const std::size_t rest = bytes.size() - sizeof head;
  if (std::memcmp(head.magic, kResultMagic, 4) != 0) throw malformed;
  if (head.status == 1) {
    if (head.a < 0 || static_cast<std::uint64_t>(head.a) != rest) throw malformed;
    throw RigBuildError(std::string(reinterpret_cast<const char*>(bytes.data() + sizeof head), rest));
  }
  const std::int64_t limit = std::numeric_limits<std::int32_t>::max();
  if (head.status != 0 || head.a < 0 || head.b < 0 || head.a > limit || head.b > limit ||
      rest != 3 * (sizeof(double) * static_cast<std::uint64_t>(head.a) + sizeof(std::int32_t) * static_cast<std::uint64_t>(head.b))) {
    throw malformed;
  }
  AssimpMesh out;
  out.meshes = head.meshes;
  out.skipped_primitives = head.skipped_primitives;
  out.mesh.vertices.resize(static_cast<Eigen::Index>(head.a), 3);
  out.mesh.triangles.resize(static_cast<Eigen::Index>(head.b), 3);
  const std::uint8_t* p = bytes.data() + sizeof head;
  std::memcpy(out.mesh.vertices.data(), p, sizeof(double) * 3 * static_cast<std::size_t>(head.a));
  p += sizeof(double) * 3 * static_cast<std::size_t>(head.a);
  std::memcpy(out.mesh.triangles.data(), p, sizeof(std::int32_t) * 3 * static_cast<std::size_t>(head.b));
  for (Eigen::Index f = 0; f < out.mesh.triangles.rows(); ++f) {
    for (int k = 0; k < 3; ++k) {
      if (out.mesh.triangles(f, k) < 0 || out.mesh.triangles(f, k) >= out.mesh.vertices.rows()) throw malformed;
    }
  }
  return out;
}

// The whole file, read once (the checked bytes are the ones assimp parses).
std::string readWholeFile(const std::filesystem::path& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) throw RigBuildError(path.string() + ": cannot open: " + std::strerror(errno));
  std::string bytes;
  struct stat st {};
  if (::fstat(fd, &st) == 0 && S_ISREG(st.st_mode)) bytes.reserve(static_cast<std::size_t>(st.st_size));
  char buffer[1 << 16];
  for (;;) {
    const ssize_t n = ::read(fd, buffer, sizeof buffer);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) {
      const int err = errno;
      ::close(fd);
      throw RigBuildError(path.string() + ": cannot read: " + std::strerror(err));
    }
    if (n == 0) break;
    bytes.append(buffer, static_cast<std::size_t>(n));
  }
  ::close(fd);
  return bytes;
}

}  // namespace

// Whether an OBJ's text has a face line ("f" followed by a blank, at the start of a line).
static bool objHasFaces(const std::string& text) {
  for (std::size_t at = 0; at < text.size();) {
    std::size_t i = at;
    while (i < text.size() && (text[i] == ' ' || text[i] == '\t')) ++i;
    if (i + 1 < text.size() && text[i] == 'f' && (text[i + 1] == ' ' || text[i + 1] == '\t')) return true;
    const std::size_t nl = text.find('\n', at);
    if (nl == std::string::npos) break;
    at = nl + 1;
  }
  return false;
}

SurfaceMesh importSurface(const std::filesystem::path& path, const ImportOptions& options, ImportStats* stats) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) {
    throw RigBuildError(path.string() + ": is a folder, not a mesh file (give an OBJ, PLY, OFF, STL, glTF or FBX file)");
  }
  if (!std::filesystem::is_regular_file(path, ec)) {
    throw RigBuildError(path.string() + ": no such file (check the path)");
  }
  const std::string ext = lowercaseExtension(path);
  const bool checked = ext == ".obj" || ext == ".off" || ext == ".ply" || ext == ".stl";
  // assimp guesses the format of a file with an unknown extension from its content, with every
  // importer it has: not for files from anyone.
  if (!checked && (ext.size() < 2 || !Assimp::Importer().IsExtensionSupported(ext))) {
    throw RigBuildError(path.string() + ": " + (ext.empty() ? std::string("no file extension") : "unknown mesh file extension '" + printableText(ext, 40) + "'") +
                        ": give the file the extension of its format (OBJ, PLY, OFF, STL, glTF/GLB, FBX or another that assimp reads)");
  }
  std::optional<std::string> bytes;
  if (std::filesystem::file_size(path, ec) == 0 && !ec) {
    throw RigBuildError(path.string() + ": the file is empty (0 bytes): give the character's surface mesh (OBJ, PLY, OFF, STL, glTF/GLB, FBX)");
  }
  if (checked) {
    bytes = readWholeFile(path);
    (void)checkSurfaceBytes(*bytes, ext, path.string(), options.file_limits);
    if (ext == ".obj" && !objHasFaces(*bytes)) {
      throw RigBuildError(path.string() + ": the OBJ has no faces (no 'f' lines): it is a point cloud or a curve; give a surface mesh");
    }
  }
  const std::string hint = ext.substr(1);
  AssimpMesh raw;
  if (!options.isolate) {
    raw = readWithAssimp(path, bytes ? &*bytes : nullptr, hint);
  } else {
    std::uint64_t file_bytes = bytes ? bytes->size() : static_cast<std::uint64_t>(std::filesystem::file_size(path, ec));
    if (!bytes && ec) file_bytes = 0;
    ChildLimits limits;
    limits.memory_bytes = options.memory_limit_bytes != 0 ? options.memory_limit_bytes : (std::uint64_t{2} << 30) + 32 * file_bytes;
    limits.cpu_seconds = options.cpu_limit_seconds != 0 ? options.cpu_limit_seconds : 30 + 2 * (file_bytes >> 20);
    const ChildOutcome outcome = runInChildProcess([&](int fd) {
      try {
        const AssimpMesh m = readWithAssimp(path, bytes ? &*bytes : nullptr, hint);
        return sendResult(fd, &m, {});
      } catch (const std::exception& e) {
        std::string what = e.what();
        if (what.find("bad_alloc") != std::string::npos) {
          what = path.string() + ": the import needs more memory than its limit of " + std::to_string(limits.memory_bytes >> 20) +
                 " MB (" + what + "): the file is corrupt or far larger than a character mesh";
        }
        return sendResult(fd, nullptr, what);
      }
    }, limits);
    if (!outcome.ok()) {
      throw RigBuildError(path.string() + ": the importer (assimp) " + outcome.describe() +
                          (outcome.signal_number != 0 && !outcome.exited ? " while reading the file" : std::string()) +
                          " (limits: " + std::to_string(limits.memory_bytes >> 20) + " MB, " + std::to_string(limits.cpu_seconds) +
                          " s of CPU): the file is corrupt or uses a feature the importer mishandles; open it in a mesh editor "
                          "(e.g. Blender or MeshLab) and export it again");
    }
    raw = receiveResult(outcome.output, path.string());
  }
  SurfaceMesh out = std::move(raw.mesh);
  ImportStats local;
  local.meshes = raw.meshes;
  local.skipped_primitives = raw.skipped_primitives;
  local.file_vertices = out.vertexCount();
  local.file_triangles = out.triangleCount();
  // The file's own vertex list and order, where the format has one.
  if (std::optional<Vertices> file = bytes ? readFileVertexList(*bytes, ext) : std::nullopt;
      file && file->rows() > 0 && file->rows() <= std::numeric_limits<std::int32_t>::max()) {
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
