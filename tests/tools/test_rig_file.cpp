// The rig file (runtime/include/tetrig/rig_file.hpp) and the rig builder's tet-mesh, selection and
// marker-binding paths, on a small generated rig: round trip, every truncation length, bit flips,
// clear refusals, the rest pose as a fixed point, and the atomic writer.
#include "small_rig.hpp"
#include "tetrig/deformer.hpp"
#include "tetrig/rig_file.hpp"
#include "tetrig/rigbuild/boundary_surface.hpp"
#include "tetrig/rigbuild/rig_description.hpp"
#include "tetrig/rigbuild/write_file_atomic.hpp"

#include <gtest/gtest.h>

#include <cstring>
#include <random>

namespace tetrig {
namespace {

using test::TempDir;

#define EXPECT_CONTAINS(haystack, needle) \
  EXPECT_NE(std::string(haystack).find(needle), std::string::npos) << "text: " << (haystack)

std::string parseError(const std::vector<std::uint8_t>& bytes, const RigParseOptions& options = {}) {
  try {
    (void)parseRig(bytes, "test.rig", options);
  } catch (const RigFileError& e) {
    return e.what();
  }
  return {};
}

void putU32(std::vector<std::uint8_t>& b, std::size_t at, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) b[at + static_cast<std::size_t>(i)] = static_cast<std::uint8_t>(v >> (8 * i));
}
void putU64(std::vector<std::uint8_t>& b, std::size_t at, std::uint64_t v) {
  for (int i = 0; i < 8; ++i) b[at + static_cast<std::size_t>(i)] = static_cast<std::uint8_t>(v >> (8 * i));
}

class SmallRig : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new TempDir();
    rig_ = new Rig(test::buildSmallRig(*dir_, &report_));
    bytes_ = new std::vector<std::uint8_t>(serializeRig(*rig_));
  }
  static void TearDownTestSuite() {
    delete bytes_;
    delete rig_;
    delete dir_;
  }
  static TempDir* dir_;
  static Rig* rig_;
  static std::vector<std::uint8_t>* bytes_;
  static rigbuild::BuildRigReport report_;
};
TempDir* SmallRig::dir_ = nullptr;
Rig* SmallRig::rig_ = nullptr;
std::vector<std::uint8_t>* SmallRig::bytes_ = nullptr;
rigbuild::BuildRigReport SmallRig::report_;

TEST(RigCrc32c, PublishedCheckValue) {
  const char* text = "123456789";
  EXPECT_EQ(rigCrc32c({reinterpret_cast<const std::uint8_t*>(text), 9}), 0xE3069283u);  // CRC-32/ISCSI catalogue
}

