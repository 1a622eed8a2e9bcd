// Surface import (assimp + welding), the hostile-file check in front of it and its child process,
// and validation/repair of the rig builder.
#include "tetrig/rigbuild/check_surface_file.hpp"
#include "tetrig/rigbuild/file_vertex_list.hpp"
#include "tetrig/rigbuild/import_surface.hpp"
#include "tetrig/rigbuild/run_in_child_process.hpp"
#include "tetrig/rigbuild/validate_surface.hpp"
#include "tetrig/rigbuild/weld_vertices.hpp"
#include "temp_dir.hpp"
#include "test_data.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cctype>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstdlib>
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

using tetrig::test::TempDir;  // a fresh private directory per test (tests/support/temp_dir.hpp)

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

// Issue 37: an ascii list length is read as a number, and "nan" passed the old range test (NaN
// fails both n < 0 and n > 1e6); converting it to an integer is undefined (UBSan aborts; x86
// gives INT64_MIN, so the face's data was skipped and the next lines read as vertices). A list
// length that is not a whole number in [0, 1e6] makes the list unreadable, before or in the
// vertex element.
TEST(ImportSurface, VertexListRefusesListLengthsThatAreNotWholeNumbers) {
  const std::string vertices = "element vertex 3\nproperty float x\nproperty float y\nproperty float z\n";
  const std::string faces = "element face 1\nproperty list uchar int vertex_indices\n";
  for (const char* length : {"nan", "-nan", "inf", "2.5", "1e300"}) {
    SCOPED_TRACE(length);
    // Faces before the vertices: the face's list is skipped, then the vertices are read.
    EXPECT_FALSE(readFileVertexList("ply\nformat ascii 1.0\n" + faces + vertices + "end_header\n" + length +
                                        "\n0 0 0\n1 0 0\n0 1 0\n",
                                    ".ply")
                     .has_value());
    // A list property inside the vertex element.
    EXPECT_FALSE(readFileVertexList("ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
                                    "property float z\nproperty list uchar float extra\nend_header\n1 2 3 " +
                                        std::string(length) + "\n",
                                    ".ply")
                     .has_value());
  }
  // The same files with a whole length read as before.
  const std::optional<Vertices> good = readFileVertexList(
      "ply\nformat ascii 1.0\n" + faces + vertices + "end_header\n3 0 1 2\n0 0 0\n1 0 0\n0 1 0\n", ".ply");
  ASSERT_TRUE(good.has_value());
  EXPECT_EQ(good->rows(), 3);
  EXPECT_EQ((*good)(1, 0), 1.0);
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

// ---- hostile files: refused by the check before assimp, with one line, at once ----

// Imports a crafted file that must be refused. Returns the message after checking that it is one
// line naming the file and that the refusal came quickly (these files cost assimp gigabytes,
// minutes or a crash before the check).
std::string refusal(const std::filesystem::path& path, const ImportOptions& options = {}) {
  const auto t0 = std::chrono::steady_clock::now();
  std::string msg;
  try {
    (void)importSurface(path, options);
    ADD_FAILURE() << path.filename() << " was imported";
  } catch (const RigBuildError& e) {
    msg = e.what();
  }
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), 5.0) << path.filename();
  EXPECT_EQ(msg.find('\n'), std::string::npos) << msg;
  EXPECT_EQ(msg.rfind(path.string() + ": ", 0), 0u) << msg;
  return msg;
}

// A tetrahedron, outward: OFF/PLY text pieces.
const char* kTetVertices = "0 0 0\n1 0 0\n0 1 0\n0 0 1\n";
const char* kTetFaces = "3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n";
const char* kPlyTetHeader = "element vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
                            "element face 4\nproperty list uchar int vertex_indices\nend_header\n";

template <class T>
void appendLe(std::string& out, T v) {
  unsigned char b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));
  out.append(reinterpret_cast<const char*>(b), sizeof(T));  // the host is little-endian
}

