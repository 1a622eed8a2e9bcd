// The rig file (runtime/include/tetrig/rig_file.hpp) and the rig builder's tet-mesh, selection and
// marker-binding paths, on a small generated rig: round trip, every truncation length, bit flips,
// clear refusals, the rest pose as a fixed point, and the atomic writer; layouts the format forbids
// (overlap, misalignment, gaps, trailing bytes, reserved words, bound-face counts, non-UTF-8
// strings) refused behind a valid checksum; a rig's text escaped by `tetrig inspect` and errors;
// rig-description integers range-checked on their full value. The fixture's rig carries
// a pose sensor, so every sweep covers the optional PSNS section too; rigs without one still
// write and read the thirteen required sections alone. The example puppet rig
// (assets/puppet_hydra.json) is built here with the rig builder.
#include "run_command.hpp"
#include "small_rig.hpp"
#include "tetrig/deformer.hpp"
#include "tetrig/printable_text.hpp"
#include "tetrig/rig_file.hpp"
#include "tetrig/tet_mesh.hpp"
#include "tetrig/rigbuild/describe_rig.hpp"
#include "tetrig/rigbuild/rig_description.hpp"
#include "tetrig/rigbuild/write_file_atomic.hpp"

#include <gtest/gtest.h>

#include <sys/wait.h>

#include <algorithm>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <functional>
#include <limits>
#include <sstream>
#include <utility>
#include <random>