TEST_F(SmallRig, HoldsWhatTheDescriptionAsks) {
  const Rig& r = *rig_;
  // 4 x 3 x 3 grid points, 6 tets per cell, 12 cells.
  EXPECT_EQ(r.body_vertex_count, 36);
  EXPECT_EQ(r.body_tet_count, 72);
  EXPECT_TRUE(report_.tet_input);
  // Fine mesh = boundary of the block: every grid vertex but the 2 interior ones (i in 1..2, j=1, k=1).
  EXPECT_EQ(r.fine_vertices.rows(), 34);
  EXPECT_EQ(r.fine_triangles.rows(), 2 * 2 * (3 * 2 + 3 * 2 + 2 * 2));
  ASSERT_EQ(r.markers.size(), 5u);
  EXPECT_EQ(r.tet_mesh.vertexCount(), 36 + 5);
  const auto expected = test::smallMarkerPositionsMm();
  for (std::size_t m = 0; m < r.markers.size(); ++m) {
    const RigMarker& mk = r.markers[m];
    EXPECT_EQ(mk.tet_vertex, 36 + static_cast<std::int32_t>(m));
    EXPECT_EQ(r.setup.vertex_handles[static_cast<std::size_t>(mk.vertex_handle)], mk.tet_vertex);
    // alignment "units": mm -> m, same axes.
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(mk.rest_position[k], expected[m][static_cast<std::size_t>(k)] * 1e-3, 1e-9);
    EXPECT_GE(mk.bound_faces, 1) << mk.label;
    EXPECT_LE(mk.bound_faces, 3) << mk.label;
    // Every marker's invisible tets: positive volume, three body corners and the marker.
    int found = 0;
    for (std::int32_t t = r.body_tet_count; t < r.tet_mesh.tetCount(); ++t) {
      if (r.tet_mesh.tets(t, 3) != mk.tet_vertex) continue;
      ++found;
      EXPECT_GT(signedVolume(r.tet_mesh, t), 0.0);
      for (int k = 0; k < 3; ++k) EXPECT_LT(r.tet_mesh.tets(t, k), r.body_vertex_count);
    }
    EXPECT_EQ(found, mk.bound_faces) << mk.label;
  }
  // Distances: the markers sit 12-15 mm outside the faces.
  EXPECT_NEAR(r.markers[0].surface_distance, 0.015, 1e-9);
  EXPECT_NEAR(r.markers[1].surface_distance, 0.012, 1e-9);
  ASSERT_EQ(r.setup.region_handles.size(), 1u);
  for (const std::int32_t t : r.setup.region_handles[0].tets) {
    int floor = 0;
    for (int k = 0; k < 4; ++k) floor += std::abs(r.tet_mesh.vertices(r.tet_mesh.tets(t, k), 1)) < 1e-9;
    EXPECT_GE(floor, 3);
  }
  // Every bottom face (2 triangles x 6 cells) has exactly one tet with 3 floor corners.
  EXPECT_EQ(r.setup.region_handles[0].tets.size(), 12u);
  ASSERT_EQ(r.setup.rigid_groups.size(), 1u);
  EXPECT_FALSE(r.setup.rigid_groups[0].tets.empty());
  ASSERT_EQ(r.setup.point_handles.size(), 1u);
  const PointHandle& ph = r.setup.point_handles[0];
  Eigen::Vector3d p = Eigen::Vector3d::Zero();
  for (int k = 0; k < 4; ++k) p += ph.barycentric[k] * r.tet_mesh.vertices.row(r.tet_mesh.tets(ph.tet, k)).transpose();
  EXPECT_NEAR((p - Eigen::Vector3d(0.2, 0.12, 0.1)).norm(), 0.0, 1e-12);
  EXPECT_GE(ph.barycentric.minCoeff(), -1e-12);  // inside its tet
  ASSERT_EQ(r.setup.stiffness.size(), static_cast<std::size_t>(r.tet_mesh.tetCount()));
  for (std::int32_t t = r.body_tet_count; t < r.tet_mesh.tetCount(); ++t) EXPECT_EQ(r.setup.stiffness[static_cast<std::size_t>(t)], 0.1);
  EXPECT_NE(std::find(r.setup.stiffness.begin(), r.setup.stiffness.end(), 0.5), r.setup.stiffness.end());
  EXPECT_TRUE(checkTetMesh(r.tet_mesh).ok());
}

