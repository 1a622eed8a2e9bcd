// Surface import (assimp + welding) and validation/repair of the rig builder.
#include "tetrig/rigbuild/file_vertex_list.hpp"
#include "tetrig/rigbuild/import_surface.hpp"
#include "tetrig/rigbuild/validate_surface.hpp"
#include "tetrig/rigbuild/weld_vertices.hpp"
#include "test_data.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cctype>
#include <cstdint>
#include <limits>
#include <cstring>
#include <filesystem>
#include <iterator>
#include <optional>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <unistd.h>

namespace tetrig::rigbuild {
namespace {

#define EXPECT_CONTAINS(haystack, needle) \
  EXPECT_NE(std::string(haystack).find(needle), std::string::npos) << "text: " << (haystack)

// Unit cube [0,1]^3; vertex index = x + 2y + 4z; quads counter-clockwise seen from outside.
const int kQuads[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4}, {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};

Eigen::RowVector3d corner(int v) { return {double(v & 1), double((v >> 1) & 1), double((v >> 2) & 1)}; }

SurfaceMesh cube(double offset_x = 0.0, double scale = 1.0) {
  SurfaceMesh m;
  m.vertices.resize(8, 3);
  for (int v = 0; v < 8; ++v) m.vertices.row(v) = corner(v) * scale + Eigen::RowVector3d(offset_x, 0, 0);
  m.triangles.resize(12, 3);
  for (int q = 0; q < 6; ++q) {
    m.triangles.row(2 * q) << kQuads[q][0], kQuads[q][1], kQuads[q][2];
    m.triangles.row(2 * q + 1) << kQuads[q][0], kQuads[q][2], kQuads[q][3];
  }
  return m;
}

SurfaceMesh concat(const SurfaceMesh& a, const SurfaceMesh& b) {
  SurfaceMesh m;
  m.vertices.resize(a.vertexCount() + b.vertexCount(), 3);
  m.vertices << a.vertices, b.vertices;
  m.triangles.resize(a.triangleCount() + b.triangleCount(), 3);
  m.triangles << a.triangles, (b.triangles.array() + a.vertexCount()).matrix();
  return m;
}

void addTriangle(SurfaceMesh& m, int a, int b, int c) {
  m.triangles.conservativeResize(m.triangleCount() + 1, 3);
  m.triangles.row(m.triangleCount() - 1) << a, b, c;
}

int addVertex(SurfaceMesh& m, const Eigen::RowVector3d& p) {
  m.vertices.conservativeResize(m.vertexCount() + 1, 3);
  m.vertices.row(m.vertexCount() - 1) = p;
  return m.vertexCount() - 1;
}

class TempDir {
 public:
  TempDir() : path_(std::filesystem::temp_directory_path() / ("tetrig_rigbuild_" + std::to_string(::getpid()))) {
    std::filesystem::create_directories(path_);
  }
  ~TempDir() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  std::filesystem::path write(const std::string& name, const std::string& text) const {
    std::ofstream(path_ / name, std::ios::binary) << text;
    return path_ / name;
  }