// Binary little-endian PLY of the tetrahedron (float x y z, uchar count + int indices); the
// header's counts and the last face's list length can be overridden.
std::string binaryPlyTet(const std::string& vertex_count = "4", const std::string& face_count = "4", std::uint8_t last_list = 3) {
  std::string b = "ply\nformat binary_little_endian 1.0\nelement vertex " + vertex_count +
                  "\nproperty float x\nproperty float y\nproperty float z\nelement face " + face_count +
                  "\nproperty list uchar int vertex_indices\nend_header\n";
  const float v[4][3] = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  const std::int32_t f[4][3] = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  for (const auto& p : v) {
    for (const float x : p) appendLe(b, x);
  }
  for (int i = 0; i < 4; ++i) {
    appendLe(b, static_cast<std::uint8_t>(i == 3 ? last_list : 3));
    for (const std::int32_t x : f[i]) appendLe(b, x);
  }
  return b;
}

TEST(HostileSurfaceFiles, OffCountsBeyondTheData) {
  const TempDir dir("tetrig-hostile");
  // Controls: the same tetrahedron, honest, imports (also with comments before the counts).
  EXPECT_EQ(importSurface(dir.write("ok.off", std::string("OFF\n# c\n4 4 6\n") + kTetVertices + kTetFaces)).triangleCount(), 4);
  // 42 bytes declaring 9 faces and holding 1 (assimp: assertion abort).
  const auto short_faces = dir.write("short_faces.off", "OFF\n4 9 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 1 2\n");
  std::string msg = refusal(short_faces);
  EXPECT_CONTAINS(msg, "declares 4 vertices and 9 faces, but the data ends after the vertices and 1 faces");
  // 2^28 vertices or faces in 44 bytes (assimp: 3-6 GB, then an abort or bad_alloc).
  msg = refusal(dir.write("huge_v.off", "OFF\n268435456 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"));
  EXPECT_CONTAINS(msg, "declares 268435456 vertices and 1 faces, but the data ends after 4 vertices");  // the face line read as one
  msg = refusal(dir.write("huge_f.off", "OFF\n3 268435456 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"));
  EXPECT_CONTAINS(msg, "268435456 faces");
  // Counts beyond 32 bits (assimp would wrap them).
  EXPECT_CONTAINS(refusal(dir.write("wrap.off", "OFF\n4294967300 4 0\n")), "vertex count 4294967300 is too large");
  // Two vertices on one line: assimp reads one per line, so its faces run out.
  EXPECT_CONTAINS(refusal(dir.write("two_per_line.off", std::string("OFF\n4 4 0\n0 0 0 1 0 0\n0 1 0\n0 0 1\n") + kTetFaces)),
                  "one vertex or face per line");
  EXPECT_CONTAINS(refusal(dir.write("nv_word.off", "OFF\nfour 4 0\n")), "vertex count is 'four', not a number");
}

TEST(HostileSurfaceFiles, OffStructureTheImporterMisreads) {
  const TempDir dir("tetrig-hostile");
  const std::string head = "OFF\n4 4 0\n";
  // An out-of-range corner (assimp clamps it to the last vertex: a wrong surface, no error).
  EXPECT_CONTAINS(refusal(dir.write("range.off", head + kTetVertices + "3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 7\n")),
                  "line 10 (face 3): corner '7' is not a vertex index in [0, 3]");
  // A comment line inside the data (assimp reads it as a vertex).
  EXPECT_CONTAINS(refusal(dir.write("comment.off", head + "0 0 0\n# note\n1 0 0\n0 1 0\n0 0 1\n" + kTetFaces)),
                  "line 4 (vertex 1) is a comment inside the vertex list");
  // A face of 12 corners (assimp drops faces of more than 9 corners: a hole, no error).
  std::string prism = "OFF\n24 14 0\n";
  for (int z = 0; z < 2; ++z) {
    for (int i = 0; i < 12; ++i) prism += std::to_string(std::cos(i * M_PI / 6)) + " " + std::to_string(std::sin(i * M_PI / 6)) + " " + std::to_string(z) + "\n";
  }
  prism += "12 11 10 9 8 7 6 5 4 3 2 1 0\n12 12 13 14 15 16 17 18 19 20 21 22 23\n";
  for (int i = 0; i < 12; ++i) prism += "4 " + std::to_string(i) + " " + std::to_string((i + 1) % 12) + " " + std::to_string(12 + (i + 1) % 12) + " " + std::to_string(12 + i) + "\n";
  EXPECT_CONTAINS(refusal(dir.write("prism12.off", prism)), "face 0) has 12 corners; the OFF importer reads faces of at most 9 corners");
  // A line longer than assimp's 4096-byte line buffer (it overflows it and splits the line).
  std::string long_line = head + kTetVertices + "3 0 2 1" + std::string(5000, ' ') + "\n3 0 1 3\n3 0 3 2\n3 1 2 3\n";
  EXPECT_CONTAINS(refusal(dir.write("long.off", long_line)), "bytes long; the OFF importer reads lines of at most 4095 bytes");
  // A face with fewer corners than it says, and variants assimp reads differently.
  EXPECT_CONTAINS(refusal(dir.write("few.off", head + kTetVertices + "3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2\n")), "says 3 corners but lists 2");
  EXPECT_CONTAINS(refusal(dir.write("h.off", std::string("4OFF\n4 4 0\n") + kTetVertices + kTetFaces)), "not supported");
  EXPECT_CONTAINS(refusal(dir.write("b.off", "OFF BINARY\n")), "binary OFF is not supported");
  EXPECT_CONTAINS(refusal(dir.write("nul.off", std::string("OFF\n4 4 0\n0 0 0\n1 0", 18) + std::string(1, '\0') + " 0\n")), "control character");
}