TEST_F(SmallRig, RoundTripIsExact) {
  const TempDir dir;
  const std::filesystem::path path = dir.path() / "small.rig";
  rigbuild::writeFileAtomically(path, *bytes_);
  const Rig back = loadRigFile(path);
  const Rig& r = *rig_;
  EXPECT_EQ(back.name, r.name);
  EXPECT_EQ(back.unit, r.unit);
  EXPECT_EQ(back.tet_mesh.vertices, r.tet_mesh.vertices);
  EXPECT_EQ(back.tet_mesh.tets, r.tet_mesh.tets);
  EXPECT_EQ(back.body_vertex_count, r.body_vertex_count);
  EXPECT_EQ(back.body_tet_count, r.body_tet_count);
  EXPECT_EQ(back.fine_vertices, r.fine_vertices);
  EXPECT_EQ(back.fine_triangles, r.fine_triangles);
  EXPECT_EQ(back.pose_transfer.row_offsets, r.pose_transfer.row_offsets);
  EXPECT_EQ(back.pose_transfer.columns, r.pose_transfer.columns);
  EXPECT_EQ(back.pose_transfer.weights, r.pose_transfer.weights);
  EXPECT_EQ(back.setup.vertex_handles, r.setup.vertex_handles);
  EXPECT_EQ(back.vertex_handle_names, r.vertex_handle_names);
  ASSERT_EQ(back.setup.region_handles.size(), r.setup.region_handles.size());
  EXPECT_EQ(back.setup.region_handles[0].tets, r.setup.region_handles[0].tets);
  EXPECT_EQ(back.setup.region_handles[0].oriented, r.setup.region_handles[0].oriented);
  EXPECT_EQ(back.region_handle_names, r.region_handle_names);
  ASSERT_EQ(back.setup.point_handles.size(), 1u);
  EXPECT_EQ(back.setup.point_handles[0].tet, r.setup.point_handles[0].tet);
  EXPECT_EQ(back.setup.point_handles[0].barycentric, r.setup.point_handles[0].barycentric);
  ASSERT_EQ(back.setup.rigid_groups.size(), 1u);
  EXPECT_EQ(back.setup.rigid_groups[0].tets, r.setup.rigid_groups[0].tets);
  EXPECT_EQ(back.rigid_group_names, r.rigid_group_names);
  EXPECT_EQ(back.setup.stiffness, r.setup.stiffness);
  ASSERT_EQ(back.markers.size(), r.markers.size());
  for (std::size_t m = 0; m < r.markers.size(); ++m) {
    EXPECT_EQ(back.markers[m].label, r.markers[m].label);
    EXPECT_EQ(back.markers[m].tet_vertex, r.markers[m].tet_vertex);
    EXPECT_EQ(back.markers[m].rest_position, r.markers[m].rest_position);
    EXPECT_EQ(back.markers[m].bound_faces, r.markers[m].bound_faces);
  }
  EXPECT_EQ(back.alignment.linear, r.alignment.linear);
  EXPECT_EQ(back.alignment.translation, r.alignment.translation);
  EXPECT_EQ(back.alignment.device_up, r.alignment.device_up);
  EXPECT_EQ(back.setup.options.rotation_steps, r.setup.options.rotation_steps);
  // Serialising again gives the same bytes.
  EXPECT_EQ(serializeRig(back), *bytes_);
  // The atomic writer left no temporary file behind.
  int files = 0;
  for (const auto& e : std::filesystem::directory_iterator(dir.path())) {
    ++files;
    EXPECT_EQ(e.path().filename(), "small.rig");
  }
  EXPECT_EQ(files, 1);
}

TEST_F(SmallRig, RestPoseIsAFixedPoint) {
  const Rig rig = parseRig(*bytes_, "small.rig");
  Deformer deformer(rig.tet_mesh, rig.setup);
  std::vector<Eigen::Vector3d> vertex_targets;
  for (const std::int32_t v : rig.setup.vertex_handles) vertex_targets.push_back(rig.tet_mesh.vertices.row(v).transpose());
  std::vector<RigidTransform> regions(rig.setup.region_handles.size());
  std::vector<Eigen::Vector3d> points;
  for (const PointHandle& ph : rig.setup.point_handles) {
    Eigen::Vector3d p = Eigen::Vector3d::Zero();
    for (int k = 0; k < 4; ++k) p += ph.barycentric[k] * rig.tet_mesh.vertices.row(rig.tet_mesh.tets(ph.tet, k)).transpose();
    points.push_back(p);
  }
  HandleTargets targets{vertex_targets, regions, points};
  StepBudget budget;
  budget.max_iterations = 5;
  const StepStats stats = deformer.step(targets, budget);
  EXPECT_EQ(stats.flags & (kStepTargetsRejected | kStepTargetsWrongSize), 0u);
  const double diag = boundingBoxDiagonal(rig.fine_vertices);
  const std::span<const double> x = deformer.positions();
  for (std::int32_t v = 0; v < rig.tet_mesh.vertexCount(); ++v) {
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(x[static_cast<std::size_t>(v) * 3 + k], rig.tet_mesh.vertices(v, k), 1e-6 * diag);
  }
  std::vector<double> fine(static_cast<std::size_t>(rig.fine_vertices.rows()) * 3);
  applyPoseTransfer(rig.pose_transfer.view(), x.data(), fine.data());
  for (Eigen::Index v = 0; v < rig.fine_vertices.rows(); ++v) {
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(fine[static_cast<std::size_t>(v) * 3 + k], rig.fine_vertices(v, k), 1e-6 * diag);
  }
}

