// Tests for the TetGen (.node/.ele) and MEDIT (.mesh) readers and for checkTetMesh.
#include "tetrig/tet_mesh.hpp"
#include "tetrig/tet_mesh_io.hpp"
#include "temp_dir.hpp"
#include "test_data.hpp"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <random>
#include <string>

#include <unistd.h>

namespace tetrig {
namespace {

// Runs `fn` and returns the MeshFileError message; fails the test if nothing (or something else)
// is thrown.
template <typename Fn>
std::string errorOf(Fn&& fn) {
  try {
    fn();
  } catch (const MeshFileError& e) {
    return e.what();
  } catch (const std::exception& e) {
    ADD_FAILURE() << "expected MeshFileError, got another exception: " << e.what();
    return {};
  }
  ADD_FAILURE() << "expected MeshFileError, nothing was thrown";
  return {};
}

#define EXPECT_CONTAINS(haystack, needle) \
  EXPECT_NE(std::string(haystack).find(needle), std::string::npos) << "message: " << (haystack)

// A unit cube split into 5 positively oriented tets, 0-based, with comments, blank lines,
// one attribute per point and boundary markers.
const char* kCubeNode0 =
    "# cube\n"
    "8 3 1 1   # points, dim, attributes, markers\n"
    "\n"
    "0  0 0 0  0.5  1\n"
    "1  1 0 0  0.5  1\n"
    "2  1 1 0  0.5  1\n"
    "3  0 1 0  0.5  1\n"
    "4  0 0 1  0.5  1\n"
    "5  1 0 1  0.5  1\n"
    "6  1 1 1  0.5  1\n"
    "7  0 1 1  0.5  1\n"
    "# trailing comment\n";
const char* kCubeEle0 =
    "5 4 1\n"
    "0  0 1 3 4  7\n"
    "1  1 2 3 6  7\n"
    "2  1 6 4 5  7\n"
    "3  3 6 7 4  7\n"
    "4  1 3 4 6  7   # the middle tet\n";

// The same cube 1-based, without attributes, with CRLF line endings and tabs.
const char* kCubeNode1 =
    "8\t3\t0\t0\r\n"
    "1  0 0 0\r\n"
    "2  1 0 0\r\n"
    "3  1 1 0\r\n"
    "4  0 1 0\r\n"
    "5  0 0 1\r\n"
    "6  1 0 1\r\n"
    "7  1 1 1\r\n"
    "8  0 1 1\r\n";
const char* kCubeEle1 =
    "5 4 0\r\n"
    "1  1 2 4 5\r\n"
    "2  2 3 4 7\r\n"
    "3  2 7 5 6\r\n"
    "4  4 7 8 5\r\n"
    "5  2 4 5 7\r\n";

void expectCube(const TetMesh& mesh) {
  ASSERT_EQ(mesh.vertexCount(), 8);
  ASSERT_EQ(mesh.tetCount(), 5);
  EXPECT_EQ(mesh.vertices.row(6), Eigen::RowVector3d(1, 1, 1));
  EXPECT_EQ(mesh.vertices.row(4), Eigen::RowVector3d(0, 0, 1));
  EXPECT_EQ(mesh.tets.row(0), (Eigen::Matrix<std::int32_t, 1, 4>(0, 1, 3, 4)));
  EXPECT_EQ(mesh.tets.row(4), (Eigen::Matrix<std::int32_t, 1, 4>(1, 3, 4, 6)));
  const TetMeshReport report = checkTetMesh(mesh);
  EXPECT_TRUE(report.ok()) << report.summary();
  double volume = 0.0;
  for (std::int32_t t = 0; t < mesh.tetCount(); ++t) volume += signedVolume(mesh, t);
  EXPECT_NEAR(volume, 1.0, 1e-12);  // the five tets fill the unit cube exactly
}

TEST(TetGenParse, ZeroBasedWithCommentsAttributesAndMarkers) {
  expectCube(parseTetGen(kCubeNode0, kCubeEle0, "cube0"));
}

TEST(TetGenParse, OneBasedWithCrlfAndTabs) { expectCube(parseTetGen(kCubeNode1, kCubeEle1, "cube1")); }

TEST(TetGenParse, TenNodeTetsKeepTheFirstFourCorners) {
  // Mid-edge nodes (indices 8..) are appended to the cube; only the corners must remain.
  std::string node = "10 3 0 0\n";
  const char* coords[] = {"0 0 0", "1 0 0", "1 1 0", "0 1 0", "0 0 1", "1 0 1", "1 1 1", "0 1 1", "0.5 0 0", "0 0.5 0"};
  for (int i = 0; i < 10; ++i) node += std::to_string(i) + " " + coords[i] + "\n";
  const std::string ele = "1 10 0\n0  0 1 3 4  8 9 8 9 8 9\n";
  const TetMesh mesh = parseTetGen(node, ele, "quadratic");
  ASSERT_EQ(mesh.tetCount(), 1);
  EXPECT_EQ(mesh.tets.row(0), (Eigen::Matrix<std::int32_t, 1, 4>(0, 1, 3, 4)));
}

// A MEDIT file with every kind of section the reader must skip, counts on the keyword's line and
// on the next line, comments and a reference column.
const char* kCubeMedit =
    "MeshVersionFormatted 2\n"
    "# a comment line\n"
    "Dimension\n3\n"
    "Vertices\n8\n"
    "0 0 0 1\n1 0 0 1\n1 1 0 1\n0 1 0 1\n0 0 1 1\n1 0 1 1\n1 1 1 1\n0 1 1 1\n"
    "Corners 2\n1\n2\n"
    "Edges\n2\n1 2 0\n2 3 0\n"
    "Ridges\n1\n1\n"
    "RequiredVertices 1\n3\n"
    "Triangles\n1\n1 2 3 0\n"
    "Tetrahedra 5\n"
    "1 2 4 5 0\n2 3 4 7 0\n2 7 5 6 0\n4 7 8 5 0\n2 4 5 7 0   # middle\n"
    "NormalAtVertices\n1\n1 1\n"
    "End\n";

TEST(MeditParse, SkipsUnknownSectionsAndReadsTets) { expectCube(parseMedit(kCubeMedit, "cube.mesh")); }

TEST(MeditParse, TetrahedraBeforeVerticesAndNoEnd) {
  const std::string text =
      "MeshVersionFormatted 1\nDimension 3\nTetrahedra\n1\n1 2 3 4 0\nVertices\n4\n"
      "0 0 0 0\n1 0 0 0\n0 1 0 0\n0 0 1 0\n";
  const TetMesh mesh = parseMedit(text, "t.mesh");
  ASSERT_EQ(mesh.tetCount(), 1);
  EXPECT_EQ(mesh.tets.row(0), (Eigen::Matrix<std::int32_t, 1, 4>(0, 1, 2, 3)));
  EXPECT_GT(signedVolume(mesh, 0), 0.0);
}

// ---- malformed inputs: the message names the file, the line and what was expected/found ----

TEST(TetGenParse, BadInputsGiveClearMessages) {
  // Fewer points than the header says.
  std::string msg = errorOf([] { (void)parseTetGen("3 3 0 0\n0 0 0 0\n1 1 0 0\n", kCubeEle0, "m"); });
  EXPECT_CONTAINS(msg, "m.node");
  EXPECT_CONTAINS(msg, "expected 3 points, found 2");
  // More points than the header says.
  msg = errorOf([] { (void)parseTetGen("1 3 0 0\n0 0 0 0\n1 1 0 0\n", kCubeEle0, "m"); });
  EXPECT_CONTAINS(msg, "m.node:3:");
  EXPECT_CONTAINS(msg, "is the point count wrong?");
  // Wrong token count on a point line (an attribute is announced but missing).
  msg = errorOf([] { (void)parseTetGen("2 3 1 0\n0 0 0 0 7\n1 1 0 0\n", kCubeEle0, "m"); });
  EXPECT_CONTAINS(msg, "m.node:3:");
  EXPECT_CONTAINS(msg, "found 4 tokens");
  EXPECT_CONTAINS(msg, "1 attributes");
  // A non-number coordinate.
  msg = errorOf([] { (void)parseTetGen("1 3 0 0\n0 0 abc 0\n", "0 4 0\n", "m"); });
  EXPECT_CONTAINS(msg, "m.node:2:");
  EXPECT_CONTAINS(msg, "found 'abc'");
  // Non-finite coordinate.
  msg = errorOf([] { (void)parseTetGen("1 3 0 0\n0 0 nan 0\n", "0 4 0\n", "m"); });
  EXPECT_CONTAINS(msg, "non-finite coordinate");
  // Dimension 2.
  msg = errorOf([] { (void)parseTetGen("1 2 0 0\n0 0 0\n", "0 4 0\n", "m"); });
  EXPECT_CONTAINS(msg, "expected dimension 3, found 2");
  // First index neither 0 nor 1.
  msg = errorOf([] { (void)parseTetGen("1 3 0 0\n5 0 0 0\n", "0 4 0\n", "m"); });
  EXPECT_CONTAINS(msg, "m.node:2:");
  EXPECT_CONTAINS(msg, "first point index");
  // Points not numbered consecutively.
  msg = errorOf([] { (void)parseTetGen("2 3 0 0\n0 0 0 0\n2 1 0 0\n", "0 4 0\n", "m"); });
  EXPECT_CONTAINS(msg, "expected point index 1");
  // Out-of-range node index in .ele (1-based file: 0 is out of range).
  msg = errorOf([] { (void)parseTetGen(kCubeNode1, "1 4 0\n1 0 2 3 4\n", "m"); });
  EXPECT_CONTAINS(msg, "m.ele:2:");
  EXPECT_CONTAINS(msg, "node index 0 is out of range [1, 8]");
  msg = errorOf([] { (void)parseTetGen(kCubeNode0, "1 4 0\n0 0 1 2 8\n", "m"); });
  EXPECT_CONTAINS(msg, "node index 8 is out of range [0, 7]");
  // Wrong token count in .ele.
  msg = errorOf([] { (void)parseTetGen(kCubeNode0, "1 4 0\n0 0 1 2\n", "m"); });
  EXPECT_CONTAINS(msg, "m.ele:2:");
  EXPECT_CONTAINS(msg, "found 4 tokens");
  // Nodes per tet neither 4 nor 10.
  msg = errorOf([] { (void)parseTetGen(kCubeNode0, "1 5 0\n0 0 1 2 3 4\n", "m"); });
  EXPECT_CONTAINS(msg, "expected 4 or 10 nodes per tet, found 5");
  // A count the file cannot hold is refused before anything is allocated.
  msg = errorOf([] { (void)parseTetGen("2000000000 3 0 0\n0 0 0 0\n", "0 4 0\n", "m"); });
  EXPECT_CONTAINS(msg, "larger than the file can hold");
  msg = errorOf([] { (void)parseTetGen("-4 3 0 0\n", "0 4 0\n", "m"); });
  EXPECT_CONTAINS(msg, "point count -4 is out of range");
  // Empty files.
  msg = errorOf([] { (void)parseTetGen("# only a comment\n", "", "m"); });
  EXPECT_CONTAINS(msg, "m.node: unexpected end of file");
  msg = errorOf([] { (void)parseTetGen(kCubeNode0, "", "m"); });
  EXPECT_CONTAINS(msg, "m.ele: unexpected end of file");
}

TEST(MeditParse, BadInputsGiveClearMessages) {
  const std::string head = "MeshVersionFormatted 1\nDimension 3\nVertices\n4\n0 0 0 0\n1 0 0 0\n0 1 0 0\n0 0 1 0\n";
  // Wrong token count in a tet row (line 11).
  std::string msg = errorOf([&] { (void)parseMedit(head + "Tetrahedra\n1\n1 2 3\nEnd\n", "x.mesh"); });
  EXPECT_CONTAINS(msg, "x.mesh:11:");
  EXPECT_CONTAINS(msg, "expected 4 vertex indices and a reference");
  EXPECT_CONTAINS(msg, "found 3 tokens");
  // Out-of-range vertex index, reported at the tet's line.
  msg = errorOf([&] { (void)parseMedit(head + "Tetrahedra\n1\n1 2 3 5 0\nEnd\n", "x.mesh"); });
  EXPECT_CONTAINS(msg, "x.mesh:11:");
  EXPECT_CONTAINS(msg, "vertex index 5 is out of range [1, 4]");
  msg = errorOf([&] { (void)parseMedit(head + "Tetrahedra\n1\n0 2 3 4 0\nEnd\n", "x.mesh"); });
  EXPECT_CONTAINS(msg, "vertex index 0 is out of range");
  // Non-number.
  msg = errorOf([&] { (void)parseMedit(head + "Tetrahedra\n1\n1 2 three 4 0\nEnd\n", "x.mesh"); });
  EXPECT_CONTAINS(msg, "found 'three'");
  // Count larger than the rows present: the next keyword is read as a row.
  msg = errorOf([&] { (void)parseMedit(head + "Tetrahedra\n2\n1 2 3 4 0\nEnd\n", "x.mesh"); });
  EXPECT_CONTAINS(msg, "x.mesh:12:");
  EXPECT_CONTAINS(msg, "found 1 token");
  // Count smaller than the rows present: a row appears where a keyword is expected.
  msg = errorOf([&] { (void)parseMedit(head + "Tetrahedra\n1\n1 2 3 4 0\n1 2 3 4 0\nEnd\n", "x.mesh"); });
  EXPECT_CONTAINS(msg, "x.mesh:12:");
  EXPECT_CONTAINS(msg, "is a count wrong?");
  // Truncated in a skipped section.
  msg = errorOf([&] { (void)parseMedit(head + "Edges\n3\n1 2 0\n", "x.mesh"); });
  EXPECT_CONTAINS(msg, "expected 3 records in section Edges, found 1");
  // Missing sections.
  msg = errorOf([&] { (void)parseMedit(head + "End\n", "x.mesh"); });
  EXPECT_CONTAINS(msg, "no Tetrahedra section");
  msg = errorOf([] { (void)parseMedit("MeshVersionFormatted 1\nDimension 3\nTetrahedra\n0\nEnd\n", "x.mesh"); });
  EXPECT_CONTAINS(msg, "no Vertices section");
  // Not a MEDIT file / wrong dimension / binary.
  msg = errorOf([] { (void)parseMedit("solid cube\n", "x.mesh"); });
  EXPECT_CONTAINS(msg, "x.mesh:1: expected 'MeshVersionFormatted'");
  msg = errorOf([] { (void)parseMedit("MeshVersionFormatted 1\nDimension 2\n", "x.mesh"); });
  EXPECT_CONTAINS(msg, "expected Dimension 3, found 2");
  msg = errorOf([] { (void)parseMedit(std::string("\x01\x00\x00\x00", 4), "x.meshb"); });
  EXPECT_CONTAINS(msg, "only ASCII MEDIT");
  // Huge count.
  msg = errorOf([] { (void)parseMedit("MeshVersionFormatted 1\nVertices 2000000000\n0 0 0 0\n", "x.mesh"); });
  EXPECT_CONTAINS(msg, "larger than the file can hold");
  // Data after End.
  msg = errorOf([&] { (void)parseMedit(head + "Tetrahedra 1\n1 2 3 4 0\nEnd\nVertices 1\n", "x.mesh"); });
  EXPECT_CONTAINS(msg, "found data after 'End'");
}

// Every prefix of a valid file yields a mesh or a MeshFileError, never a crash or another
// exception (run under ASan/UBSan in the asan preset).
TEST(TetMeshIoTruncation, EveryPrefixOfTetGenFilesIsHandled) {
  const std::string node = kCubeNode0;
  const std::string ele = kCubeEle0;
  int errors = 0;
  for (size_t n = 0; n <= node.size(); ++n) {
    try {
      (void)parseTetGen(node.substr(0, n), ele, "cut");
    } catch (const MeshFileError&) {
      ++errors;
    }
  }
  for (size_t n = 0; n <= ele.size(); ++n) {
    try {
      (void)parseTetGen(node, ele.substr(0, n), "cut");
    } catch (const MeshFileError&) {
      ++errors;
    }
  }
  EXPECT_GT(errors, 0);
  // The whole files parse.
  EXPECT_NO_THROW((void)parseTetGen(node, ele, "whole"));
}

TEST(TetMeshIoTruncation, EveryPrefixOfMeditFileIsHandled) {
  const std::string text = kCubeMedit;
  int errors = 0;
  int meshes = 0;
  for (size_t n = 0; n <= text.size(); ++n) {
    try {
      const TetMesh mesh = parseMedit(text.substr(0, n), "cut.mesh");
      ++meshes;
      // A prefix accepted as a mesh must be internally consistent.
      EXPECT_EQ(checkTetMesh(mesh).out_of_range_indices, 0);
    } catch (const MeshFileError&) {
      ++errors;
    }
  }
  EXPECT_GT(errors, 0);
  EXPECT_GT(meshes, 0);  // at least the whole file (and the prefixes lacking only the tail)
}

// Random single- and multi-byte edits of valid files (deterministic seed): each result is a mesh
// whose indices are in range, or a MeshFileError; never a crash or another exception.
TEST(TetMeshIoMutation, MutatedFilesAreHandled) {
  std::mt19937 rng(20071);
  const std::string alphabet = "0123456789-+. \n\t#eEaxnN\r\x01";
  auto mutate = [&](std::string text) {
    std::uniform_int_distribution<int> edits(1, 4);
    for (int e = edits(rng); e > 0; --e) {
      std::uniform_int_distribution<size_t> pos(0, text.size() - 1);
      std::uniform_int_distribution<size_t> pick(0, alphabet.size() - 1);
      const size_t at = pos(rng);
      switch (rng() % 3) {
        case 0: text[at] = alphabet[pick(rng)]; break;
        case 1: text.insert(at, 1, alphabet[pick(rng)]); break;
        default: text.erase(at, 1); break;
      }
    }
    return text;
  };
  int meshes = 0;
  for (int i = 0; i < 3000; ++i) {
    try {
      const TetMesh mesh = (i % 3 == 0)   ? parseMedit(mutate(kCubeMedit), "m.mesh")
                           : (i % 3 == 1) ? parseTetGen(mutate(kCubeNode0), kCubeEle0, "m")
                                          : parseTetGen(kCubeNode1, mutate(kCubeEle1), "m");
      EXPECT_EQ(checkTetMesh(mesh).out_of_range_indices, 0);
      EXPECT_TRUE(mesh.vertices.allFinite());
      ++meshes;
    } catch (const MeshFileError&) {
    }
  }
  EXPECT_GT(meshes, 0);  // some edits (in comments, whitespace) leave a valid file
}

// ---- checkTetMesh ----

TEST(CheckTetMesh, ReportsInvertedAndZeroVolumeTets) {
  TetMesh mesh;
  mesh.vertices.resize(5, 3);
  mesh.vertices << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 1, 1, 0;
  mesh.tets.resize(3, 4);
  mesh.tets << 0, 1, 2, 3,  // positive: det[e1, e2, e3] = 1
      0, 2, 1, 3,           // inverted (two corners swapped)
      0, 1, 2, 4;           // all four corners in the plane z = 0
  const TetMeshReport report = checkTetMesh(mesh);
  EXPECT_EQ(report.inverted_tets, 1);
  EXPECT_EQ(report.degenerate_tets, 1);
  EXPECT_FALSE(report.ok());
  ASSERT_EQ(report.first_bad_tets.size(), 2u);
  EXPECT_EQ(report.first_bad_tets[0], 1);
  EXPECT_EQ(report.first_bad_tets[1], 2);
  EXPECT_CONTAINS(report.summary(), "1 inverted tets");
  EXPECT_CONTAINS(report.summary(), "1 zero-volume tets");
}

// ---- files on disk ----

TEST(TetMeshIoFiles, MissingFileAndUnknownExtension) {
  const test::TempDir tmp("tetrig-io");  // a fresh private directory: nothing of that name can be there
  const auto dir = tmp.path();
  std::string msg = errorOf([&] { (void)readTetMesh(dir / "tetrig_no_such_file_4711.mesh"); });
  EXPECT_CONTAINS(msg, "tetrig_no_such_file_4711.mesh: cannot open file");
  msg = errorOf([&] { (void)readTetMesh(dir / "whatever.obj"); });
  EXPECT_CONTAINS(msg, "unknown tet mesh extension '.obj'");
}

TEST(TetMeshIoFiles, TetGenStemOrEitherFile) {
  const test::TempDir tmp("tetrig-io");
  const auto dir = tmp.path();
  { std::ofstream(dir / "cube.1.node") << kCubeNode1; }
  { std::ofstream(dir / "cube.1.ele") << kCubeEle1; }
  expectCube(readTetGen(dir / "cube.1"));
  expectCube(readTetMesh(dir / "cube.1.node"));
  expectCube(readTetMesh(dir / "cube.1.ele"));
}

TEST(TetMeshIoData, PbdArmadillo4k) {
  TETRIG_REQUIRE_DATA(node, "meshes/PositionBasedDynamics/armadillo_4k.node");
  const TetMesh mesh = readTetMesh(node);
  EXPECT_EQ(mesh.vertexCount(), 1180);
  EXPECT_EQ(mesh.tetCount(), 3717);
  // First records of the files (0-based): point 0 and tet 0.
  EXPECT_DOUBLE_EQ(mesh.vertices(0, 0), -1.0329299999999999);
  EXPECT_DOUBLE_EQ(mesh.vertices(0, 1), 1.35422);
  EXPECT_EQ(mesh.tets.row(0), (Eigen::Matrix<std::int32_t, 1, 4>(480, 116, 560, 1054)));
  const TetMeshReport report = checkTetMesh(mesh);
  EXPECT_TRUE(report.ok()) << report.summary();
  EXPECT_EQ(report.unused_vertices, 0);
}

TEST(TetMeshIoData, OctopusLowMeditWithEdges) {
  TETRIG_REQUIRE_DATA(path, "meshes/libigl-tutorial-data/octopus-low.mesh");
  const TetMesh mesh = readTetMesh(path);
  EXPECT_EQ(mesh.vertexCount(), 452);
  EXPECT_EQ(mesh.tetCount(), 1140);
  EXPECT_DOUBLE_EQ(mesh.vertices(0, 0), -0.066882);
  // File row "236 407 255 404 0" is 1-based.
  EXPECT_EQ(mesh.tets.row(0), (Eigen::Matrix<std::int32_t, 1, 4>(235, 406, 254, 403)));
  const TetMeshReport report = checkTetMesh(mesh);
  EXPECT_EQ(report.inverted_tets, 0) << report.summary();
  EXPECT_EQ(report.out_of_range_indices, 0);
}

TEST(TetMeshIoData, HandMedit) {
  TETRIG_REQUIRE_DATA(path, "meshes/libigl-tutorial-data/hand.mesh");
  const TetMesh mesh = readMedit(path);
  EXPECT_EQ(mesh.vertexCount(), 7234);
  EXPECT_EQ(mesh.tetCount(), 29998);
  EXPECT_EQ(mesh.tets.row(0), (Eigen::Matrix<std::int32_t, 1, 4>(4468, 4279, 6838, 4472)));
  const TetMeshReport report = checkTetMesh(mesh);
  EXPECT_EQ(report.inverted_tets, 0) << report.summary();
  EXPECT_EQ(report.out_of_range_indices, 0);
}

}  // namespace
}  // namespace tetrig