TEST(HostileSurfaceFiles, PlyCountsBeyondTheData) {
  const TempDir dir("tetrig-hostile");
  EXPECT_EQ(importSurface(dir.write("ok.ply", std::string("ply\nformat ascii 1.0\n") + kPlyTetHeader + kTetVertices + kTetFaces)).triangleCount(), 4);
  EXPECT_EQ(importSurface(dir.write("ok_bin.ply", binaryPlyTet())).triangleCount(), 4);
  // Empty elements (with or without properties) hold no data, in either format.
  std::string empty_bin = binaryPlyTet();
  empty_bin.insert(empty_bin.find("element vertex"), "element nothing 0\nelement edge 0\nproperty int vertex1\n");
  EXPECT_EQ(importSurface(dir.write("empty_bin.ply", empty_bin)).triangleCount(), 4);
  // Under 200 bytes claiming 2^28 vertices or faces (assimp: 3-5 GB and minutes, or bad_alloc).
  std::string msg = refusal(dir.write("huge_v_ascii.ply", "ply\nformat ascii 1.0\nelement vertex 268435456\nproperty float x\nproperty float y\n"
                                                          "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n"));
  EXPECT_CONTAINS(msg, "the file ends before element 'vertex' item 1 (line 11)");
  msg = refusal(dir.write("huge_f_ascii.ply", std::string("ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
                                                          "element face 268435456\nproperty list uchar int vertex_indices\nend_header\n") + kTetVertices + kTetFaces));
  EXPECT_CONTAINS(msg, "the file ends before element 'face' item 4");
  msg = refusal(dir.write("huge_v_bin.ply", binaryPlyTet("268435456")));
  EXPECT_CONTAINS(msg, "element 'vertex' declares 268435456 items of 12 bytes but only");
  msg = refusal(dir.write("huge_f_bin.ply", binaryPlyTet("4", "268435456")));
  EXPECT_CONTAINS(msg, "the file ends inside element 'face' item 4");
  // A list longer than the data (assimp reads past its buffer: a segmentation fault).
  msg = refusal(dir.write("long_list.ply", binaryPlyTet("4", "4", 200)));
  EXPECT_CONTAINS(msg, "element 'face' item 3");
  EXPECT_CONTAINS(msg, "lists 200 values of 4 bytes but only 12 bytes remain");
  // Too few items on an ascii line (assimp fills in zeros), blank lines (assimp reads an empty item).
  EXPECT_CONTAINS(refusal(dir.write("short_line.ply", std::string("ply\nformat ascii 1.0\n") + kPlyTetHeader + "0 0 0\n1 0\n0 1 0\n0 0 1\n" + kTetFaces)),
                  "property 'z' is missing");
  EXPECT_CONTAINS(refusal(dir.write("blank.ply", std::string("ply\nformat ascii 1.0\n") + kPlyTetHeader + "0 0 0\n1 0 0\n\n0 1 0\n0 0 1\n" + kTetFaces)),
                  "element 'vertex' item 2 (line 12) is empty");
}