TEST_F(SmallRig, EveryTruncationIsRefused) {
  const std::vector<std::uint8_t>& full = *bytes_;
  for (std::size_t len = 0; len < full.size(); ++len) {
    std::vector<std::uint8_t> cut(full.begin(), full.begin() + static_cast<std::ptrdiff_t>(len));
    EXPECT_FALSE(parseError(cut).empty()) << "length " << len;
    // Behind the checksum too: a header that claims the truncated length, checksum not verified,
    // so the section table and section parsers see the short data.
    if (len >= 32) {
      putU64(cut, 16, len);
      RigParseOptions no_crc;
      no_crc.verify_checksum = false;
      EXPECT_FALSE(parseError(cut, no_crc).empty()) << "length " << len;
    }
  }
}

TEST_F(SmallRig, EveryBitFlipIsRefused) {
  // CRC-32C detects every single-bit error; header fields are checked on their own.
  std::mt19937 rng(12345);
  const std::vector<std::uint8_t>& full = *bytes_;
  std::vector<std::uint8_t> flipped = full;
  int checked = 0;
  for (std::size_t at = 0; at < full.size(); at += 1 + rng() % 7) {
    const std::uint8_t bit = static_cast<std::uint8_t>(1u << (rng() % 8));
    flipped[at] ^= bit;
    EXPECT_FALSE(parseError(flipped).empty()) << "byte " << at;
    flipped[at] ^= bit;
    ++checked;
  }
  EXPECT_GT(checked, static_cast<int>(full.size() / 8));
}

TEST_F(SmallRig, RandomCorruptionBehindTheChecksumNeverCrashes) {
  // With the checksum off, corrupted sections reach the parsers: each must either be refused with
  // RigFileError or give a rig that passes validation (the Deformer may still refuse it, cleanly).
  std::mt19937 rng(777);
  RigParseOptions no_crc;
  no_crc.verify_checksum = false;
  int refused = 0, accepted = 0;
  for (int trial = 0; trial < 3000; ++trial) {
    std::vector<std::uint8_t> b = *bytes_;
    const int flips = 1 + static_cast<int>(rng() % 4);
    for (int f = 0; f < flips; ++f) b[32 + rng() % (b.size() - 32)] = static_cast<std::uint8_t>(rng());
    try {
      const Rig r = parseRig(b, "fuzz.rig", no_crc);
      EXPECT_EQ(validateRig(r), "");
      ++accepted;
    } catch (const RigFileError&) {
      ++refused;
    }
  }
  EXPECT_GT(refused, 0);
  EXPECT_EQ(refused + accepted, 3000);
}

TEST_F(SmallRig, HeaderFaultsHaveClearMessages) {
  std::vector<std::uint8_t> b = *bytes_;
  b[0] = 'X';
  EXPECT_CONTAINS(parseError(b), "not a rig file");
  b = *bytes_;
  putU32(b, 8, kRigFormatVersion + 1);
  EXPECT_CONTAINS(parseError(b), "version 2");
  b = *bytes_;
  b[200] ^= 0x01;
  EXPECT_CONTAINS(parseError(b), "checksum mismatch");
  b = *bytes_;
  b.push_back(0);
  EXPECT_CONTAINS(parseError(b), "truncated or appended");
  EXPECT_CONTAINS(parseError({}), "shorter than the 32-byte header");
  try {
    (void)loadRigFile("/nonexistent/tetrig/x.rig");
    FAIL() << "no exception";
  } catch (const RigFileError& e) {
    EXPECT_CONTAINS(e.what(), "/nonexistent/tetrig/x.rig");
  }
}

TEST_F(SmallRig, InconsistentRigsAreNotWritten) {
  Rig bad = *rig_;
  bad.markers[0].vertex_handle = 1;  // the handle of another marker
  EXPECT_THROW((void)serializeRig(bad), RigFileError);
  bad = *rig_;
  bad.tet_mesh.tets(0, 0) = 999;
  EXPECT_NE(validateRig(bad), "");
  bad = *rig_;
  bad.pose_transfer.columns[0] = bad.pose_transfer.cols;
  EXPECT_NE(validateRig(bad), "");
  bad = *rig_;
  std::swap(bad.tet_mesh.tets(3, 0), bad.tet_mesh.tets(3, 1));  // inverted
  EXPECT_CONTAINS(validateRig(bad), "inverted");
}