 private:
  std::filesystem::path path_;
};

std::string base64(const std::vector<unsigned char>& bytes) {
  static const char* kAlphabet = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  for (size_t i = 0; i < bytes.size(); i += 3) {
    const unsigned n = (unsigned(bytes[i]) << 16) | (i + 1 < bytes.size() ? unsigned(bytes[i + 1]) << 8 : 0u) |
                       (i + 2 < bytes.size() ? unsigned(bytes[i + 2]) : 0u);
    out += kAlphabet[(n >> 18) & 63];
    out += kAlphabet[(n >> 12) & 63];
    out += i + 1 < bytes.size() ? kAlphabet[(n >> 6) & 63] : '=';
    out += i + 2 < bytes.size() ? kAlphabet[n & 63] : '=';
  }
  return out;
}

// Imports `path`, validates it and checks it is the unit cube shifted by `offset_x`.
void expectUnitCube(const std::filesystem::path& path, double offset_x = 0.0) {
  SCOPED_TRACE(path.filename().string());
  ImportStats stats;
  SurfaceMesh m = importSurface(path, {}, &stats);
  EXPECT_EQ(m.vertexCount(), 8);
  EXPECT_EQ(m.triangleCount(), 12);
  const SurfaceReport report = validateSurface(m);
  EXPECT_TRUE(report.ok()) << report.summary();
  EXPECT_NEAR(report.volume, 1.0, 1e-6);  // the unit cube, outward (flipped if needed)
  EXPECT_EQ(report.genus, 0);
  EXPECT_NEAR(m.vertices.col(0).minCoeff(), offset_x, 1e-6);
  EXPECT_NEAR(m.vertices.col(0).maxCoeff(), offset_x + 1.0, 1e-6);
}

TEST(ImportSurface, CubeInEveryFormat) {
  TempDir dir;
  std::ostringstream obj, off, ply, stl;
  for (int v = 0; v < 8; ++v) obj << "v " << corner(v) << "\n";
  for (const auto& q : kQuads) obj << "f " << q[0] + 1 << ' ' << q[1] + 1 << ' ' << q[2] + 1 << ' ' << q[3] + 1 << "\n";
  off << "OFF\n8 12 0\n";
  for (int v = 0; v < 8; ++v) off << corner(v) << "\n";
  ply << "ply\nformat ascii 1.0\nelement vertex 8\nproperty float x\nproperty float y\nproperty float z\n"
         "element face 12\nproperty list uchar int vertex_indices\nend_header\n";
  for (int v = 0; v < 8; ++v) ply << corner(v) << "\n";
  stl << "solid cube\n";
  const SurfaceMesh c = cube();
  for (int f = 0; f < 12; ++f) {
    off << "3 " << c.triangles.row(f) << "\n";
    ply << "3 " << c.triangles.row(f) << "\n";
    stl << " facet normal 0 0 0\n  outer loop\n";
    for (int k = 0; k < 3; ++k) stl << "   vertex " << c.vertices.row(c.triangles(f, k)) << "\n";
    stl << "  endloop\n endfacet\n";
  }
  stl << "endsolid cube\n";
  expectUnitCube(dir.write("cube.obj", obj.str()));  // quads: triangulated by assimp
  expectUnitCube(dir.write("cube.off", off.str()));
  expectUnitCube(dir.write("cube.ply", ply.str()));
  expectUnitCube(dir.write("cube.stl", stl.str()));  // 36 unshared vertices welded to 8

  // glTF 2.0 with an embedded buffer and a node translation that must be applied.
  std::vector<unsigned char> buffer;
  for (int v = 0; v < 8; ++v) {
    for (int k = 0; k < 3; ++k) {
      const float x = static_cast<float>(corner(v)[k]);
      unsigned char b[4];
      std::memcpy(b, &x, 4);
      buffer.insert(buffer.end(), b, b + 4);
    }
  }
  for (int f = 0; f < 12; ++f) {
    for (int k = 0; k < 3; ++k) {
      const auto i = static_cast<std::uint16_t>(c.triangles(f, k));
      buffer.push_back(static_cast<unsigned char>(i & 0xff));
      buffer.push_back(static_cast<unsigned char>(i >> 8));
    }
  }
  std::ostringstream gltf;
  gltf << R"({"asset":{"version":"2.0"},"scene":0,"scenes":[{"nodes":[0]}],)"
       << R"("nodes":[{"mesh":0,"translation":[2,0,0]}],)"
       << R"("meshes":[{"primitives":[{"attributes":{"POSITION":0},"indices":1}]}],)"
       << R"("buffers":[{"byteLength":168,"uri":"data:application/octet-stream;base64,)" << base64(buffer) << R"("}],)"
       << R"("bufferViews":[{"buffer":0,"byteOffset":0,"byteLength":96},{"buffer":0,"byteOffset":96,"byteLength":72}],)"
       << R"("accessors":[{"bufferView":0,"componentType":5126,"count":8,"type":"VEC3","min":[0,0,0],"max":[1,1,1]},)"
       << R"({"bufferView":1,"componentType":5123,"count":36,"type":"SCALAR"}]})";
  expectUnitCube(dir.write("cube.gltf", gltf.str()), 2.0);
}

// ---- file vertex order (OBJ, OFF, PLY keep the file's order) ----

// Triangles as sorted lists of corner triples, each rotated so its smallest index comes first
// (orientation kept): equal lists = the same triangles over the same vertex numbering.
std::vector<std::array<std::int32_t, 3>> canonicalTriangles(const Triangles& t) {
  std::vector<std::array<std::int32_t, 3>> out;
  for (Eigen::Index f = 0; f < t.rows(); ++f) {
    std::array<std::int32_t, 3> c{t(f, 0), t(f, 1), t(f, 2)};
    while (c[0] > c[1] || c[0] > c[2]) std::rotate(c.begin(), c.begin() + 1, c.end());
    out.push_back(c);
  }
  std::sort(out.begin(), out.end());
  return out;
}

void appendBytes(std::string& out, const void* p, std::size_t n, bool big) {
  const auto* b = static_cast<const unsigned char*>(p);
  for (std::size_t i = 0; i < n; ++i) out += static_cast<char>(b[big ? n - 1 - i : i]);  // the host is little-endian
}

// The unit cube scaled by 0.3 and shifted by 0.1 (coordinates not representable in float), its
// vertices written in a scrambled order: file vertex i is cube corner kPerm[i]. The first face
// uses file vertices 3, 1, 4, so "order of first use" differs from file order.
constexpr int kPerm[8] = {5, 2, 7, 0, 3, 6, 1, 4};

TEST(ImportSurface, KeepsTheFileVertexOrder) {
  ASSERT_EQ(std::endian::native, std::endian::little);
  TempDir dir;
  SurfaceMesh file;  // what the files say, in file numbering
  file.vertices.resize(8, 3);
  int inverse[8];
  for (int i = 0; i < 8; ++i) {
    file.vertices.row(i) = corner(kPerm[i]) * 0.3 + Eigen::RowVector3d::Constant(0.1);
    inverse[kPerm[i]] = i;
  }
  const SurfaceMesh c = cube();
  file.triangles.resize(12, 3);
  for (int f = 0; f < 12; ++f) {
    for (int k = 0; k < 3; ++k) file.triangles(f, k) = inverse[c.triangles(f, k)];
  }
  ASSERT_EQ(file.triangles.row(0), (Eigen::Matrix<std::int32_t, 1, 3>(3, 1, 4)));

  std::ostringstream obj, off, ply;
  obj.precision(17);
  off.precision(17);
  ply.precision(17);
  off << "OFF\n# a comment\n8 12 0\n";
  ply << "ply\nformat ascii 1.0\ncomment written by the test\nelement vertex 8\nproperty double x\nproperty double y\n"
         "property double z\nelement face 12\nproperty list uchar int vertex_indices\nend_header\n";
  for (int i = 0; i < 8; ++i) {
    const Eigen::RowVector3d p = file.vertices.row(i);
    obj << "v " << p[0] << ' ' << p[1] << ' ' << p[2] << "\n";
    off << p[0] << ' ' << p[1] << ' ' << p[2] << "\n";
    ply << p[0] << ' ' << p[1] << ' ' << p[2] << "\n";
  }
  for (int f = 0; f < 12; ++f) {
    const auto t = file.triangles.row(f);
    obj << "f " << t[0] + 1 << ' ' << t[1] + 1 << ' ' << t[2] + 1 << "\n";
    off << "3 " << t[0] << ' ' << t[1] << ' ' << t[2] << "\n";
    ply << "3 " << t[0] << ' ' << t[1] << ' ' << t[2] << "\n";
  }
  // Binary PLY, both byte orders: float positions plus an extra per-vertex byte to skip.
  std::string binary[2];
  for (int big = 0; big < 2; ++big) {
    std::string& b = binary[big];
    b = std::string("ply\nformat ") + (big ? "binary_big_endian" : "binary_little_endian") +
        " 1.0\nelement vertex 8\nproperty float x\nproperty float y\nproperty float z\nproperty uchar flags\n"
        "element face 12\nproperty list uchar int vertex_indices\nend_header\n";
    for (int i = 0; i < 8; ++i) {
      for (int k = 0; k < 3; ++k) {
        const float x = static_cast<float>(file.vertices(i, k));
        appendBytes(b, &x, 4, big != 0);
      }
      b += static_cast<char>(0x7f);
    }
    for (int f = 0; f < 12; ++f) {
      b += static_cast<char>(3);
      for (int k = 0; k < 3; ++k) {
        const std::int32_t v = file.triangles(f, k);
        appendBytes(b, &v, 4, big != 0);
      }
    }
  }
  const std::vector<std::array<std::int32_t, 3>> expected_triangles = canonicalTriangles(file.triangles);
  struct Case {
    std::filesystem::path path;
    bool single_precision;
  };
  const Case cases[] = {{dir.write("order.obj", obj.str()), false},
                        {dir.write("order.off", off.str()), false},
                        {dir.write("order.ply", ply.str()), false},
                        {dir.write("order_le.ply", binary[0]), true},
                        {dir.write("order_be.ply", binary[1]), true}};
  for (const Case& k : cases) {
    SCOPED_TRACE(k.path.filename().string());
    ImportStats stats;
    const SurfaceMesh m = importSurface(k.path, {}, &stats);
    EXPECT_TRUE(stats.file_order);
    EXPECT_EQ(stats.file_vertices, 8);
    EXPECT_EQ(stats.unreferenced_vertices, 0);
    ASSERT_EQ(m.vertexCount(), 8);
    for (int i = 0; i < 8; ++i) {
      for (int a = 0; a < 3; ++a) {
        // Text: the file's double itself (not assimp's float); binary float: that float.
        const double want = k.single_precision ? static_cast<double>(static_cast<float>(file.vertices(i, a))) : file.vertices(i, a);
        EXPECT_EQ(m.vertices(i, a), want) << "vertex " << i << " axis " << a;
      }
      EXPECT_EQ(stats.file_to_vertex[static_cast<std::size_t>(i)], i);
    }
    EXPECT_EQ(canonicalTriangles(m.triangles), expected_triangles);
  }

  // The vertex-list reader on every truncation of these files: a list of at most 8 vertices, each
  // one of the file's (a cut inside the last number may shorten it), or nothing; never a throw.
  for (const Case& k : cases) {
    SCOPED_TRACE(k.path.filename().string());
    std::ifstream in(k.path, std::ios::binary);
    const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    const std::filesystem::path cut = dir.write("cut" + k.path.extension().string(), "");
    for (std::size_t n = 0; n < bytes.size(); ++n) {
      std::ofstream(cut, std::ios::binary | std::ios::trunc) << bytes.substr(0, n);
      std::optional<Vertices> list;
      ASSERT_NO_THROW(list = readFileVertexList(cut)) << n;
      if (list) {
        ASSERT_LE(list->rows(), 8) << n;
      }
    }
    const std::optional<Vertices> full = readFileVertexList(k.path);
    ASSERT_TRUE(full.has_value());
    EXPECT_EQ(full->rows(), 8);
  }
  // Absurd counts are refused before anything is allocated for them.
  EXPECT_FALSE(readFileVertexList(dir.write("huge.off", "OFF\n2000000000 1 0\n0 0 0\n")).has_value());
  EXPECT_FALSE(readFileVertexList(dir.write("huge.ply", "ply\nformat binary_little_endian 1.0\nelement vertex 2000000000\n"
                                                         "property double x\nproperty double y\nproperty double z\nend_header\n"))
                   .has_value());
  // An element without properties holds no data whatever its count: skipped at once (this one
  // made the reader loop 4e18 times before the vertices).
  const std::optional<Vertices> empty_element = readFileVertexList(
      dir.write("empty_element.ply", "ply\nformat ascii 1.0\nelement nothing 4000000000000000000\nelement vertex 1\n"
                                     "property float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n"));
  ASSERT_TRUE(empty_element.has_value());
  EXPECT_EQ(empty_element->rows(), 1);
  EXPECT_EQ((*empty_element)(0, 2), 3.0);
  EXPECT_FALSE(readFileVertexList(dir.write("mesh.stl", "solid x\nendsolid x\n")).has_value());  // no shared list
}

TEST(ImportSurface, DuplicateAndUnusedFileVertices) {
  // File vertices: 0..1 = cube corners kPerm[0..1], 2 = an unused point, 3..8 = corners kPerm[2..7],
  // 9 = an exact copy of vertex 0 that half of the faces use instead of vertex 0.
  TempDir dir;
  std::vector<Eigen::RowVector3d> v;
  int file_of_corner[8];
  for (int i = 0; i < 8; ++i) {
    if (i == 2) v.push_back(Eigen::RowVector3d(5, 5, 5));
    file_of_corner[kPerm[i]] = static_cast<int>(v.size());
    v.push_back(corner(kPerm[i]));
  }
  v.push_back(v[0]);
  std::ostringstream obj;
  for (const auto& p : v) obj << "v " << p[0] << ' ' << p[1] << ' ' << p[2] << "\n";
  const SurfaceMesh c = cube();
  int uses_copy = 0;
  for (int f = 0; f < 12; ++f) {
    obj << "f";
    for (int k = 0; k < 3; ++k) {
      int id = file_of_corner[c.triangles(f, k)];
      if (id == 0 && (f % 2) == 1) {
        id = 9;
        ++uses_copy;
      }
      obj << ' ' << id + 1;
    }
    obj << "\n";
  }
  ASSERT_GT(uses_copy, 0);
  ImportStats stats;
  SurfaceMesh m = importSurface(dir.write("dup.obj", obj.str()), {}, &stats);
  EXPECT_TRUE(stats.file_order);
  EXPECT_EQ(stats.file_vertices, 10);
  EXPECT_EQ(stats.welded_vertices, 1);        // the copy joins vertex 0
  EXPECT_EQ(stats.unreferenced_vertices, 1);  // the unused point is still there
  ASSERT_EQ(m.vertexCount(), 9);
  ASSERT_EQ(stats.file_to_vertex.size(), 10u);
  for (int i = 0; i < 9; ++i) EXPECT_EQ(stats.file_to_vertex[static_cast<std::size_t>(i)], i);
  EXPECT_EQ(stats.file_to_vertex[9], 0);
  for (int i = 0; i < 9; ++i) EXPECT_EQ(m.vertices.row(i), v[static_cast<std::size_t>(i)]) << i;

  // Validation removes the unused point: later ids shift down by one.
  const SurfaceReport r = validateSurface(m);
  EXPECT_TRUE(r.ok()) << r.summary();
  ASSERT_EQ(m.vertexCount(), 8);
  ASSERT_EQ(r.vertex_map.size(), 9u);
  EXPECT_EQ(r.vertex_map[0], 0);
  EXPECT_EQ(r.vertex_map[1], 1);
  EXPECT_EQ(r.vertex_map[2], -1);
  for (int i = 3; i < 9; ++i) EXPECT_EQ(r.vertex_map[static_cast<std::size_t>(i)], i - 1);
  for (int i = 0; i < 9; ++i) {
    if (r.vertex_map[static_cast<std::size_t>(i)] >= 0) {
      EXPECT_EQ(m.vertices.row(r.vertex_map[static_cast<std::size_t>(i)]), v[static_cast<std::size_t>(i)]);
    }
  }
  EXPECT_NEAR(r.volume, 1.0, 1e-12);
}

TEST(ImportSurface, MissingAndUnreadableFiles) {
  TempDir dir;
  try {
    (void)importSurface("/nonexistent/tetrig/mesh.obj");
    FAIL() << "no exception";
  } catch (const RigBuildError& e) {
    EXPECT_CONTAINS(e.what(), "/nonexistent/tetrig/mesh.obj: no such file");
  }
  EXPECT_THROW((void)importSurface(dir.write("garbage.ply", "ply\nthis is not a ply file\n")), RigBuildError);
  EXPECT_THROW((void)importSurface(dir.write("points.obj", "v 0 0 0\nv 1 0 0\n")), RigBuildError);
}

TEST(WeldVertices, MergesWithinToleranceOnly) {
  SurfaceMesh m;
  m.vertices.resize(4, 3);
  m.vertices << 0, 0, 0, 1, 0, 0, 1e-9, 0, 0, 1.1, 0, 0;
  m.triangles.resize(1, 3);
  m.triangles << 2, 1, 3;
  const std::vector<std::int32_t> map = weldVertices(m, 1e-6);
  ASSERT_EQ(m.vertexCount(), 3);
  EXPECT_EQ(map[2], 0);  // within 1e-6 of vertex 0
  EXPECT_EQ(map[3], 2);  // 0.1 away from vertex 1: kept
  EXPECT_EQ(m.triangles.row(0), (Eigen::Matrix<std::int32_t, 1, 3>(0, 1, 2)));
  EXPECT_EQ(m.vertices.row(0), Eigen::RowVector3d(0, 0, 0));  // the first one keeps its position
}

// ---- validation: repairs ----

TEST(ValidateSurface, FlipsAnInwardSurface) {
  SurfaceMesh m = cube();
  for (int f = 0; f < 12; ++f) std::swap(m.triangles(f, 1), m.triangles(f, 2));
  EXPECT_NEAR(signedVolume(m), -1.0, 1e-12);
  const SurfaceReport r = validateSurface(m);
  EXPECT_TRUE(r.ok()) << r.summary();
  EXPECT_TRUE(r.flipped_inside_out);
  EXPECT_NEAR(signedVolume(m), 1.0, 1e-12);
}

TEST(ValidateSurface, ReorientsAnInconsistentFace) {
  SurfaceMesh m = cube();
  std::swap(m.triangles(5, 1), m.triangles(5, 2));
  const SurfaceReport r = validateSurface(m);
  EXPECT_TRUE(r.ok()) << r.summary();
  EXPECT_EQ(r.reoriented_faces, 1);
  EXPECT_FALSE(r.flipped_inside_out);
  EXPECT_EQ(surfaceTopology(m).inconsistent_edges, 0);
  EXPECT_NEAR(signedVolume(m), 1.0, 1e-12);
}

TEST(ValidateSurface, WeldsDuplicatesRemovesDegenerateAndUnusedAndDuplicateFaces) {
  SurfaceMesh m = cube();
  const int copy = addVertex(m, corner(7));     // duplicate of vertex 7
  for (int f = 0; f < 12; ++f) {
    for (int k = 0; k < 3; ++k) {
      if (m.triangles(f, k) == 7 && f % 2 == 0) m.triangles(f, k) = copy;
    }
  }
  (void)addVertex(m, Eigen::RowVector3d(5, 5, 5));  // unused
  addTriangle(m, 0, 0, 1);                          // degenerate: repeated corner
  addTriangle(m, m.triangles(3, 0), m.triangles(3, 1), m.triangles(3, 2));  // duplicate face
  const SurfaceReport r = validateSurface(m);
  EXPECT_TRUE(r.ok()) << r.summary();
  EXPECT_EQ(r.welded_vertices, 1);
  EXPECT_EQ(r.removed_degenerate_faces, 1);
  EXPECT_EQ(r.removed_duplicate_faces, 1);
  EXPECT_EQ(r.removed_unused_vertices, 1);
  EXPECT_EQ(m.vertexCount(), 8);
  EXPECT_EQ(m.triangleCount(), 12);
  EXPECT_NEAR(r.volume, 1.0, 1e-12);
}

TEST(ValidateSurface, KeepLargestComponentOnRequest) {
  SurfaceMesh m = concat(cube(), cube(3.0, 0.5));
  ValidateOptions options;
  options.keep_largest_component = true;
  // Both cubes have 12 faces: make the first one larger by splitting a face into three.
  const int centre = addVertex(m, Eigen::RowVector3d(0.7, 0.3, 1.0));  // inside face (4, 5, 7)
  const Eigen::Matrix<std::int32_t, 1, 3> top = m.triangles.row(2);  // (4, 5, 7) on z = 1
  m.triangles.row(2) << top[0], top[1], centre;
  addTriangle(m, top[1], top[2], centre);
  addTriangle(m, top[2], top[0], centre);
  const SurfaceReport r = validateSurface(m, options);
  EXPECT_TRUE(r.ok()) << r.summary();
  EXPECT_EQ(r.dropped_components, 1);
  EXPECT_EQ(r.dropped_component_faces, 12);
  EXPECT_NEAR(r.volume, 1.0, 1e-12);
  EXPECT_LT(m.vertices.col(0).maxCoeff(), 1.5);  // the small cube at x = 3 is gone
  // vertex_map: the first cube's 8 corners keep their ids, the small cube's 8 are gone, the
  // face-centre vertex (input 16) moves down to 8.
  ASSERT_EQ(r.vertex_map.size(), 17u);
  for (int v = 0; v < 8; ++v) EXPECT_EQ(r.vertex_map[static_cast<std::size_t>(v)], v);
  for (int v = 8; v < 16; ++v) EXPECT_EQ(r.vertex_map[static_cast<std::size_t>(v)], -1);
  EXPECT_EQ(r.vertex_map[16], 8);
  EXPECT_EQ(m.vertices.row(8), Eigen::RowVector3d(0.7, 0.3, 1.0));
}

// ---- validation: refusals, with what to do ----

std::string refusalOf(SurfaceMesh m) {
  const SurfaceReport r = validateSurface(m);
  EXPECT_FALSE(r.ok()) << r.summary();
  try {
    requireUsableSurface(r, "test.obj");
  } catch (const RigBuildError& e) {
    return e.what();
  }
  ADD_FAILURE() << "requireUsableSurface did not throw";
  return {};
}

TEST(ValidateSurface, RefusesAnOpenSurface) {
  SurfaceMesh m = cube();
  m.triangles.conservativeResize(11, 3);  // one triangle missing: a hole with 3 boundary edges
  const std::string msg = refusalOf(m);
  EXPECT_CONTAINS(msg, "test.obj: surface refused");
  EXPECT_CONTAINS(msg, "open: 3 boundary edges");
  EXPECT_CONTAINS(msg, "close the holes");
}

TEST(ValidateSurface, RefusesNonManifoldEdges) {
  SurfaceMesh m = cube();
  const int fin = addVertex(m, Eigen::RowVector3d(0.5, -1.0, 0.5));
  addTriangle(m, 0, 1, fin);  // edge 0-1 now has three faces; the fin's other edges are open
  const std::string msg = refusalOf(m);
  EXPECT_CONTAINS(msg, "1 non-manifold edges");
  EXPECT_CONTAINS(msg, "exactly two faces");
}

TEST(ValidateSurface, RefusesSeveralComponents) {
  const std::string msg = refusalOf(concat(cube(), cube(3.0)));
  EXPECT_CONTAINS(msg, "2 separate components");
  EXPECT_CONTAINS(msg, "keep_largest_component");
}

TEST(ValidateSurface, RefusesNonManifoldVertex) {
  // Two cubes touching at one corner: cube A's vertex 7 is cube B's vertex 0.
  SurfaceMesh b = cube(1.0);
  b.vertices.rowwise() += Eigen::RowVector3d(0, 1, 1);
  SurfaceMesh m = concat(cube(), b);  // welding merges the touching corners
  const SurfaceReport r = validateSurface(m);
  EXPECT_EQ(r.components, 1);
  EXPECT_EQ(r.non_manifold_vertices, 1);
  EXPECT_EQ(r.non_manifold_edges, 0);
  EXPECT_FALSE(r.ok());
  EXPECT_CONTAINS(r.refusals.front(), "non-manifold vertices");
}

TEST(ValidateSurface, RefusesNonFiniteAndFlat) {
  SurfaceMesh m = cube();
  m.vertices(3, 1) = std::numeric_limits<double>::quiet_NaN();
  EXPECT_CONTAINS(refusalOf(m), "NaN or infinite");
  SurfaceMesh flat = cube();
  flat.vertices.col(2).setZero();  // squashed: faces collapse onto each other
  EXPECT_FALSE(validateSurface(flat).ok());
}

// ---- real meshes (../shared/data, see NOTES.md section 1) ----

struct RealMesh {
  const char* path;
  std::int32_t vertices;
  std::int32_t triangles;
};

class RealSurface : public ::testing::TestWithParam<RealMesh> {};

TEST_P(RealSurface, ImportsAndValidatesClosedGenusZero) {
  TETRIG_REQUIRE_DATA(path, GetParam().path);
  SurfaceMesh m = importSurface(path);
  const SurfaceReport r = validateSurface(m);
  EXPECT_TRUE(r.ok()) << r.summary();
  // Counts and topology as listed in NOTES.md (measured independently of this code).
  EXPECT_EQ(r.vertices, GetParam().vertices) << r.summary();
  EXPECT_EQ(r.triangles, GetParam().triangles);
  EXPECT_EQ(r.genus, 0);
  EXPECT_EQ(r.components, 1);
  EXPECT_GT(r.volume, 0.0);
}

// The real file read by the test itself (OBJ "v"/"f" lines, OFF): imported vertex i is the
// file's vertex i at the file's coordinates, the triangles are the file's faces, and validation
// (the files are clean) keeps every vertex where it is.
TEST_P(RealSurface, KeepsTheFileVertexOrder) {
  TETRIG_REQUIRE_DATA(path, GetParam().path);
  std::vector<Eigen::RowVector3d> v;
  std::vector<std::array<std::int32_t, 3>> faces;
  std::ifstream in(path);
  if (path.extension() == ".off") {
    std::string magic;
    std::size_t nv = 0, nf = 0, ne = 0;
    in >> magic >> nv >> nf >> ne;
    ASSERT_EQ(magic, "OFF");
    v.resize(nv);
    for (auto& p : v) in >> p[0] >> p[1] >> p[2];
    for (std::size_t f = 0; f < nf; ++f) {
      int n = 0;
      std::array<std::int32_t, 3> t{};
      in >> n >> t[0] >> t[1] >> t[2];
      ASSERT_EQ(n, 3);
      faces.push_back(t);
    }
  } else {
    for (std::string line; std::getline(in, line);) {
      std::istringstream s(line);
      std::string tag;
      s >> tag;
      if (tag == "v") {
        Eigen::RowVector3d p;
        s >> p[0] >> p[1] >> p[2];
        v.push_back(p);
      } else if (tag == "f") {
        std::vector<std::int32_t> ids;
        for (std::string corner_text; s >> corner_text;) ids.push_back(std::stoi(corner_text.substr(0, corner_text.find('/'))) - 1);
        ASSERT_EQ(ids.size(), 3u);
        faces.push_back({ids[0], ids[1], ids[2]});
      }
    }
  }
  ASSERT_EQ(static_cast<std::int32_t>(v.size()), GetParam().vertices);
  ImportStats stats;
  SurfaceMesh m = importSurface(path, {}, &stats);
  EXPECT_TRUE(stats.file_order);
  ASSERT_EQ(m.vertexCount(), GetParam().vertices);
  std::int32_t mismatched = 0;
  for (std::int32_t i = 0; i < m.vertexCount(); ++i) {
    if (m.vertices.row(i) != v[static_cast<std::size_t>(i)]) ++mismatched;
  }
  EXPECT_EQ(mismatched, 0);
  Triangles t(static_cast<Eigen::Index>(faces.size()), 3);
  for (std::size_t f = 0; f < faces.size(); ++f) t.row(static_cast<Eigen::Index>(f)) << faces[f][0], faces[f][1], faces[f][2];
  EXPECT_TRUE(canonicalTriangles(m.triangles) == canonicalTriangles(t));
  const SurfaceReport r = validateSurface(m);
  ASSERT_EQ(m.vertexCount(), GetParam().vertices);
  for (std::int32_t i = 0; i < m.vertexCount(); ++i) ASSERT_EQ(r.vertex_map[static_cast<std::size_t>(i)], i);
}

INSTANTIATE_TEST_SUITE_P(
    Data, RealSurface,
    ::testing::Values(RealMesh{"meshes/libigl-tutorial-data/decimated-knight.off", 502, 1000},
                      RealMesh{"meshes/odedstein-meshes/human_man.obj", 6890, 13776},
                      RealMesh{"meshes/libigl-tutorial-data/armadillo.obj", 43243, 86482},
                      RealMesh{"meshes/correspondence/dragon.obj", 10002, 20000},
                      RealMesh{"meshes/deformation-survey/cactus.off", 5261, 10518},
                      RealMesh{"meshes/deformation-survey/cylinder.off", 4802, 9600}),
    [](const ::testing::TestParamInfo<RealMesh>& param_info) {
      std::string name = std::filesystem::path(param_info.param.path).stem().string();
      for (char& ch : name) {
        if (!std::isalnum(static_cast<unsigned char>(ch))) ch = '_';
      }
      return name;
    });

TEST(RealSurfaceVolume, HumanManVolumeMatchesNotes) {
  TETRIG_REQUIRE_DATA(path, "meshes/odedstein-meshes/human_man.obj");
  SurfaceMesh m = importSurface(path);
  const SurfaceReport r = validateSurface(m);
  EXPECT_NEAR(r.volume, 0.083, 0.001);  // NOTES.md: outward, +0.083 m^3
  EXPECT_FALSE(r.flipped_inside_out);
}

}  // namespace
}  // namespace tetrig::rigbuild