TEST(HostileSurfaceFiles, PlyStructureTheImporterMisreads) {
  const TempDir dir("tetrig-hostile");
  const std::string ascii = "ply\nformat ascii 1.0\n";
  // Out-of-range and negative corners (assimp keeps them: reads outside its vertex array).
  EXPECT_CONTAINS(refusal(dir.write("range.ply", ascii + kPlyTetHeader + kTetVertices + "3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 9\n")),
                  "element 'face' item 3 (line 17): corner 9 is not a vertex index in [0, 3]");
  EXPECT_CONTAINS(refusal(dir.write("negative.ply", ascii + kPlyTetHeader + kTetVertices + "3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 -1\n")),
                  "corner -1 is not a vertex index");
  // An element assimp does not know, holding data (assimp reads its count as 0 and misreads the rest: an abort).
  EXPECT_CONTAINS(refusal(dir.write("unknown.ply", ascii + "element foo 2\nproperty float a\n" + kPlyTetHeader + "5\n6\n" + kTetVertices + kTetFaces)),
                  "element 'foo' holds 2 items, but the PLY importer only reads");
  // ... which is fine when it holds nothing.
  EXPECT_EQ(importSurface(dir.write("unknown_empty.ply", ascii + "element foo 0\nproperty float a\n" + kPlyTetHeader + kTetVertices + kTetFaces)).triangleCount(), 4);
  // Triangle strips (assimp keeps one triangle per strip).
  EXPECT_CONTAINS(refusal(dir.write("strips.ply", ascii + "element vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
                                                  "element tristrips 1\nproperty list int int vertex_indices\nend_header\n" + kTetVertices + "6 0 1 2 3 0 1\n")),
                  "triangle strips (element 'tristrips') are read wrongly");
  // A face of no corners (assimp: an assertion abort), a list in element vertex, more texture
  // coordinates than corners (assimp reads past the face's corners).
  EXPECT_CONTAINS(refusal(dir.write("zero.ply", ascii + kPlyTetHeader + kTetVertices + "3 0 2 1\n3 0 1 3\n3 0 3 2\n0\n")), "a face with no corners");
  EXPECT_CONTAINS(refusal(dir.write("vlist.ply", ascii + "element vertex 4\nproperty float x\nproperty float y\nproperty float z\nproperty list uchar float w\n"
                                                 "element face 4\nproperty list uchar int vertex_indices\nend_header\n0 0 0 0\n1 0 0 0\n0 1 0 0\n0 0 1 0\n" + kTetFaces)),
                  "list property 'w' is not read safely");
  EXPECT_CONTAINS(refusal(dir.write("uv.ply", ascii + "element vertex 4\nproperty float x\nproperty float y\nproperty float z\nelement face 4\n"
                                              "property list uchar int vertex_indices\nproperty list uchar float texcoord\nend_header\n" + kTetVertices +
                                              "3 0 2 1 6 0 0 0 0 0 0\n3 0 1 3 6 0 0 0 0 0 0\n3 0 3 2 6 0 0 0 0 0 0\n3 1 2 3 8 0 0 0 0 0 0 0 0\n")),
                  "8 texture coordinates for 3 corners");
  // A binary header with CR LF line ends (assimp starts the data one byte early).
  std::string crlf = binaryPlyTet();
  const std::size_t end = crlf.find("end_header\n") + 11;
  std::string header = crlf.substr(0, end), fixed;
  for (const char c : header) fixed += c == '\n' ? std::string("\r\n") : std::string(1, c);
  EXPECT_CONTAINS(refusal(dir.write("crlf.ply", fixed + crlf.substr(end))), "line feed alone");
  // Header lines the importer reads differently, and names shown escaped.
  // A comment between two properties (assimp drops the properties after it: y and z read as 0).
  EXPECT_CONTAINS(refusal(dir.write("comment.ply", ascii + "element vertex 4\nproperty float x\ncomment c\nproperty float y\nproperty float z\n"
                                                   "element face 4\nproperty list uchar int vertex_indices\nend_header\n" + kTetVertices + kTetFaces)),
                  "header line 6: a property after a comment or obj_info line");
  EXPECT_CONTAINS(refusal(dir.write("lead.ply", ascii + " element vertex 4\n")), "starts with a blank");
  EXPECT_CONTAINS(refusal(dir.write("type.ply", ascii + "element vertex 4\nproperty int64 x\n")), "unknown property type 'int64'");
  EXPECT_CONTAINS(refusal(dir.write("esc.ply", ascii + "element \x1b[2J 3\nproperty float x\nend_header\n")), "holds a control character (\\x1b)");
  EXPECT_CONTAINS(refusal(dir.write("bytes.ply", ascii + "element \xff\xfe 3\nproperty float x\nend_header\n")), "element '\\xff\\xfe' holds 3 items");
}