TEST(RigBuild, MarkerBeyondTheLimitStopsTheBuildNamingIt) {
  const TempDir dir;
  // TOP, FRONT and BACK are 15 mm out, LEFT and RIGHT 12 mm: with a 13.5 mm limit the build stops
  // and names a marker beyond it, and not the ones within it.
  try {
    (void)test::buildSmallRig(dir, nullptr, 0.0135);
    FAIL() << "no exception";
  } catch (const rigbuild::RigBuildError& e) {
    const std::string what = e.what();
    EXPECT_CONTAINS(what, "from the surface after alignment");
    EXPECT_TRUE(what.find("marker TOP") != std::string::npos || what.find("marker FRONT") != std::string::npos ||
                what.find("marker BACK") != std::string::npos)
        << what;
    EXPECT_EQ(what.find("LEFT ("), std::string::npos) << what;  // 12 mm: within the limit
  }
}

TEST(RigDescription, RefusalsNameThePath) {
  auto error = [](const std::string& json) {
    try {
      (void)rigbuild::parseRigDescription(json, "r.json");
    } catch (const rigbuild::RigBuildError& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  EXPECT_CONTAINS(error(R"({"region_handles": [{"select": {"cube": 1}}]})"), "region_handles[0].select: unknown key 'cube'");
  EXPECT_CONTAINS(error(R"({"vertex_handles": [{"select": {"vertices": [1], "box": {"min":[0,0,0],"max":[1,1,1]}}}]})"),
                  "exactly one of");
  EXPECT_CONTAINS(error(R"({"markers": {"max_distance": -1}})"), "markers.max_distance");
  EXPECT_CONTAINS(error(R"({"tet_vertices": 2)"), "not valid JSON");
  EXPECT_CONTAINS(error(R"({"stiffness": [{"select": {"vertices": [0]}}]})"), "needs a value");
  EXPECT_CONTAINS(error(R"({"mesh_unit": "furlong"})"), "mesh_unit");
  const rigbuild::RigDescription d =
      rigbuild::parseRigDescription(R"({"vertex_handles": [{"name": "h", "select": {"sel_file": "a.sel", "sel_values": [2]}}]})", "/x/r.json");
  EXPECT_EQ(d.vertex_handles[0].select.sel_file, std::filesystem::path("/x/a.sel"));
}

TEST(RigBuild, OverlappingHandlesAreRefusedByName) {
  const TempDir dir;
  rigbuild::BuildRigInputs in;
  in.mesh = test::writeBlockTetMesh(dir, "block");
  in.description = rigbuild::parseRigDescription(R"({
    "vertex_handles": [ { "name": "pin", "select": { "vertices": [0] } } ],
    "region_handles": [ { "name": "floor", "select": { "box": { "min": [-1, -0.01, -1], "max": [1, 0.01, 1] } } } ] })",
                                                 dir.path() / "r.json");
  try {
    (void)rigbuild::buildRig(in);
    FAIL() << "no exception";
  } catch (const rigbuild::RigBuildError& e) {
    EXPECT_CONTAINS(e.what(), "vertex handle 'pin'");
    EXPECT_CONTAINS(e.what(), "region handle 'floor'");
  }
}

TEST(AtomicWrite, FailureLeavesNothing) {
  const TempDir dir;
  const std::vector<std::uint8_t> bytes(100, 7);
  EXPECT_THROW(rigbuild::writeFileAtomically(dir.path() / "missing-dir" / "x.rig", bytes), rigbuild::RigBuildError);
  rigbuild::writeFileAtomically(dir.path() / "x.rig", bytes);
  rigbuild::writeFileAtomically(dir.path() / "x.rig", std::vector<std::uint8_t>(10, 1));  // replaces
  EXPECT_EQ(std::filesystem::file_size(dir.path() / "x.rig"), 10u);
  int files = 0;
  for ([[maybe_unused]] const auto& e : std::filesystem::directory_iterator(dir.path())) ++files;
  EXPECT_EQ(files, 1);
}

}  // namespace
}  // namespace tetrig