namespace tetrig {
namespace {

using test::TempDir;

#define EXPECT_CONTAINS(haystack, needle) \
  EXPECT_NE(std::string(haystack).find(needle), std::string::npos) << "text: " << (haystack)

// Offset and size of the section `name` in the table, or {0, 0} when absent.
std::pair<std::size_t, std::size_t> findSection(const std::vector<std::uint8_t>& b, const char (&name)[5]) {
  auto u32 = [&b](std::size_t at) {
    std::uint32_t v = 0;
    for (int i = 0; i < 4; ++i) v |= static_cast<std::uint32_t>(b[at + static_cast<std::size_t>(i)]) << (8 * i);
    return v;
  };
  auto u64 = [&b](std::size_t at) {
    std::uint64_t v = 0;
    for (int i = 0; i < 8; ++i) v |= static_cast<std::uint64_t>(b[at + static_cast<std::size_t>(i)]) << (8 * i);
    return v;
  };
  std::uint32_t wanted = 0;
  for (int i = 0; i < 4; ++i) wanted |= static_cast<std::uint32_t>(static_cast<unsigned char>(name[i])) << (8 * i);
  const std::uint32_t sections = u32(12);
  for (std::uint32_t i = 0; i < sections; ++i) {
    const std::size_t entry = 32 + 24 * static_cast<std::size_t>(i);
    if (u32(entry) == wanted) return {static_cast<std::size_t>(u64(entry + 8)), static_cast<std::size_t>(u64(entry + 16))};
  }
  return {0, 0};
}

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
// Recomputes the header's CRC-32C after an edit, so the edit reaches the section parsers.
void fixChecksum(std::vector<std::uint8_t>& b) {
  putU32(b, 24, rigCrc32c(std::span<const std::uint8_t>(b).subspan(32)));
}

// The pose sensor the fixture adds to the small rig (its only region, "floor", is oriented).
RigPoseSensor smallPoseSensor() {
  RigPoseSensor ps;
  ps.sensor_label = "hydra1";
  ps.region_handle = 0;
  ps.mode = PoseSensorMode::kClutch;
  ps.clutch_buttons = 0x21;
  ps.translation_scale = 0.75;
  return ps;
}

class SmallRig : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new TempDir();
    rig_ = new Rig(test::buildSmallRig(*dir_, &report_));
    rig_->pose_sensors.push_back(smallPoseSensor());
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
  ASSERT_EQ(back.pose_sensors.size(), 1u);
  EXPECT_EQ(back.pose_sensors[0].sensor_label, "hydra1");
  EXPECT_EQ(back.pose_sensors[0].region_handle, 0);
  EXPECT_EQ(back.pose_sensors[0].mode, PoseSensorMode::kClutch);
  EXPECT_EQ(back.pose_sensors[0].clutch_buttons, 0x21);
  EXPECT_EQ(back.pose_sensors[0].translation_scale, 0.75);
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

TEST_F(SmallRig, RigsWithoutPoseSensorsHaveNoPoseSensorSection) {
  // No pose sensors: the thirteen required sections only, exactly what the writer produced before
  // the optional section existed, and it loads with no pose sensors.
  Rig plain = *rig_;
  plain.pose_sensors.clear();
  const std::vector<std::uint8_t> bytes = serializeRig(plain);
  EXPECT_EQ(bytes[12], 13u);
  EXPECT_EQ(findSection(bytes, "PSNS").second, 0u);
  EXPECT_EQ(findSection(*bytes_, "PSNS").first + findSection(*bytes_, "PSNS").second, bytes_->size());  // the last section
  EXPECT_EQ((*bytes_)[12], 14u);
  // The same bytes before the pose sensors' section: the required sections did not change.
  EXPECT_TRUE(std::equal(bytes.begin() + 32 + 13 * 24, bytes.end(), bytes_->begin() + 32 + 14 * 24));
  const Rig back = parseRig(bytes, "plain.rig");
  EXPECT_TRUE(back.pose_sensors.empty());
  EXPECT_EQ(back.setup.region_handles.size(), 1u);
}

TEST_F(SmallRig, PoseSensorSectionTruncatedAtEveryLengthIsRefused) {
  // A consistent file (table size, header size, checksum) whose PSNS section is cut short.
  const auto [offset, size] = findSection(*bytes_, "PSNS");
  ASSERT_GT(size, 0u);
  ASSERT_EQ(offset + size, bytes_->size());
  std::size_t entry = 0;
  for (std::size_t i = 0; i < 14; ++i) {
    if (std::memcmp(bytes_->data() + 32 + 24 * i, "PSNS", 4) == 0) entry = 32 + 24 * i;
  }
  ASSERT_NE(entry, 0u);
  for (std::size_t cut = 0; cut < size; ++cut) {
    std::vector<std::uint8_t> b(bytes_->begin(), bytes_->begin() + static_cast<std::ptrdiff_t>(offset + cut));
    putU64(b, entry + 16, cut);
    putU64(b, 16, b.size());
    fixChecksum(b);
    const std::string e = parseError(b);
    EXPECT_CONTAINS(e, "section PSNS");
    EXPECT_CONTAINS(e, "truncated");
  }
}

// The coarse level (CRSE): a whole rig file inside the rig file. Here the small rig is its own
// coarse level (the section's format does not depend on what it holds).
Rig withCoarse(const Rig& rig) {
  Rig r = rig;
  Rig c = rig;
  c.coarse.reset();
  r.coarse = std::make_shared<const Rig>(std::move(c));
  return r;
}

TEST_F(SmallRig, CoarseLevelRoundTripsAsAWholeRigFileOfItsOwn) {
  const Rig with = withCoarse(*rig_);
  const std::vector<std::uint8_t> bytes = serializeRig(with);
  EXPECT_EQ(bytes[12], 15u);
  const auto [offset, size] = findSection(bytes, "CRSE");
  ASSERT_GT(size, 0u);
  EXPECT_EQ(offset + size, bytes.size());  // the last section
  // Its content is the coarse rig's own file, byte for byte.
  const std::vector<std::uint8_t> inner = serializeRig(*with.coarse);
  ASSERT_EQ(size, inner.size());
  EXPECT_TRUE(std::equal(inner.begin(), inner.end(), bytes.begin() + static_cast<std::ptrdiff_t>(offset)));
  const Rig back = parseRig(bytes, "with-coarse.rig");
  ASSERT_NE(back.coarse, nullptr);
  EXPECT_EQ(back.coarse->coarse, nullptr);
  EXPECT_EQ(serializeRig(back), bytes);
  // Without a coarse level, no CRSE section: the file is the one written before it existed.
  EXPECT_EQ(findSection(*bytes_, "CRSE").second, 0u);
  EXPECT_EQ(parseRig(*bytes_, "plain.rig").coarse, nullptr);
}

TEST_F(SmallRig, CoarseSectionTruncatedOrCorruptIsRefusedNamingIt) {
  const std::vector<std::uint8_t> full = serializeRig(withCoarse(*rig_));
  const auto [offset, size] = findSection(full, "CRSE");
  std::size_t entry = 0;
  for (std::size_t i = 0; i < 15; ++i) {
    if (std::memcmp(full.data() + 32 + 24 * i, "CRSE", 4) == 0) entry = 32 + 24 * i;
  }
  ASSERT_NE(entry, 0u);
  // Cut at lengths across the inner file (every 97th, and the edges), the outer file kept consistent.
  for (std::size_t cut = 0; cut < size; cut += (cut < 64 || cut + 64 > size) ? 1 : 97) {
    std::vector<std::uint8_t> b(full.begin(), full.begin() + static_cast<std::ptrdiff_t>(offset + cut));
    putU64(b, entry + 16, cut);
    putU64(b, 16, b.size());
    fixChecksum(b);
    const std::string e = parseError(b);
    EXPECT_CONTAINS(e, "section CRSE (the coarse level)");
  }
  // An inner file that holds a coarse level of its own (crafted: the writer never makes one) is
  // refused before that level is parsed, so levels cannot nest to any depth.
  {
    const std::vector<std::uint8_t> inner = serializeRig(withCoarse(*rig_));
    std::vector<std::uint8_t> b(full.begin(), full.begin() + static_cast<std::ptrdiff_t>(offset));
    b.insert(b.end(), inner.begin(), inner.end());
    putU64(b, entry + 16, inner.size());
    putU64(b, 16, b.size());
    fixChecksum(b);
    const std::string e = parseError(b);
    EXPECT_CONTAINS(e, "section CRSE (the coarse level): the coarse level has a coarse level of its own");
  }
  // A bit flip inside the inner file: its own checksum refuses it.
  std::vector<std::uint8_t> b = full;
  b[offset + size / 2] ^= 0x10;
  fixChecksum(b);
  const std::string e = parseError(b);
  EXPECT_CONTAINS(e, "section CRSE (the coarse level)");
  EXPECT_CONTAINS(e, "checksum mismatch");
}

TEST_F(SmallRig, CoarseLevelsThatDoNotFitAreNotWritten) {
  const auto refused = [](const Rig& r) {
    try {
      (void)serializeRig(r);
    } catch (const RigFileError& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  // A coarse level of its own.
  Rig nested = withCoarse(*rig_);
  Rig inner = *nested.coarse;
  inner.coarse = std::make_shared<const Rig>(*rig_);
  nested.coarse = std::make_shared<const Rig>(inner);
  EXPECT_CONTAINS(refused(nested), "coarse level has a coarse level of its own");
  // A marker the rig does not have.
  ASSERT_FALSE(rig_->markers.empty());
  Rig foreign = withCoarse(*rig_);
  Rig c = *foreign.coarse;
  c.markers[0].label = "ZZZZ";
  foreign.coarse = std::make_shared<const Rig>(c);
  EXPECT_CONTAINS(refused(foreign), "marker 'ZZZZ' is not a marker of the rig");
  // Another rig space.
  Rig moved = withCoarse(*rig_);
  c = *moved.coarse;
  c.alignment.translation.x() += 0.01;
  moved.coarse = std::make_shared<const Rig>(c);
  EXPECT_CONTAINS(refused(moved), "alignment");
  // Another number of region handles.
  Rig regions = withCoarse(*rig_);
  c = *regions.coarse;
  c.setup.region_handles.clear();
  c.region_handle_names.clear();
  c.pose_sensors.clear();
  regions.coarse = std::make_shared<const Rig>(c);
  EXPECT_CONTAINS(refused(regions), "region handles");
}

TEST_F(SmallRig, PoseSensorSectionFaultsHaveClearMessages) {
  const auto [offset, size] = findSection(*bytes_, "PSNS");
  ASSERT_GT(size, 0u);
  // Layout: u32 n, str label ("hydra1": u32 6 + 6 bytes), i32 region, u8 mode, u8 buttons, f64 scale.
  const std::size_t region_at = offset + 4 + 4 + 6, mode_at = region_at + 4, scale_at = mode_at + 2;
  auto edited = [&](auto edit) {
    std::vector<std::uint8_t> b = *bytes_;
    edit(b);
    fixChecksum(b);
    return parseError(b);
  };
  EXPECT_EQ(edited([](std::vector<std::uint8_t>&) {}), "");
  EXPECT_CONTAINS(edited([&](std::vector<std::uint8_t>& b) { b[mode_at] = 2; }), "pose sensor mode 2 is not 0 (clutch) or 1 (absolute)");
  EXPECT_CONTAINS(edited([&](std::vector<std::uint8_t>& b) { putU32(b, region_at, 1); }), "pose sensor 0 (hydra1) names region handle 1 of 1");
  EXPECT_CONTAINS(edited([&](std::vector<std::uint8_t>& b) { b[mode_at + 1] = 0; }), "clutch mode with no clutch button");
  EXPECT_CONTAINS(edited([&](std::vector<std::uint8_t>& b) { putU64(b, scale_at, 0x7FF0000000000000ull); }),  // +inf
                  "non-finite value in pose sensor translation scale");
  EXPECT_CONTAINS(edited([&](std::vector<std::uint8_t>& b) { putU64(b, scale_at, 0xBFF0000000000000ull); }),  // -1.0
                  "translation scale that is not a finite positive number");
  EXPECT_CONTAINS(edited([&](std::vector<std::uint8_t>& b) { putU32(b, offset, 1000); }), "truncated: 1000 pose sensors");
  EXPECT_CONTAINS(edited([&](std::vector<std::uint8_t>& b) { putU32(b, offset, 0); }), "24 unexpected bytes at the end of the section");
  // Absolute mode (1) with any button byte is fine.
  std::vector<std::uint8_t> b = *bytes_;
  b[mode_at] = 1;
  fixChecksum(b);
  EXPECT_EQ(parseRig(b, "abs.rig").pose_sensors[0].mode, PoseSensorMode::kAbsolute);
}

TEST_F(SmallRig, RandomCorruptionOfThePoseSensorSectionNeverCrashes) {
  // Bytes of the PSNS section replaced at random, behind the checksum: each file is refused with
  // RigFileError or parses into a rig that passes validation.
  const auto [offset, size] = findSection(*bytes_, "PSNS");
  ASSERT_GT(size, 0u);
  std::mt19937 rng(4242);
  RigParseOptions no_crc;
  no_crc.verify_checksum = false;
  int refused = 0, accepted = 0;
  for (int trial = 0; trial < 2000; ++trial) {
    std::vector<std::uint8_t> b = *bytes_;
    const int flips = 1 + static_cast<int>(rng() % 3);
    for (int f = 0; f < flips; ++f) b[offset + rng() % size] = static_cast<std::uint8_t>(rng());
    try {
      const Rig r = parseRig(b, "fuzz.rig", no_crc);
      EXPECT_EQ(validateRig(r), "");
      ++accepted;
    } catch (const RigFileError& e) {
      EXPECT_NE(std::string(e.what()).find("fuzz.rig: "), std::string::npos) << e.what();
      ++refused;
    }
  }
  EXPECT_GT(refused, 0);
  EXPECT_GT(accepted, 0);  // e.g. another label byte or button mask
}

TEST_F(SmallRig, InvalidPoseSensorsAreNotWritten) {
  auto fault = [&](auto edit) {
    Rig bad = *rig_;
    edit(bad.pose_sensors[0], bad);
    EXPECT_THROW((void)serializeRig(bad), RigFileError);
    return validateRig(bad);
  };
  EXPECT_CONTAINS(fault([](RigPoseSensor& p, Rig&) { p.sensor_label.clear(); }), "empty sensor label");
  EXPECT_CONTAINS(fault([](RigPoseSensor& p, Rig&) { p.region_handle = -1; }), "names region handle -1 of 1");
  EXPECT_CONTAINS(fault([](RigPoseSensor&, Rig& r) { r.setup.region_handles[0].oriented = false; }), "which is not oriented");
  EXPECT_CONTAINS(fault([](RigPoseSensor& p, Rig&) { p.clutch_buttons = 0; }), "no clutch button");
  EXPECT_CONTAINS(fault([](RigPoseSensor& p, Rig&) { p.translation_scale = 0.0; }), "translation scale");
  EXPECT_CONTAINS(fault([](RigPoseSensor& p, Rig&) { p.translation_scale = std::numeric_limits<double>::quiet_NaN(); }),
                  "translation scale");
  EXPECT_CONTAINS(fault([](RigPoseSensor& p, Rig& r) { r.pose_sensors.push_back(p); }), "is driven twice (by pose sensors or marker clusters)");
  Rig ok = *rig_;
  ok.pose_sensors[0].mode = PoseSensorMode::kAbsolute;
  ok.pose_sensors[0].clutch_buttons = 0;  // buttons do not matter in absolute mode
  EXPECT_EQ(validateRig(ok), "");
}

// Texture coordinates and materials (the optional UVMT section): a made-up set on the small rig's
// fine triangles (corners with and without a uv, triangles with and without a material).
Rig withSurface(const Rig& rig) {
  Rig r = rig;
  RigSurfaceAttributes& s = r.surface;
  s.asset = "/assets/block.obj";
  s.material_libraries = {"block.mtl", "more/extra.mtl"};
  s.materials = {{"paint", "", Eigen::Vector3d(0.8, 0.1, 0.1)}, {"skin", "textures/skin.png", Eigen::Vector3d::Ones()}};
  s.uvs.resize(5, 2);
  s.uvs << 0, 0, 1, 0, 0, 1, 0.25, 0.75, 1, 1;
  const Eigen::Index f = r.fine_triangles.rows();
  s.corner_uvs.resize(f, 3);
  s.triangle_materials.resize(static_cast<std::size_t>(f));
  for (Eigen::Index t = 0; t < f; ++t) {
    for (int k = 0; k < 3; ++k) s.corner_uvs(t, k) = static_cast<std::int32_t>((t + k) % 6) - 1;
    s.triangle_materials[static_cast<std::size_t>(t)] = static_cast<std::int32_t>(t % 3) - 1;
  }
  return r;
}

TEST_F(SmallRig, SurfaceAttributesRoundTripInTheirOwnOptionalSection) {
  const Rig with = withSurface(*rig_);
  const std::vector<std::uint8_t> bytes = serializeRig(with);
  EXPECT_EQ(bytes[12], 15u);  // the thirteen, PSNS and UVMT
  const auto [offset, size] = findSection(bytes, "UVMT");
  ASSERT_GT(size, 0u);
  EXPECT_EQ(offset + size, bytes.size());  // the last section here
  const Rig back = parseRig(bytes, "uv.rig");
  EXPECT_EQ(back.surface.asset, with.surface.asset);
  EXPECT_EQ(back.surface.material_libraries, with.surface.material_libraries);
  ASSERT_EQ(back.surface.materials.size(), 2u);
  EXPECT_EQ(back.surface.materials[1].name, "skin");
  EXPECT_EQ(back.surface.materials[1].diffuse_texture, "textures/skin.png");
  EXPECT_EQ(back.surface.materials[0].diffuse_color, Eigen::Vector3d(0.8, 0.1, 0.1));
  EXPECT_EQ(back.surface.uvs, with.surface.uvs);
  EXPECT_EQ(back.surface.corner_uvs, with.surface.corner_uvs);
  EXPECT_EQ(back.surface.triangle_materials, with.surface.triangle_materials);
  EXPECT_EQ(serializeRig(back), bytes);
  // Without them, no section: the file written before it existed.
  EXPECT_EQ(findSection(*bytes_, "UVMT").second, 0u);
  EXPECT_TRUE(parseRig(*bytes_, "plain.rig").surface.empty());
  // A reader that predates the section sees an unknown tag and loads the rest (here: the tag
  // renamed to one this reader does not know either).
  std::vector<std::uint8_t> renamed = bytes;
  for (std::size_t i = 0; i < 15; ++i) {
    if (std::memcmp(renamed.data() + 32 + 24 * i, "UVMT", 4) == 0) std::memcpy(renamed.data() + 32 + 24 * i, "ZZZZ", 4);
  }
  fixChecksum(renamed);
  const Rig older = parseRig(renamed, "older-reader.rig");
  EXPECT_TRUE(older.surface.empty());
  EXPECT_EQ(older.fine_triangles, with.fine_triangles);
  // Materials alone (an OBJ with usemtl but no vt) and uvs alone are fine too.
  Rig materials_only = with;
  materials_only.surface.uvs.resize(0, 2);
  materials_only.surface.corner_uvs.setConstant(-1);
  EXPECT_EQ(parseRig(serializeRig(materials_only), "m.rig").surface.materials.size(), 2u);
  Rig uvs_only = with;
  uvs_only.surface.materials.clear();
  uvs_only.surface.material_libraries.clear();
  std::fill(uvs_only.surface.triangle_materials.begin(), uvs_only.surface.triangle_materials.end(), -1);
  EXPECT_EQ(parseRig(serializeRig(uvs_only), "u.rig").surface.uvs.rows(), 5);
}

TEST_F(SmallRig, SurfaceSectionTruncatedAtEveryLengthOrCorruptIsRefused) {
  const std::vector<std::uint8_t> bytes = serializeRig(withSurface(*rig_));
  const auto [offset, size] = findSection(bytes, "UVMT");
  ASSERT_GT(size, 0u);
  ASSERT_EQ(offset + size, bytes.size());
  std::size_t entry = 0;
  for (std::size_t i = 0; i < 15; ++i) {
    if (std::memcmp(bytes.data() + 32 + 24 * i, "UVMT", 4) == 0) entry = 32 + 24 * i;
  }
  ASSERT_NE(entry, 0u);
  for (std::size_t cut = 0; cut < size; ++cut) {
    std::vector<std::uint8_t> b(bytes.begin(), bytes.begin() + static_cast<std::ptrdiff_t>(offset + cut));
    putU64(b, entry + 16, cut);
    putU64(b, 16, b.size());
    fixChecksum(b);
    const std::string e = parseError(b);
    EXPECT_CONTAINS(e, "section UVMT");
    EXPECT_CONTAINS(e, "truncated");
  }
  // Random bytes of the section behind the checksum: refused naming the file, or a valid rig.
  std::mt19937 rng(77);
  RigParseOptions no_crc;
  no_crc.verify_checksum = false;
  int refused = 0;
  for (int trial = 0; trial < 1000; ++trial) {
    std::vector<std::uint8_t> b = bytes;
    for (int f = 0; f < 2; ++f) b[offset + rng() % size] = static_cast<std::uint8_t>(rng());
    try {
      EXPECT_EQ(validateRig(parseRig(b, "fuzz.rig", no_crc)), "");
    } catch (const RigFileError& e) {
      EXPECT_CONTAINS(e.what(), "fuzz.rig: ");
      ++refused;
    }
  }
  EXPECT_GT(refused, 0);
}

TEST_F(SmallRig, InvalidSurfaceAttributesAreNotWritten) {
  auto fault = [&](auto edit) {
    Rig bad = withSurface(*rig_);
    edit(bad.surface);
    EXPECT_THROW((void)serializeRig(bad), RigFileError);
    return validateRig(bad);
  };
  EXPECT_CONTAINS(fault([](RigSurfaceAttributes& s) { s.corner_uvs(2, 1) = 5; }), "fine triangle 2 names uv 5 of 5");
  EXPECT_CONTAINS(fault([](RigSurfaceAttributes& s) { s.corner_uvs(0, 0) = -2; }), "fine triangle 0 names uv -2 of 5");
  EXPECT_CONTAINS(fault([](RigSurfaceAttributes& s) { s.triangle_materials[3] = 2; }), "fine triangle 3 names material 2 of 2");
  EXPECT_CONTAINS(fault([](RigSurfaceAttributes& s) { s.triangle_materials.pop_back(); }), "triangle materials for");
  EXPECT_CONTAINS(fault([](RigSurfaceAttributes& s) { s.corner_uvs.conservativeResize(s.corner_uvs.rows() - 1, 3); }), "corner rows");
  EXPECT_CONTAINS(fault([](RigSurfaceAttributes& s) { s.uvs(1, 1) = std::numeric_limits<double>::infinity(); }), "a uv is not finite");
  EXPECT_CONTAINS(fault([](RigSurfaceAttributes& s) { s.materials[0].name = "bad\xff"; }), "the name of material 0 is not valid UTF-8");
  EXPECT_CONTAINS(fault([](RigSurfaceAttributes& s) {
                    s.uvs.resize(0, 2);
                    s.materials.clear();
                  }),
                  "without a uv table or materials");
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

TEST(RigDescription, PoseSensorsNameAnOrientedRegionOfTheSameDescription) {
  auto error = [](const std::string& sensors) {
    const std::string json = R"({"region_handles": [
        {"name": "left", "select": {"vertices": [0]}},
        {"name": "right", "select": {"vertices": [1]}},
        {"name": "loose", "select": {"vertices": [2]}, "oriented": false}], "pose_sensors": )" + sensors + "}";
    try {
      (void)rigbuild::parseRigDescription(json, "p.json");
    } catch (const rigbuild::RigBuildError& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  EXPECT_EQ(error(R"([{"sensor": "hydra0", "region": "left"}, {"sensor": "hydra1", "region": "right", "mode": "absolute"}])"), "");
  EXPECT_CONTAINS(error(R"([{"sensor": "hydra1", "region": "right_hand"}])"),
                  "p.json: pose_sensors[0].region: no region handle is named 'right_hand' (region handles: left, right, loose)");
  EXPECT_CONTAINS(error(R"([{"sensor": "hydra1", "region": "loose"}])"), "pose_sensors[0].region: region handle 'loose' is not oriented");
  EXPECT_CONTAINS(error(R"([{"sensor": "hydra0", "region": "left"}, {"sensor": "hydra1", "region": "left"}])"),
                  "pose_sensors[1].region: region handle 'left' is already driven by pose_sensors[0]");
  EXPECT_CONTAINS(error(R"([{"region": "left"}])"), "pose_sensors[0]: needs a sensor");
  EXPECT_CONTAINS(error(R"([{"sensor": "", "region": "left"}])"), "pose_sensors[0].sensor: must not be empty");
  EXPECT_CONTAINS(error(R"([{"sensor": "hydra0"}])"), "pose_sensors[0]: needs a region");
  EXPECT_CONTAINS(error(R"([{"sensor": "hydra0", "region": "left", "mode": "relative"}])"), "pose_sensors[0].mode: expected \"clutch\" or \"absolute\"");
  EXPECT_CONTAINS(error(R"([{"sensor": "hydra0", "region": "left", "clutch_buttons": 0}])"), "pose_sensors[0].clutch_buttons");
  EXPECT_CONTAINS(error(R"([{"sensor": "hydra0", "region": "left", "clutch_buttons": 256}])"), "pose_sensors[0].clutch_buttons");
  EXPECT_CONTAINS(error(R"([{"sensor": "hydra0", "region": "left", "translation_scale": -2}])"), "pose_sensors[0].translation_scale");
  EXPECT_CONTAINS(error(R"([{"sensor": "hydra0", "region": "left", "scale": 2}])"), "pose_sensors[0]: unknown key 'scale'");
  EXPECT_CONTAINS(error(R"({"sensor": "hydra0"})"), "pose_sensors: expected an array");
  const rigbuild::RigDescription d = rigbuild::parseRigDescription(R"({"region_handles": [
        {"name": "a", "select": {"vertices": [0]}}, {"name": "b", "select": {"vertices": [1]}}],
      "pose_sensors": [{"sensor": "hydra1", "region": "b", "mode": "absolute", "clutch_buttons": 6, "translation_scale": 2.5}]})",
                                                                   "p.json");
  ASSERT_EQ(d.pose_sensors.size(), 1u);
  EXPECT_EQ(d.pose_sensors[0].sensor, "hydra1");
  EXPECT_EQ(d.pose_sensors[0].region_index, 1);
  EXPECT_EQ(d.pose_sensors[0].mode, PoseSensorMode::kAbsolute);
  EXPECT_EQ(d.pose_sensors[0].clutch_buttons, 6);
  EXPECT_EQ(d.pose_sensors[0].translation_scale, 2.5);
}

// A region driven by a marker cluster (region_handles[i].markers -> Rig::marker_regions, section
// MKRG): labels resolve to rig marker indices, the section round-trips, and bad clusters stop the
// parse or the build naming the path or the label.
TEST(RigBuild, ARegionDrivenByMarkersIsBuiltSavedAndLoaded) {
  TempDir dir;
  const auto build = [&](const std::string& markers) {
    std::string json = test::smallRigJson();
    const std::string key = R"("oriented": true })";
    json.replace(json.find(key), key.size(), R"("oriented": true, "markers": )" + markers + " }");
    rigbuild::BuildRigInputs in;
    in.mesh = test::writeBlockTetMesh(dir, "block");
    in.description = rigbuild::parseRigDescription(json, dir.path() / "small.json");
    in.clip = test::writeSmallClip(dir);
    return rigbuild::buildRig(in);
  };
  const Rig rig = build(R"(["LEFT", "RIGHT", "FRONT"])");
  ASSERT_EQ(rig.marker_regions.size(), 1u);
  EXPECT_EQ(rig.marker_regions[0].region_handle, 0);
  ASSERT_EQ(rig.marker_regions[0].markers.size(), 3u);
  const std::vector<std::string> labels{"LEFT", "RIGHT", "FRONT"};
  for (std::size_t i = 0; i < 3; ++i) EXPECT_EQ(rig.markers[static_cast<std::size_t>(rig.marker_regions[0].markers[i])].label, labels[i]);
  const std::vector<std::uint8_t> bytes = serializeRig(rig);
  EXPECT_GT(findSection(bytes, "MKRG").second, 0u);
  const Rig back = parseRig(bytes, "mkrg.rig");
  ASSERT_EQ(back.marker_regions.size(), 1u);
  EXPECT_EQ(back.marker_regions[0].region_handle, 0);
  EXPECT_EQ(back.marker_regions[0].markers, rig.marker_regions[0].markers);
  EXPECT_EQ(serializeRig(back), bytes);
  EXPECT_CONTAINS(rigbuild::describeRig(back, 0, false), "markers LEFT RIGHT FRONT drive region 'floor'");
  try {
    (void)build(R"(["LEFT", "RIGHT", "ELBOW"])");
    ADD_FAILURE() << "an unknown marker was accepted";
  } catch (const rigbuild::RigBuildError& e) {
    EXPECT_CONTAINS(std::string(e.what()), "region handle 'floor': marker 'ELBOW' is not a marker of this rig");
  }
  const auto error = [](const std::string& json) {
    try {
      (void)rigbuild::parseRigDescription(json, "m.json");
    } catch (const rigbuild::RigBuildError& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  const std::string region = R"({"region_handles": [{"name": "foot", "select": {"vertices": [0]}, )";
  EXPECT_CONTAINS(error(region + R"("markers": ["A", "B"]}]})"), "region_handles[0].markers: needs at least 3");
  EXPECT_CONTAINS(error(region + R"("markers": ["A", "B", "A"]}]})"), "region_handles[0].markers: names 'A' twice");
  EXPECT_CONTAINS(error(region + R"("oriented": false, "markers": ["A", "B", "C"]}]})"), "must be oriented");
  EXPECT_CONTAINS(error(region + R"("markers": ["A", "B", "C"]}], "pose_sensors": [{"sensor": "hydra0", "region": "foot"}]})"),
                  "pose_sensors[0].region: region handle 'foot' is already driven by its markers");
}

// Volume regions (the description's "volume" list -> DeformerSetup::volume_weights, section VOLW):
// each selected body tet takes its entry's weight (a later entry wins where they overlap), every
// other tet and every invisible tet 0; the section round-trips; a rig without volume regions has no
// VOLW section; bad weights stop the parse, the writer and the loader (behind a valid checksum).
TEST(RigBuild, VolumeRegionsAreBuiltSavedAndLoaded) {
  TempDir dir;
  const auto build = [&](const std::string& volume, bool coarse_level = false, rigbuild::BuildRigReport* report = nullptr) {
    std::string json = test::smallRigJson();
    json.insert(json.rfind('}'), R"(, "volume": )" + volume);
    rigbuild::BuildRigInputs in;
    in.mesh = test::writeBlockTetMesh(dir, "block");
    in.description = rigbuild::parseRigDescription(json, dir.path() / "small.json");
    in.clip = test::writeSmallClip(dir);
    in.coarse_level = coarse_level;
    return rigbuild::buildRig(in, report);
  };
  // The block's left two thirds (x <= 0.2) at 0.6, then its left third (x <= 0.1) at 0.3.
  const Rig rig = build(R"([{"name": "left two thirds", "select": {"box": {"min": [-1, -1, -1], "max": [0.2001, 1, 1]}}, "value": 0.6},
                            {"name": "left third", "select": {"box": {"min": [-1, -1, -1], "max": [0.1001, 1, 1]}}, "value": 0.3}])");
  ASSERT_EQ(rig.setup.volume_weights.size(), static_cast<std::size_t>(rig.tet_mesh.tetCount()));
  int at_third = 0, at_two_thirds = 0;
  for (std::int32_t t = 0; t < rig.tet_mesh.tetCount(); ++t) {
    double max_x = -1.0;
    for (int k = 0; k < 4; ++k) max_x = std::max(max_x, rig.tet_mesh.vertices(rig.tet_mesh.tets(t, k), 0));
    const double expected = t >= rig.body_tet_count ? 0.0 : max_x <= 0.1001 ? 0.3 : max_x <= 0.2001 ? 0.6 : 0.0;
    EXPECT_EQ(rig.setup.volume_weights[static_cast<std::size_t>(t)], expected) << "tet " << t;
    at_third += expected == 0.3;
    at_two_thirds += expected == 0.6;
  }
  EXPECT_EQ(at_third, rig.body_tet_count / 3);  // 4 of the block's 12 cells, 6 tets each
  EXPECT_EQ(at_two_thirds, rig.body_tet_count / 3);
  const std::vector<std::uint8_t> bytes = serializeRig(rig);
  EXPECT_EQ(findSection(bytes, "VOLW").second, 4u + 8u * static_cast<std::size_t>(rig.tet_mesh.tetCount()));  // count, weights
  const Rig back = parseRig(bytes, "volw.rig");
  EXPECT_EQ(back.setup.volume_weights, rig.setup.volume_weights);
  EXPECT_EQ(serializeRig(back), bytes);
  EXPECT_CONTAINS(rigbuild::describeRig(back, 0, false), "volume term:   on " + std::to_string(at_third + at_two_thirds) + " of " +
                                                             std::to_string(rig.tet_mesh.tetCount()) + " tets, weight up to 0.6");
  // A region no tet fills stops the build, but a coarse level (few large tets) goes without it, noted.
  const std::string tiny = R"([{"name": "tiny", "select": {"sphere": {"center": [0.15, 0.1, 0.1], "radius": 0.01}}, "value": 0.5}])";
  try {
    (void)build(tiny);
    ADD_FAILURE() << "an empty volume region was accepted";
  } catch (const rigbuild::RigBuildError& e) {
    EXPECT_CONTAINS(std::string(e.what()), "volume 'tiny': the selection contains no tet vertex");
  }
  rigbuild::BuildRigReport coarse_report;
  EXPECT_TRUE(build(tiny, true, &coarse_report).setup.volume_weights.empty());
  const auto noted = std::find_if(coarse_report.notes.begin(), coarse_report.notes.end(),
                                  [](const std::string& n) { return n.starts_with("volume 'tiny': no coarse tet"); });
  EXPECT_NE(noted, coarse_report.notes.end());
  // Without volume regions: no section, and the description says nothing of a volume term.
  const Rig plain = test::buildSmallRig(dir);
  EXPECT_TRUE(plain.setup.volume_weights.empty());
  EXPECT_EQ(findSection(serializeRig(plain), "VOLW").second, 0u);
  EXPECT_EQ(rigbuild::describeRig(plain, 0, false).find("volume term"), std::string::npos);
  // A weight of 1 (the term alone: no rotation left) or a wrong count is neither written nor loaded.
  Rig bad = rig;
  bad.setup.volume_weights[3] = 1.0;
  EXPECT_CONTAINS(validateRig(bad), "volume weight of tet 3 is not in [0, 1)");
  EXPECT_THROW((void)serializeRig(bad), RigFileError);
  bad.setup.volume_weights.pop_back();
  EXPECT_CONTAINS(validateRig(bad), "volume weights has " + std::to_string(rig.tet_mesh.tetCount() - 1) + " values for");
  std::vector<std::uint8_t> crafted = bytes;
  const std::size_t first_weight = findSection(crafted, "VOLW").first + 4;
  const double too_large = 1.5, nan = std::numeric_limits<double>::quiet_NaN();
  std::memcpy(crafted.data() + first_weight, &too_large, 8);
  fixChecksum(crafted);
  EXPECT_CONTAINS(parseError(crafted), "volume weight of tet 0 is not in [0, 1)");
  std::memcpy(crafted.data() + first_weight, &nan, 8);
  fixChecksum(crafted);
  EXPECT_CONTAINS(parseError(crafted), "section VOLW at byte 12: non-finite value in volume weight");
  const auto error = [](const std::string& volume) {
    try {
      (void)rigbuild::parseRigDescription(R"({"volume": )" + volume + "}", "v.json");
    } catch (const rigbuild::RigBuildError& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  const std::string select = R"({"select": {"vertices": [0]}, )";
  EXPECT_CONTAINS(error("[" + select + R"("value": 1}])"), "v.json: volume[0].value: must be in [0, 1)");
  EXPECT_CONTAINS(error("[" + select + R"("value": -0.1}])"), "volume[0].value: must be in [0, 1)");
  EXPECT_CONTAINS(error(R"([{"select": {"vertices": [0]}}])"), "volume[0]: needs a value");
  EXPECT_CONTAINS(error("[" + select + R"("value": 0.5, "oriented": true}])"), "volume[0]: unknown key 'oriented'");
  EXPECT_EQ(error("[" + select + R"("value": 0}])"), "");
}

TEST(RigBuild, PoseSensorsWithoutAClipTakeTheAlignmentFromTheDescription) {
  const TempDir dir;
  rigbuild::BuildRigInputs in;
  in.mesh = test::writeBlockTetMesh(dir, "block");
  // The floor's vertices lie in one plane, so no tet has four corners there: min_corners 3 (the default is 4).
  const std::string floor =
      R"("region_handles": [ { "name": "floor", "select": { "box": { "min": [-1, -0.01, -1], "max": [1, 0.01, 1] }, "min_corners": 3 } } ])";
  const std::string regions = floor + R"(,
      "pose_sensors": [ { "sensor": "hydra0", "region": "floor", "clutch_buttons": 4, "translation_scale": 0.5 } ])";
  // Axes and unit: device z up -> rig y up, mm -> m.
  in.description = rigbuild::parseRigDescription("{ \"mesh_unit\": \"m\", \"mesh_up\": \"y\", \"markers\": { \"device_up\": \"z\" }, " +
                                                     regions + "}", dir.path() / "r.json");
  rigbuild::BuildRigReport report;
  const Rig rig = rigbuild::buildRig(in, &report);
  ASSERT_EQ(rig.pose_sensors.size(), 1u);
  EXPECT_EQ(rig.pose_sensors[0].sensor_label, "hydra0");
  EXPECT_EQ(rig.pose_sensors[0].region_handle, 0);
  EXPECT_EQ(rig.pose_sensors[0].clutch_buttons, 4);
  EXPECT_EQ(rig.pose_sensors[0].translation_scale, 0.5);
  EXPECT_LT((rig.alignment.apply(Eigen::Vector3d(0, 0, 1000)) - Eigen::Vector3d(0, 1, 0)).norm(), 1e-12);
  EXPECT_NEAR(rig.alignment.linear.determinant(), 1e-9, 1e-21);  // a rotation times 0.001
  EXPECT_TRUE(std::any_of(report.notes.begin(), report.notes.end(),
                          [](const std::string& n) { return n.find("device up z -> rig up y") != std::string::npos; }));
  // An explicit matrix.
  in.description = rigbuild::parseRigDescription(R"({ "mesh_unit": "m", "markers": { "alignment": "matrix",
      "matrix": [0, 0, 0.002, 1,  0.002, 0, 0, 2,  0, 0.002, 0, 3] }, )" + regions + "}", dir.path() / "r.json");
  const Rig m = rigbuild::buildRig(in);
  EXPECT_LT((m.alignment.apply(Eigen::Vector3d(10, 20, 30)) - Eigen::Vector3d(1.06, 2.02, 3.04)).norm(), 1e-12);
  EXPECT_NEAR(m.alignment.fit_scale, 2.0, 1e-12);
  // Without pose sensors a rig without a clip keeps the unit-only alignment it always had.
  in.description = rigbuild::parseRigDescription(R"({ "mesh_unit": "m", "markers": { "device_up": "z" }, )" + floor + "}", dir.path() / "r.json");
  EXPECT_EQ(rigbuild::buildRig(in).alignment.linear, Eigen::Matrix3d(1e-3 * Eigen::Matrix3d::Identity()));
}

TEST(RigBuild, ThePuppetHydraExampleBuilds) {
  // assets/puppet_hydra.json on assets/bar_4x4x33.node: the two ends of the bar as oriented
  // regions, hydra0 on the near end and hydra1 on the far end, clutch on button bit 0x01; bar in
  // cm, the Hydra's mm -> 0.1 cm with the same axes (both y up).
  const std::filesystem::path source(TETRIG_SOURCE_DIR);
  rigbuild::BuildRigInputs in;
  in.mesh = source / "assets" / "bar_4x4x33.node";
  in.description = rigbuild::readRigDescription(source / "assets" / "puppet_hydra.json");
  const Rig rig = rigbuild::buildRig(in);  // also builds the Deformer once (check_deformer)
  ASSERT_EQ(rig.setup.region_handles.size(), 2u);
  EXPECT_EQ(rig.region_handle_names, (std::vector<std::string>{"near_end", "far_end"}));
  for (std::size_t r = 0; r < 2; ++r) {
    const RegionHandle& region = rig.setup.region_handles[r];
    EXPECT_TRUE(region.oriented);
    EXPECT_EQ(region.tets.size(), 4u * 4u * 5u) << "one layer of 4 x 4 cubes, 5 tets each";
    for (const std::int32_t t : region.tets) {
      for (int k = 0; k < 4; ++k) {
        const double z = rig.tet_mesh.vertices(rig.tet_mesh.tets(t, k), 2);
        EXPECT_TRUE(r == 0 ? z <= 1.0 : z >= 32.0) << "region " << r << " tet " << t << " corner z " << z;
      }
    }
  }
  ASSERT_EQ(rig.pose_sensors.size(), 2u);
  EXPECT_EQ(rig.pose_sensors[0].sensor_label, "hydra0");
  EXPECT_EQ(rig.pose_sensors[0].region_handle, 0);
  EXPECT_EQ(rig.pose_sensors[1].sensor_label, "hydra1");
  EXPECT_EQ(rig.pose_sensors[1].region_handle, 1);
  for (const RigPoseSensor& ps : rig.pose_sensors) {
    EXPECT_EQ(ps.mode, PoseSensorMode::kClutch);
    EXPECT_EQ(ps.clutch_buttons, 1);
    EXPECT_EQ(ps.translation_scale, 1.0);
  }
  EXPECT_EQ(rig.unit, "cm");
  EXPECT_LT((rig.alignment.linear - 0.1 * Eigen::Matrix3d::Identity()).norm(), 1e-15);
  // Through the file and back.
  const Rig back = parseRig(serializeRig(rig), "puppet.rig");
  ASSERT_EQ(back.pose_sensors.size(), 2u);
  EXPECT_EQ(back.pose_sensors[1].sensor_label, "hydra1");
  EXPECT_EQ(back.pose_sensors[1].region_handle, 1);
}

TEST(RigBuild, OverlappingHandlesAreRefusedByName) {
  const TempDir dir;
  rigbuild::BuildRigInputs in;
  in.mesh = test::writeBlockTetMesh(dir, "block");
  in.description = rigbuild::parseRigDescription(R"({
    "vertex_handles": [ { "name": "pin", "select": { "vertices": [0] } } ],
    "region_handles": [ { "name": "floor", "select": { "box": { "min": [-1, -0.01, -1], "max": [1, 0.01, 1] }, "min_corners": 3 } } ] })",
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


// ---- layouts docs/rig-format.md forbids: refused even behind a valid checksum ----

struct TableEntry {
  std::size_t at;  // byte offset of the entry in the table
  std::string tag;
  std::size_t offset, size;
};

std::vector<TableEntry> tableEntries(const std::vector<std::uint8_t>& b) {
  std::vector<TableEntry> out;
  const std::uint32_t n = static_cast<std::uint32_t>(b[12]) | (static_cast<std::uint32_t>(b[13]) << 8);
  for (std::uint32_t i = 0; i < n; ++i) {
    const std::size_t at = 32 + 24 * static_cast<std::size_t>(i);
    std::uint64_t offset = 0, size = 0;
    for (int k = 0; k < 8; ++k) {
      offset |= static_cast<std::uint64_t>(b[at + 8 + static_cast<std::size_t>(k)]) << (8 * k);
      size |= static_cast<std::uint64_t>(b[at + 16 + static_cast<std::size_t>(k)]) << (8 * k);
    }
    out.push_back({at, std::string(reinterpret_cast<const char*>(b.data() + at), 4), static_cast<std::size_t>(offset),
                   static_cast<std::size_t>(size)});
  }
  std::sort(out.begin(), out.end(), [](const TableEntry& a, const TableEntry& c) { return a.offset < c.offset; });
  return out;
}

// The fixture's bytes after `edit`, with the checksum recomputed: only the edit can trip the loader.
template <typename Edit>
std::string errorAfter(const std::vector<std::uint8_t>& bytes, Edit edit) {
  std::vector<std::uint8_t> b = bytes;
  edit(b);
  fixChecksum(b);
  return parseError(b);
}

TEST_F(SmallRig, ForbiddenLayoutsAreRefusedBehindAValidChecksum) {
  const std::vector<TableEntry> sections = tableEntries(*bytes_);  // in file order
  ASSERT_EQ(sections.size(), 14u);
  ASSERT_EQ(sections.front().offset, 32u + 14u * 24u);     // right after the table
  ASSERT_EQ(sections.back().offset + sections.back().size, bytes_->size());  // the last ends the file
  const TableEntry& first = sections[0];
  const TableEntry& second = sections[1];
  const TableEntry& last = sections.back();
  EXPECT_EQ(errorAfter(*bytes_, [](std::vector<std::uint8_t>&) {}), "");

  // Overlapping sections: the first grown by 8 bytes into the second, or the second moved onto the first.
  std::string e = errorAfter(*bytes_, [&](std::vector<std::uint8_t>& b) { putU64(b, first.at + 16, first.size + 8); });
  EXPECT_CONTAINS(e, "section " + second.tag + " (bytes " + std::to_string(second.offset));
  EXPECT_CONTAINS(e, "overlaps section " + first.tag + ", which ends at byte " + std::to_string(first.offset + first.size + 8));
  e = errorAfter(*bytes_, [&](std::vector<std::uint8_t>& b) { putU64(b, second.at + 8, first.offset); });
  EXPECT_CONTAINS(e, "overlaps section ");
  // A section starting off an 8-byte boundary (the last one, 4 bytes later and 4 bytes shorter).
  e = errorAfter(*bytes_, [&](std::vector<std::uint8_t>& b) {
    putU64(b, last.at + 8, last.offset + 4);
    putU64(b, last.at + 16, last.size - 4);
  });
  EXPECT_CONTAINS(e, "section " + last.tag + " starts at byte " + std::to_string(last.offset + 4) + ", not on an 8-byte boundary");
  // Bytes after the last section (zeros, and a partial word), with the header's file size matching.
  for (const std::size_t extra : {std::size_t{8}, std::size_t{3}}) {
    e = errorAfter(*bytes_, [&](std::vector<std::uint8_t>& b) {
      b.resize(b.size() + extra, 0);
      putU64(b, 16, b.size());
    });
    EXPECT_CONTAINS(e, std::to_string(extra) + " bytes after the last section (section " + last.tag + " ends at byte " +
                           std::to_string(bytes_->size()) + ", the file at " + std::to_string(bytes_->size() + extra) + ")");
  }
  // A gap of a whole word before the last section (more than alignment padding).
  e = errorAfter(*bytes_, [&](std::vector<std::uint8_t>& b) {
    b.insert(b.begin() + static_cast<std::ptrdiff_t>(last.offset), 8, 0);
    putU64(b, last.at + 8, last.offset + 8);
    putU64(b, 16, b.size());
  });
  EXPECT_CONTAINS(e, "section " + last.tag + " (bytes " + std::to_string(last.offset + 8));
  EXPECT_CONTAINS(e, "only the zero padding up to the next 8-byte boundary");
  // Padding that is not zero.
  std::size_t padding_at = 0;
  std::string padded_tag;
  for (std::size_t i = 1; i < sections.size() && padding_at == 0; ++i) {
    const std::size_t end = sections[i - 1].offset + sections[i - 1].size;
    if (sections[i].offset > end) {
      padding_at = end;
      padded_tag = sections[i].tag;
    }
  }
  ASSERT_NE(padding_at, 0u) << "the fixture has no padded section";
  EXPECT_EQ((*bytes_)[padding_at], 0);
  e = errorAfter(*bytes_, [&](std::vector<std::uint8_t>& b) { b[padding_at] = 0x5A; });
  EXPECT_CONTAINS(e, "padding byte " + std::to_string(padding_at) + " before section " + padded_tag);
  EXPECT_CONTAINS(e, "is not 0");
  // A non-zero reserved word: in a section table entry, and in the header.
  e = errorAfter(*bytes_, [&](std::vector<std::uint8_t>& b) { putU32(b, second.at + 4, 7); });
  EXPECT_CONTAINS(e, "(" + second.tag + "): reserved word is 7, not 0");
  e = errorAfter(*bytes_, [&](std::vector<std::uint8_t>& b) { putU32(b, 28, 1); });
  EXPECT_CONTAINS(e, "reserved header word is not 0");
  // A tag that is not four printable ASCII characters (an unknown tag would be skipped otherwise).
  e = errorAfter(*bytes_, [&](std::vector<std::uint8_t>& b) { b[last.at + 2] = 0x1B; });
  EXPECT_CONTAINS(e, "the tag is not four printable ASCII characters");
  // An unknown tag of printable characters is a section like any other: skipped.
  std::vector<std::uint8_t> unknown = *bytes_;
  std::memcpy(unknown.data() + last.at, "ZZZZ", 4);
  fixChecksum(unknown);
  EXPECT_TRUE(parseRig(unknown, "unknown.rig").pose_sensors.empty());  // PSNS unknown now: no pose sensors
}

TEST_F(SmallRig, BoundFaceCountsMustBeTheInvisibleTets) {
  // MARK: u32 n, then per marker str label, i32 tet vertex, i32 vertex handle, 3 f64, i32 bound faces, f64 distance.
  const auto [offset, size] = findSection(*bytes_, "MARK");
  ASSERT_GT(size, 0u);
  const RigMarker& m0 = rig_->markers[0];
  const std::size_t bound_at = offset + 4 + 4 + m0.label.size() + 4 + 4 + 24;
  ASSERT_EQ(static_cast<std::int32_t>(bytes_->at(bound_at)), m0.bound_faces);
  const std::string who = "marker 0 (" + m0.label + ")";
  EXPECT_CONTAINS(errorAfter(*bytes_, [&](std::vector<std::uint8_t>& b) { putU32(b, bound_at, 0xFFFFFFFFu); }),
                  who + " has a negative bound-face count (-1)");
  EXPECT_CONTAINS(errorAfter(*bytes_, [&](std::vector<std::uint8_t>& b) { putU32(b, bound_at, static_cast<std::uint32_t>(m0.bound_faces + 1)); }),
                  who + " says " + std::to_string(m0.bound_faces + 1) + " bound faces but " + std::to_string(m0.bound_faces) +
                      " invisible tets join it to the body");
  EXPECT_CONTAINS(errorAfter(*bytes_, [&](std::vector<std::uint8_t>& b) { putU32(b, bound_at, 0); }), who + " says 0 bound faces");
}

TEST_F(SmallRig, StringsMustBeUtf8) {
  // META: str name ("small block") first: one byte of it replaced keeps every size.
  const auto [offset, size] = findSection(*bytes_, "META");
  ASSERT_EQ(rig_->name, "small block");
  EXPECT_CONTAINS(errorAfter(*bytes_, [&](std::vector<std::uint8_t>& b) { b[offset + 4 + 5] = 0xFF; }),
                  "the rig name is not valid UTF-8 ('small\\xffblock')");
  // Well-formed UTF-8, even with control characters, loads (printing escapes them).
  std::vector<std::uint8_t> b = *bytes_;
  b[offset + 4 + 5] = 0x1B;
  fixChecksum(b);
  EXPECT_EQ(parseRig(b, "esc.rig").name, "small\x1b" "block");
  auto fault = [&](auto edit) {
    Rig bad = *rig_;
    edit(bad);
    EXPECT_THROW((void)serializeRig(bad), RigFileError);
    return validateRig(bad);
  };
  EXPECT_CONTAINS(fault([](Rig& r) { r.unit = "m\xc3"; }), "the unit is not valid UTF-8");
  EXPECT_CONTAINS(fault([](Rig& r) { r.region_handle_names[0] = "fl\xed\xa0\x80oor"; }), "the name of region handle 0 is not valid UTF-8");
  EXPECT_CONTAINS(fault([](Rig& r) { r.rigid_group_names[0] = "\x9b"; }), "the name of rigid group 0 is not valid UTF-8 ('\\x9b')");
  EXPECT_CONTAINS(fault([](Rig& r) { r.point_handle_names[0] = "\xc0\xaf"; }), "the name of point handle 0 is not valid UTF-8");
  EXPECT_CONTAINS(fault([](Rig& r) { r.markers[2].label = "H\xfc" "fte"; }), "marker 2 (H\\xfcfte): the label is not valid UTF-8");
  EXPECT_CONTAINS(fault([](Rig& r) { r.pose_sensors[0].sensor_label = "hydra\xff"; }), "the label of pose sensor 0 is not valid UTF-8");
  EXPECT_CONTAINS(fault([](Rig& r) { r.alignment.device_up = "up\xff"; }), "the device up axis is not valid UTF-8");
}

TEST_F(SmallRig, MarkerVerticesAndInvisibleTetsFollowTheLayout) {
  // TETV: body vertices first, then one per marker; TETS: body tets first, then invisible tets of
  // three body corners and one marker; labels non-empty and distinct; B's rows sum to 1.
  auto fault = [&](auto edit) {
    Rig bad = *rig_;
    edit(bad);
    EXPECT_THROW((void)serializeRig(bad), RigFileError);
    return validateRig(bad);
  };
  EXPECT_CONTAINS(fault([](Rig& r) { r.body_vertex_count -= 1; }), "the tet mesh has 6 vertices after its 35 body vertices but the rig has 5 markers");
  EXPECT_CONTAINS(fault([](Rig& r) {
                    r.markers[0].tet_vertex = 0;
                    r.setup.vertex_handles[static_cast<std::size_t>(r.markers[0].vertex_handle)] = 0;
                  }),
                  "marker 0 (TOP) names tet vertex 0, not a marker vertex (36..40)");
  EXPECT_CONTAINS(fault([](Rig& r) {
                    r.markers[1].tet_vertex = r.markers[0].tet_vertex;
                    r.markers[1].vertex_handle = r.markers[0].vertex_handle;
                  }),
                  "marker 1 (LEFT) and marker 0 name the same tet vertex 36");
  EXPECT_CONTAINS(fault([](Rig& r) { r.markers[3].label = r.markers[1].label; }), "marker 3 (LEFT) has the label of marker 1: labels must be distinct");
  EXPECT_CONTAINS(fault([](Rig& r) { r.markers[4].label.clear(); }), "marker 4 has an empty label");
  EXPECT_CONTAINS(fault([](Rig& r) { r.body_tet_count += 1; }), "body tet 72 names marker vertex");
  EXPECT_CONTAINS(fault([](Rig& r) { r.body_tet_count -= 1; }), "invisible tet 71 has 0 marker corners, not 1");
  EXPECT_CONTAINS(fault([](Rig& r) { r.pose_transfer.weights[0] += 0.5; }), "pose transfer B: row 0 sums to 1.5");
  EXPECT_CONTAINS(fault([](Rig& r) { r.alignment.fit_scale = 0.0; }), "fit scale or unit conversion is not positive");
  EXPECT_CONTAINS(fault([](Rig& r) { r.alignment.rig_units_per_mm = -1e-3; }), "fit scale or unit conversion is not positive");
}

// ---- terminal safety: text from a file never reaches the terminal raw ----

using CliRun = test::CommandRun;

CliRun runTetrig(const std::string& args, const TempDir& dir) { return test::runCommand(TETRIG_EXE, args, dir.path()); }

// Bytes a terminal acts on: C0 controls other than the line ends, DEL, C1 (raw or in UTF-8), and
// anything that is not UTF-8.
void expectTerminalSafe(const std::string& text) {
  EXPECT_TRUE(isWellFormedUtf8(text)) << printableText(text);
  for (std::size_t i = 0; i < text.size(); ++i) {
    const auto b = static_cast<unsigned char>(text[i]);
    EXPECT_FALSE((b < 0x20 && b != '\n') || b == 0x7F) << "byte " << int(b) << " at " << i << " in: " << printableText(text);
    if (b == 0xC2 && i + 1 < text.size()) {
      EXPECT_GT(static_cast<unsigned char>(text[i + 1]), 0x9F) << printableText(text);
    }
  }
}

Rig hostileRig(const Rig& base) {
  Rig evil = base;
  evil.name = "evil\x1b[2J\nname";
  evil.unit = "m\x1b]0;pwned\x07";
  evil.builder = "tetrig\r\x1b[1A";
  evil.region_handle_names[0] = "floor\xc2\x9b" "31m";  // U+009B (CSI) in UTF-8
  evil.rigid_group_names[0] = "core\xe2\x80\xae";      // right-to-left override
  evil.point_handle_names[0] = "in\x7fside";
  evil.markers[0].label = "TOP\x1b[8m";
  evil.pose_sensors[0].sensor_label = "hydra\x1b[5m1";
  evil.alignment.device_up = "y\x1b[0m";
  return evil;
}

TEST_F(SmallRig, InspectEscapesTheFilesText) {
  const TempDir dir;
  const Rig evil = hostileRig(*rig_);
  ASSERT_EQ(validateRig(evil), "");  // well-formed UTF-8: a valid rig, whatever its names hold
  const std::filesystem::path path = dir.path() / "evil.rig";
  rigbuild::writeFileAtomically(path, serializeRig(evil));
  const CliRun r = runTetrig("inspect '" + path.string() + "' --markers", dir);
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_CONTAINS(r.out, "rig:           evil\\x1b[2J\\nname\n");
  EXPECT_CONTAINS(r.out, "built by:      tetrig\\r\\x1b[1A (format version 1)");
  EXPECT_CONTAINS(r.out, "unit:          m\\x1b]0;pwned\\x07, up axis y");
  EXPECT_CONTAINS(r.out, "region handle 'floor\\xc2\\x9b31m'");
  EXPECT_CONTAINS(r.out, "rigid group 'core\\xe2\\x80\\xae'");
  EXPECT_CONTAINS(r.out, "point handle 'in\\x7fside'");
  EXPECT_CONTAINS(r.out, "pose sensor 'hydra\\x1b[5m1' drives region 'floor\\xc2\\x9b31m'");
  EXPECT_CONTAINS(r.out, "  TOP\\x1b[8m ");
  EXPECT_CONTAINS(r.out, "device mm (up y\\x1b[0m) -> rig m\\x1b]0;pwned\\x07");
  expectTerminalSafe(r.out);
  // The name's newline did not make a line: as many lines as the plain rig's summary.
  const std::string plain = rigbuild::describeRig(*rig_, 0, true);
  EXPECT_EQ(std::count(r.out.begin(), r.out.end(), '\n'), std::count(plain.begin(), plain.end(), '\n'));
}

TEST_F(SmallRig, DescribeEscapesMalformedTextAndCutsLongNames) {
  // A rig in memory (not from a file) may hold anything: bytes that are not UTF-8 are escaped too.
  Rig odd = *rig_;
  odd.name = std::string(1000, 'n');
  odd.region_handle_names[0] = "raw\x9b" "csi\xff";
  const std::string text = rigbuild::describeRig(odd, 0, true);
  EXPECT_CONTAINS(text, "rig:           " + std::string(256, 'n') + "... (1000 bytes)\n");
  EXPECT_CONTAINS(text, "region handle 'raw\\x9bcsi\\xff'");
  expectTerminalSafe(text);
}

TEST(TerminalSafety, ErrorsEscapeTheFilesText) {
  // A JSON key holding an escape sequence ("\u001b" decodes to ESC): the one-line error shows it escaped.
  const TempDir dir;
  const std::filesystem::path json = dir.write("evil.json", R"({"\u001b[2J\u009b": 1})");
  const std::string out = (dir.path() / "x.rig").string();
  const CliRun r = runTetrig("build-rig --mesh /nonexistent/m.obj --rig '" + json.string() + "' --out '" + out + "' --quiet", dir);
  EXPECT_NE(r.status, 0);
  EXPECT_EQ(r.err.rfind("tetrig build-rig: error: ", 0), 0u) << r.err;
  EXPECT_CONTAINS(r.err, "unknown key '\\x1b[2J\\xc2\\x9b'");
  EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
  expectTerminalSafe(r.err);
  EXPECT_FALSE(std::filesystem::exists(out));
}

// ---- rig description integers: the full value is range-checked, never cast first ----

struct IntegerField {
  std::string path;                     // JSON path in messages
  std::function<std::string(const std::string&)> json;  // a description with the value in place
  std::int64_t lo, hi;
  std::function<std::int64_t(const rigbuild::RigDescription&)> read;
};

std::vector<IntegerField> integerFields() {
  using D = rigbuild::RigDescription;
  const std::string region = R"("region_handles": [{"name": "r", "select": {"vertices": [0]}}])";
  const std::int64_t i32_max = std::numeric_limits<std::int32_t>::max(), i32_min = std::numeric_limits<std::int32_t>::min();
  return {
      {"deformer.rotation_steps", [](const std::string& v) { return R"({"deformer": {"rotation_steps": )" + v + "}}"; }, 0, 64,
       [](const D& d) { return std::int64_t{d.rotation_steps}; }},
      {"tet_vertices", [](const std::string& v) { return R"({"tet_vertices": )" + v + "}"; }, 4, 10'000'000,
       [](const D& d) { return std::int64_t{d.tet_vertices}; }},
      {"pose_transfer.max_nonzeros_per_row", [](const std::string& v) { return R"({"pose_transfer": {"max_nonzeros_per_row": )" + v + "}}"; },
       0, i32_max, [](const D& d) { return std::int64_t{d.pose_max_nonzeros}; }},
      {"vertex_handles[0].select.vertices[0]",
       [](const std::string& v) { return R"({"vertex_handles": [{"select": {"vertices": [)" + v + "]}}]}"; }, 0, i32_max,
       [](const D& d) { return std::int64_t{d.vertex_handles[0].select.vertices[0]}; }},
      {"vertex_handles[0].select.sel_values[0]",
       [](const std::string& v) { return R"({"vertex_handles": [{"select": {"sel_file": "a.sel", "sel_values": [)" + v + "]}}]}"; },
       i32_min, i32_max, [](const D& d) { return std::int64_t{d.vertex_handles[0].select.sel_values[0]}; }},
      {"region_handles[0].select.min_corners",
       [](const std::string& v) { return R"({"region_handles": [{"select": {"vertices": [0], "min_corners": )" + v + "}}]}"; }, 1, 4,
       [](const D& d) { return std::int64_t{d.region_handles[0].select.min_corners}; }},
      {"markers.frame", [](const std::string& v) { return R"({"markers": {"frame": )" + v + "}}"; }, 0, 100'000'000,
       [](const D& d) { return d.markers.frame; }},
      {"markers.icp_iterations", [](const std::string& v) { return R"({"markers": {"icp_iterations": )" + v + "}}"; }, 0, 10000,
       [](const D& d) { return std::int64_t{d.markers.icp_iterations}; }},
      {"markers.faces_per_marker", [](const std::string& v) { return R"({"markers": {"faces_per_marker": )" + v + "}}"; }, 1, 16,
       [](const D& d) { return std::int64_t{d.markers.faces_per_marker}; }},
      {"pose_sensors[0].clutch_buttons",
       [region](const std::string& v) { return "{" + region + R"(, "pose_sensors": [{"sensor": "h", "region": "r", "clutch_buttons": )" + v + "}]}"; },
       1, 255, [](const D& d) { return std::int64_t{d.pose_sensors[0].clutch_buttons}; }},
  };
}

std::string descriptionError(const std::string& json) {
  try {
    (void)rigbuild::parseRigDescription(json, "i.json");
  } catch (const rigbuild::RigBuildError& e) {
    return e.what();
  }
  return {};
}

TEST(RigDescription, IntegersAreRangeCheckedOnTheFullValue) {
  // The issue's case: 4294967298 cast to int is 2, which was accepted as 2 rotation steps.
  EXPECT_CONTAINS(descriptionError(R"({"deformer": {"rotation_steps": 4294967298}})"),
                  "i.json: deformer.rotation_steps: expected an integer in [0, 64], got 4294967298");
  for (const IntegerField& f : integerFields()) {
    SCOPED_TRACE(f.path);
    const std::string expected = "i.json: " + f.path + ": expected an integer in [" + std::to_string(f.lo) + ", " + std::to_string(f.hi) + "]";
    // Both ends of the range are read exactly.
    for (const std::int64_t v : {f.lo, f.hi}) {
      const std::string json = f.json(std::to_string(v));
      ASSERT_EQ(descriptionError(json), "") << json;
      EXPECT_EQ(f.read(rigbuild::parseRigDescription(json, "i.json")), v);
    }
    // Values whose low 32 bits (or whose wrap to 64 bits) land inside the range, and values just outside it.
    const std::vector<std::string> refused = {
        std::to_string(f.lo + (std::int64_t{1} << 32)), std::to_string(f.hi + (std::int64_t{1} << 32)),
        std::to_string(f.lo - 1), std::to_string(f.hi + 1),
        "18446744073709551615",                              // 2^64 - 1: -1 as int64
        std::to_string((std::uint64_t{1} << 63) + static_cast<std::uint64_t>(f.lo)),  // wraps to a negative int64
        "-9223372036854775808"};
    for (const std::string& v : refused) {
      const std::string e = descriptionError(f.json(v));
      EXPECT_CONTAINS(e, expected);
      EXPECT_CONTAINS(e, "got " + v);
    }
    // Numbers that are not integers, and integers beyond 64 bits (read as floating point).
    for (const std::string v : {"2.5", "2.0", "1e1", "-0.5", "18446744073709551616", "1e300"}) {
      const std::string e = descriptionError(f.json(v));
      EXPECT_CONTAINS(e, expected);
      EXPECT_CONTAINS(e, "write integers without a fraction or exponent");
    }
    for (const std::string v : {"true", "null", "[1]"}) EXPECT_CONTAINS(descriptionError(f.json(v)), expected);
  }
  EXPECT_CONTAINS(descriptionError(R"({"deformer": {"rotation_steps": "3"}})"), "deformer.rotation_steps: expected an integer in [0, 64]");
  EXPECT_CONTAINS(descriptionError(R"({"pose_transfer": {"max_nonzeros_per_row": 3}})"),
                  "pose_transfer.max_nonzeros_per_row: must be 0 (no cap) or at least 4");
  EXPECT_EQ(descriptionError(R"({"version": 1})"), "");
  for (const std::string v : {"4294967297", "18446744073709551617", "1.0", "2"}) {
    EXPECT_CONTAINS(descriptionError(R"({"version": )" + v + "}"), "i.json: version: ");
  }
}

}  // namespace
}  // namespace tetrig