TEST(HostileSurfaceFiles, StlSizeAndObjPolygons) {
  const TempDir dir("tetrig-hostile");
  // A binary STL whose triangle count does not match its size.
  std::string stl(80, ' ');
  appendLe(stl, std::uint32_t{1} << 28);
  stl += std::string(50, '\0');
  EXPECT_CONTAINS(refusal(dir.write("huge.stl", stl)), "header says 268435456 triangles must be 13421772884 bytes, the file has 134");
  EXPECT_CONTAINS(refusal(dir.write("tiny.stl", "abc")), "neither a binary STL");
  // One face of 100k corners (assimp triangulates it in quadratic time: minutes).
  std::ostringstream big;
  for (int i = 0; i < 100000; ++i) big << "v " << std::cos(i * 2e-5 * M_PI) << ' ' << std::sin(i * 2e-5 * M_PI) << " 0\n";
  big << "f";
  for (int i = 1; i <= 100000; ++i) big << ' ' << i;
  big << "\n";
  EXPECT_CONTAINS(refusal(dir.write("big_face.obj", big.str())),
                  "line 100001 (face statement) has 100000 corners, more than the 1024 a face may have");
  // The same through line continuations.
  std::string split = "v 0 0 0\nf";
  for (int i = 0; i < 1100; ++i) split += i % 100 == 99 ? " 1 \\\n" : " 1";
  EXPECT_CONTAINS(refusal(dir.write("split.obj", split + "\n")), "line 2 (face statement) has 1100 corners");
  // Many polygons within the per-face limit add up (the triangulation budget).
  std::string many = "v 0 0 0\n";
  for (int f = 0; f < 300; ++f) {
    many += "f";
    for (int i = 0; i < 300; ++i) many += " 1";
    many += "\n";
  }
  EXPECT_CONTAINS(refusal(dir.write("many.obj", many)), "add up to more triangulation work than allowed");
  // Within the limits a polygon imports: a 64-sided prism (two 64-gons and 64 quads).
  std::ostringstream prism;
  for (int z = 0; z < 2; ++z) {
    for (int i = 0; i < 64; ++i) prism << "v " << std::cos(i * M_PI / 32) << ' ' << std::sin(i * M_PI / 32) << ' ' << z << "\n";
  }
  prism << "f";
  for (int i = 64; i >= 1; --i) prism << ' ' << i;
  prism << "\nf";
  for (int i = 65; i <= 128; ++i) prism << ' ' << i;
  prism << "\n";
  for (int i = 0; i < 64; ++i) prism << "f " << i + 1 << ' ' << (i + 1) % 64 + 1 << ' ' << (i + 1) % 64 + 65 << ' ' << i + 65 << "\n";
  SurfaceMesh m = importSurface(dir.write("prism64.obj", prism.str()));
  EXPECT_EQ(m.triangleCount(), 2 * 62 + 2 * 64);
  const SurfaceReport r = validateSurface(m);
  EXPECT_TRUE(r.ok()) << r.summary();
  // An extension assimp does not know: refused, not guessed from the content by every importer.
  EXPECT_CONTAINS(refusal(dir.write("mesh.xyz", "v 0 0 0\n")), "unknown mesh file extension '.xyz'");
  EXPECT_CONTAINS(refusal(dir.write("mesh", "v 0 0 0\n")), "no file extension");
}

// ---- the importer runs in a child process: what the check cannot foresee ends as an error ----

TEST(ImportIsolation, ChildOutcomes) {
  // A crash, an abort, the CPU limit and the memory limit each come back as an outcome.
  ChildOutcome c = runInChildProcess([](int) -> bool {
    std::signal(SIGSEGV, SIG_DFL);  // (sanitizer builds catch SIGSEGV themselves)
    std::raise(SIGSEGV);
    return true;
  });
  EXPECT_FALSE(c.ok());
  EXPECT_EQ(c.signal_number, SIGSEGV);
  EXPECT_CONTAINS(c.describe(), "crashed with signal 11");
  c = runInChildProcess([](int) -> bool { std::abort(); });
  EXPECT_EQ(c.signal_number, SIGABRT);
  ChildLimits cpu;
  cpu.cpu_seconds = 1;
  c = runInChildProcess([](int) -> bool {
    volatile std::uint64_t x = 0;
    for (;;) x = x + 1;
  }, cpu);
  EXPECT_EQ(c.signal_number, SIGXCPU) << c.describe();
  EXPECT_CONTAINS(c.describe(), "CPU time limit");
#if !defined(__SANITIZE_ADDRESS__)
  ChildLimits memory;
  memory.memory_bytes = 64u << 20;
  c = runInChildProcess([](int fd) -> bool {
    try {
      std::vector<char> big(std::size_t{1} << 30, 1);  // 1 GiB against a 64 MiB limit
      return big[12345] == 0;
    } catch (const std::bad_alloc&) {
      return writeAllToFd(fd, "bad_alloc", 9);
    }
  }, memory);
  EXPECT_TRUE(c.ok()) << c.describe();
  EXPECT_EQ(std::string(c.output.begin(), c.output.end()), "bad_alloc");
#endif
  // Output, exit codes and captured stdout.
  c = runInChildProcess([](int fd) -> bool {
    std::printf("to the log\n");
    return writeAllToFd(fd, "result", 6);
  }, {}, true);
  EXPECT_TRUE(c.ok());
  EXPECT_EQ(std::string(c.output.begin(), c.output.end()), "result");
  EXPECT_EQ(c.log, "to the log\n");
  c = runInChildProcess([](int) -> bool { return false; });
  EXPECT_TRUE(c.exited);
  EXPECT_EQ(c.exit_code, 1);
  c = runInChildProcess([](int) -> bool { throw std::runtime_error("x"); });
  EXPECT_EQ(c.exit_code, 2);
}

TEST(ImportIsolation, SameMeshThroughTheChildAndLimitsReported) {
  const TempDir dir("tetrig-isolation");
  std::ostringstream obj;
  obj.precision(17);
  for (int v = 0; v < 8; ++v) obj << "v " << corner(v) * 0.3 + Eigen::RowVector3d::Constant(0.1) << "\n";
  for (const auto& q : kQuads) obj << "f " << q[0] + 1 << ' ' << q[1] + 1 << ' ' << q[2] + 1 << ' ' << q[3] + 1 << "\n";
  const auto path = dir.write("cube.obj", obj.str());
  ImportOptions in_process;
  in_process.isolate = false;
  ImportStats a_stats, b_stats;
  const SurfaceMesh a = importSurface(path, {}, &a_stats);
  const SurfaceMesh b = importSurface(path, in_process, &b_stats);
  EXPECT_EQ(a.vertices, b.vertices);  // bit for bit through the pipe
  EXPECT_EQ(a.triangles, b.triangles);
  EXPECT_EQ(a_stats.file_to_vertex, b_stats.file_to_vertex);
  EXPECT_TRUE(a_stats.file_order);
  // An error inside the child comes back as the same one line.
  const auto glb = dir.write("broken.glb", "glTF not really");
  const std::string isolated = refusal(glb);
  EXPECT_EQ(isolated, refusal(glb, in_process));
  EXPECT_CONTAINS(isolated, "cannot import");
#if !defined(__SANITIZE_ADDRESS__)
  // The memory limit: far too small for assimp, reported as such (in the child, not a crash here).
  ImportOptions tight;
  tight.memory_limit_bytes = 1u << 20;
  const std::string msg = refusal(path, tight);
  EXPECT_CONTAINS(msg, "the import needs more memory than its limit of 1 MB");
#endif
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
