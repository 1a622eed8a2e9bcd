// Marker alignment a user can trust, on generated data (t_shape_rig.hpp: a T-pose body and clips of
// it in device millimetres): the plausibility checks (alignment_checks.hpp) refuse an arms-down
// frame and a body of another size and accept the mesh's pose; --frame auto
// (rest_frame_search.hpp) finds the T-pose frames of a clip that starts arms down and says clearly
// when no frame fits; the marker distance limit follows the mesh's size; a rig without handles
// stops before the mesh is read; region selections default to min_corners 4; inspect prints no
// alignment for a rig without markers. The real-data counterparts are in test_rig_markers_real.cpp.
#include "t_shape_rig.hpp"
#include "tetrig/rigbuild/alignment_checks.hpp"
#include "tetrig/tet_mesh.hpp"
#include "tetrig/rigbuild/build_rig.hpp"
#include "tetrig/rigbuild/closest_point.hpp"
#include "tetrig/rigbuild/describe_rig.hpp"
#include "tetrig/rigbuild/rest_frame_search.hpp"
#include "tetrig/tet_mesh_io.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

namespace tetrig {
namespace {

using test::LabelledPoints;
using test::TempDir;

#define EXPECT_CONTAINS(haystack, needle) \
  EXPECT_NE(std::string(haystack).find(needle), std::string::npos) << "text: " << (haystack)
#define EXPECT_NOT_CONTAINS(haystack, needle) \
  EXPECT_EQ(std::string(haystack).find(needle), std::string::npos) << "text: " << (haystack)

// Diagonal of the T's bounding box [-0.9, 0.9] x [0, 1.8] x [-0.1, 0.1].
const double kTDiagonal = std::sqrt(1.8 * 1.8 + 1.8 * 1.8 + 0.2 * 0.2);

std::vector<LabelledPoints> repeat(const LabelledPoints& pose, std::size_t n) { return std::vector<LabelledPoints>(n, pose); }

rigbuild::BuildRigInputs tInputs(const TempDir& dir, const std::filesystem::path& clip) {
  rigbuild::BuildRigInputs in;
  in.mesh = test::writeTTetMesh(dir, "t");
  in.clip = clip;
  in.check_deformer = false;
  return in;
}

std::string buildError(const rigbuild::BuildRigInputs& in) {
  try {
    (void)rigbuild::buildRig(in);
  } catch (const rigbuild::RigBuildError& e) {
    return e.what();
  }
  return {};
}

bool hasNote(const rigbuild::BuildRigReport& report, const std::string& text) {
  return std::any_of(report.notes.begin(), report.notes.end(), [&](const std::string& n) { return n.find(text) != std::string::npos; });
}

// The T's surface (boundary of its tet mesh, tets oriented as the builder does) for direct checks.
rigbuild::SurfaceMesh tSurface(const TempDir& dir) {
  TetMesh tets = readTetGen(test::writeTTetMesh(dir, "t"));
  for (std::int32_t t = 0; t < tets.tetCount(); ++t) {
    if (signedVolume(tets, t) < 0) std::swap(tets.tets(t, 2), tets.tets(t, 3));
  }
  rigbuild::SurfaceMesh s;
  s.vertices = tets.vertices;
  s.triangles = boundaryFaces(tets);
  return s;
}

TEST(AlignmentChecks, TheMeshPosePassesEveryCheck) {
  const TempDir dir;
  rigbuild::BuildRigReport report;
  const Rig rig = rigbuild::buildRig(tInputs(dir, test::writeTClip(dir, "t.c3d", repeat(test::tPoseMarkers(), 3))), &report);
  ASSERT_EQ(rig.markers.size(), 17u);
  ASSERT_TRUE(report.alignment_check.has_value());
  const rigbuild::AlignmentCheck& c = *report.alignment_check;
  EXPECT_TRUE(c.ok()) << c.summary();
  EXPECT_NEAR(c.fit_scale, 1.0, 0.03);
  EXPECT_LT(std::abs(c.up.gap_lo), 0.03);
  EXPECT_LT(std::abs(c.up.gap_hi), 0.03);
  EXPECT_LT(std::abs(c.across.gap_lo), 0.03);
  EXPECT_LT(std::abs(c.across.gap_hi), 0.03);
  EXPECT_EQ(c.far_markers, 0);
  EXPECT_LT(c.max_distance, 0.03);
  EXPECT_TRUE(hasNote(report, "alignment checks: fit scale"));
  EXPECT_EQ(report.rest_frame, 0);
  // The relative default limit: 6 % of the mesh's diagonal.
  EXPECT_NEAR(report.marker_distance_limit, 0.06 * kTDiagonal, 1e-12);
}

TEST(AlignmentChecks, AnArmsDownFrameIsRefusedAsAPoseMismatch) {
  const TempDir dir;
  const std::filesystem::path clip = test::writeTClip(dir, "down.c3d", repeat(test::armsDownMarkers(), 2));
  rigbuild::BuildRigInputs in = tInputs(dir, clip);
  const std::string e = buildError(in);
  EXPECT_CONTAINS(e, clip.string() + ": frame 0: the marker alignment is implausible: ");
  EXPECT_CONTAINS(e, "along the mesh's widest horizontal axis the outermost markers");
  EXPECT_CONTAINS(e, "not in the mesh's rest pose");
  EXPECT_CONTAINS(e, "--frame auto");
  EXPECT_CONTAINS(e, "--accept-pose-mismatch");
  EXPECT_NOT_CONTAINS(e, "fit scale");  // the size fits; only the pose does not
  // Asked to, the build goes on and says what it accepted.
  in.accept_pose_mismatch = true;
  rigbuild::BuildRigReport report;
  const Rig rig = rigbuild::buildRig(in, &report);
  EXPECT_EQ(rig.markers.size(), 17u);
  ASSERT_TRUE(report.alignment_check.has_value());
  EXPECT_FALSE(report.alignment_check->pose_failures.empty());
  EXPECT_GT(report.alignment_check->across.gap_lo, 0.25);
  EXPECT_GT(report.alignment_check->across.gap_hi, 0.25);
  EXPECT_TRUE(hasNote(report, "implausible alignment accepted as asked: along the mesh's widest horizontal axis"));
  in.accept_pose_mismatch = false;
  in.accept_implausible_alignment = true;
  EXPECT_EQ(buildError(in), "");
  // The limit is configurable in the description.
  in.accept_implausible_alignment = false;
  in.description = rigbuild::parseRigDescription(R"({"markers": {"checks": {"max_extent_gap": 0.45, "max_far_fraction": 1}}})", dir.path() / "r.json");
  EXPECT_EQ(buildError(in), "");
  in.description = rigbuild::parseRigDescription(R"({"markers": {"checks": {"pose": false}}})", dir.path() / "r.json");
  EXPECT_EQ(buildError(in), "");
}

TEST(AlignmentChecks, ABodyOfAnotherSizeIsRefusedByTheFitScale) {
  const TempDir dir;
  // A T-pose clip of a body half the mesh's size: it fits only when scaled by 2.
  rigbuild::BuildRigInputs in = tInputs(dir, test::writeTClip(dir, "half.c3d", repeat(test::tPoseMarkers(), 2), 0.5));
  const std::string e = buildError(in);
  EXPECT_CONTAINS(e, "frame 0: the marker alignment is implausible: fit scale 1.9");  // 1.96: the markers sit outside the skin
  EXPECT_CONTAINS(e, " is outside 0.85..1.18");
  EXPECT_CONTAINS(e, "check the mesh's unit (taken as m: the mesh is 1.8 m tall, the markers span 89");
  EXPECT_NOT_CONTAINS(e, "widest horizontal axis");  // the pose fits
  in.min_fit_scale = 3.0;
  in.max_fit_scale = 2.5;
  EXPECT_CONTAINS(buildError(in), "the fit scale range 3..2.5 is empty: --min-fit-scale must be positive and at most --max-fit-scale");
  in.min_fit_scale.reset();
  rigbuild::BuildRigReport report;
  (void)rigbuild::buildRig(in, &report);
  ASSERT_TRUE(report.alignment_check.has_value());
  EXPECT_NEAR(report.alignment_check->fit_scale, 2.0, 0.05);
  EXPECT_TRUE(report.alignment_check->ok());
  // A mesh in another unit than declared: the same T in centimetres read as metres.
  rigbuild::BuildRigInputs cm = tInputs(dir, test::writeTClip(dir, "t.c3d", repeat(test::tPoseMarkers(), 2)));
  cm.mesh = test::writeTTetMesh(dir, "t_cm", 100.0);
  const std::string as_metres = buildError(cm);
  EXPECT_CONTAINS(as_metres, "the marker alignment is implausible: fit scale 97.8 is outside 0.85..1.18");
  EXPECT_CONTAINS(as_metres, "taken as m: the mesh is 180 m tall, the markers span 1785 mm");
  cm.description.mesh_unit = "cm";
  EXPECT_EQ(buildError(cm), "");
}

// --mesh-unit auto with markers: the unit that makes the mesh about as tall as the performer's
// markers (a 180-unit body is centimetres, not millimetres); without markers, the height alone.
TEST(AlignmentChecks, AutoMeshUnitFollowsThePerformersHeight) {
  const TempDir dir;
  const std::filesystem::path clip = test::writeTClip(dir, "t.c3d", repeat(test::tPoseMarkers(), 2));
  for (const auto& [scale, unit] : {std::pair{1.0, "m"}, std::pair{100.0, "cm"}, std::pair{1000.0, "mm"}}) {
    SCOPED_TRACE(unit);
    rigbuild::BuildRigInputs in = tInputs(dir, clip);
    in.mesh = test::writeTTetMesh(dir, std::string("t_") + unit, scale);
    in.description.mesh_unit = "auto";
    rigbuild::BuildRigReport report;
    const Rig rig = rigbuild::buildRig(in, &report);
    EXPECT_EQ(rig.unit, unit);
    EXPECT_TRUE(hasNote(report, std::string("mesh unit taken as ") + unit + ": the mesh is ")) << report.notes.size();
    EXPECT_TRUE(hasNote(report, "the performer's markers 17"));
    ASSERT_TRUE(report.alignment_check.has_value());
    EXPECT_TRUE(report.alignment_check->ok());
  }
}

TEST(AlignmentChecks, CheckAlignmentMeasuresEachCriterion) {
  const TempDir dir;
  const rigbuild::SurfaceMesh surface = tSurface(dir);
  const LabelledPoints markers = test::tPoseMarkers();
  std::vector<Eigen::Vector3d> positions;
  std::vector<std::string> labels;
  for (const auto& [label, p] : markers) {
    labels.push_back(label);
    positions.push_back(p);
  }
  std::vector<double> distances(markers.size(), 0.015);
  const rigbuild::AlignmentCheckLimits limits;
  rigbuild::AlignmentCheck c = rigbuild::checkAlignment(surface, "y", positions, distances, labels, 1.0, limits);
  EXPECT_TRUE(c.ok()) << c.summary();
  // Up: the toes 3 cm above the bottom, the head marker 1.5 cm above the top (beyond: negative).
  EXPECT_EQ(c.up.label_lo, "LTOE");
  EXPECT_NEAR(c.up.gap_lo, 0.03 / 1.8, 1e-9);
  EXPECT_EQ(c.up.label_hi, "HEAD");
  EXPECT_NEAR(c.up.gap_hi, -0.015 / 1.8, 1e-9);
  // Across: the arms (x), the hand markers 1.5 cm beyond each end.
  EXPECT_GT(std::abs(c.across.axis.x()), 0.999);
  EXPECT_NEAR(c.across.gap_lo, -0.015 / 1.8, 1e-4);  // the axis leans by a hair: the Kuhn faces are not symmetric
  EXPECT_NEAR(c.across.gap_hi, -0.015 / 1.8, 1e-4);
  EXPECT_NEAR(c.diagonal, kTDiagonal, 1e-9);
  // Fit scale: both ends of the range pass, just outside fails.
  for (const double s : {0.85, 1.18}) EXPECT_TRUE(rigbuild::checkAlignment(surface, "y", positions, distances, labels, s, limits).ok()) << s;
  for (const double s : {0.849, 1.181}) {
    c = rigbuild::checkAlignment(surface, "y", positions, distances, labels, s, limits);
    ASSERT_EQ(c.scale_failures.size(), 1u) << s;
    EXPECT_CONTAINS(c.scale_failures[0], "is outside 0.85..1.18");
    EXPECT_TRUE(c.pose_failures.empty());
  }
  // Far markers: 4 of 17 (23.5 %) beyond 3 % of the diagonal pass, 5 (29 %) fail.
  const double far = 0.031 * kTDiagonal;
  for (int i = 0; i < 4; ++i) distances[static_cast<std::size_t>(i)] = far;
  EXPECT_TRUE(rigbuild::checkAlignment(surface, "y", positions, distances, labels, 1.0, limits).ok());
  distances[4] = far;
  c = rigbuild::checkAlignment(surface, "y", positions, distances, labels, 1.0, limits);
  ASSERT_EQ(c.pose_failures.size(), 1u);
  EXPECT_CONTAINS(c.pose_failures[0], "5 of 17 markers (29.4 %) are further than 0.0766 (3 % of the mesh's diagonal)");
  // Extent: the head marker 20 % of the height below the top fails, 14 % passes.
  std::fill(distances.begin(), distances.end(), 0.015);
  positions[0].y() = 1.8 - 0.14 * 1.8;
  EXPECT_TRUE(rigbuild::checkAlignment(surface, "y", positions, distances, labels, 1.0, limits).ok());
  positions[0].y() = 1.8 - 0.2 * 1.8;
  c = rigbuild::checkAlignment(surface, "y", positions, distances, labels, 1.0, limits);
  ASSERT_EQ(c.pose_failures.size(), 1u);
  EXPECT_CONTAINS(c.pose_failures[0], "the highest marker (LELB) is 15.8 % of the mesh's height below its top (limit 15 %)");
  // Switched off, a check only measures.
  rigbuild::AlignmentCheckLimits off = limits;
  off.check_pose = false;
  off.check_scale = false;
  c = rigbuild::checkAlignment(surface, "y", positions, distances, labels, 0.1, off);
  EXPECT_TRUE(c.ok());
  EXPECT_NEAR(c.up.gap_hi, (1.8 - 1.515) / 1.8, 1e-9);
}

TEST(FrameAuto, FindsTheTPoseFramesOfAClipThatStartsArmsDown) {
  const TempDir dir;
  std::vector<LabelledPoints> frames = repeat(test::armsDownMarkers(), 12);
  for (int i = 0; i < 6; ++i) frames.push_back(test::tPoseMarkers());
  for (int i = 0; i < 6; ++i) frames.push_back(test::armsDownMarkers());
  rigbuild::BuildRigInputs in = tInputs(dir, test::writeTClip(dir, "mixed.c3d", frames));
  // Frame 0 (the default) is arms down and refused.
  EXPECT_CONTAINS(buildError(in), "frame 0: the marker alignment is implausible");
  in.frame_auto = true;
  rigbuild::BuildRigReport report;
  const Rig rig = rigbuild::buildRig(in, &report);
  EXPECT_GE(report.rest_frame, 12);
  EXPECT_LE(report.rest_frame, 17);
  ASSERT_TRUE(report.frame_search.has_value());
  EXPECT_EQ(report.frame_search->frame, report.rest_frame);
  EXPECT_EQ(report.frame_search->searched, 24);
  EXPECT_EQ(report.frame_search->plausible, 6);
  EXPECT_TRUE(report.frame_search->chosen.plausible);
  EXPECT_TRUE(report.alignment_check->ok());
  EXPECT_TRUE(hasNote(report, "--frame auto chose frame " + std::to_string(report.rest_frame) + " (0."));
  EXPECT_EQ(rig.markers.size(), 17u);
  // The same from the description ("frame": "auto"); an explicit frame wins over it.
  rigbuild::BuildRigInputs json = tInputs(dir, in.clip.value());
  json.description = rigbuild::parseRigDescription(R"({"markers": {"frame": "auto"}})", dir.path() / "r.json");
  rigbuild::BuildRigReport json_report;
  (void)rigbuild::buildRig(json, &json_report);
  EXPECT_EQ(json_report.rest_frame, report.rest_frame);
  json.frame = 3;
  EXPECT_CONTAINS(buildError(json), "frame 3: the marker alignment is implausible");
}

TEST(FrameAuto, SaysClearlyWhenNoFrameFits) {
  const TempDir dir;
  rigbuild::BuildRigInputs in = tInputs(dir, test::writeTClip(dir, "down.c3d", repeat(test::armsDownMarkers(), 30)));
  in.frame_auto = true;
  const std::string e = buildError(in);
  EXPECT_CONTAINS(e, "down.c3d: --frame auto: no frame fits the mesh's rest pose: searched 30 of 30 frames");
  EXPECT_CONTAINS(e, "fails: along the mesh's widest horizontal axis");
  EXPECT_CONTAINS(e, "build the rig from a calibration clip of the same marker set in the mesh's pose");
  // No frame reaches a plausible size: the unit or the body is wrong, not the pose.
  in.clip = test::writeTClip(dir, "half.c3d", repeat(test::tPoseMarkers(), 30), 0.5);
  const std::string s = buildError(in);
  EXPECT_CONTAINS(s, "no frame fits the mesh's rest pose");
  EXPECT_CONTAINS(s, "no frame reaches a plausible fit scale: check the mesh's unit");
  // Overridden, every frame counts and the best-fitting one is taken.
  in.accept_implausible_alignment = true;
  rigbuild::BuildRigReport report;
  (void)rigbuild::buildRig(in, &report);
  ASSERT_TRUE(report.frame_search.has_value());
  EXPECT_EQ(report.frame_search->plausible, 30);
  EXPECT_EQ(report.rest_frame, report.frame_search->frame);
}

TEST(FrameAuto, LongClipsAreScreenedThenRefinedAroundTheBest) {
  // 450 frames, the T-pose only in frames 301-309: the screening takes every 3rd frame (at most 200),
  // the refinement the frames next to the best one.
  const TempDir dir;
  std::vector<LabelledPoints> frames = repeat(test::armsDownMarkers(), 450);
  for (std::size_t f = 301; f <= 309; ++f) frames[f] = test::tPoseMarkers();
  rigbuild::BuildRigInputs in = tInputs(dir, test::writeTClip(dir, "long.c3d", frames));
  in.frame_auto = true;
  rigbuild::BuildRigReport report;
  (void)rigbuild::buildRig(in, &report);
  ASSERT_TRUE(report.frame_search.has_value());
  const rigbuild::RestFrameSearch& found = *report.frame_search;
  EXPECT_EQ(found.usable_frames, 450);
  EXPECT_EQ(found.stride, 3);
  EXPECT_EQ(found.searched, 150 + 4);  // the screening, then the 2 frames on each side of the best
  EXPECT_GE(found.frame, 301);
  EXPECT_LE(found.frame, 309);
  EXPECT_GE(found.plausible, 3 + 1);  // frames 303, 306, 309 and at least one neighbour of the best
}

TEST(FrameAuto, SurfaceSamplesBoundTheExactDistance) {
  // The search's approximate query: never nearer than the exact closest point, and never further
  // than the sample spacing beyond it.
  const TempDir dir;
  const rigbuild::SurfaceMesh surface = tSurface(dir);
  const double spacing = 0.01 * kTDiagonal;
  const rigbuild::SurfaceSamples samples(surface);
  const rigbuild::SurfaceQuery exact(surface.vertices, surface.triangles);
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> x(-1.1, 1.1), y(-0.2, 2.0), z(-0.3, 0.3);
  double worst = 0;
  for (int i = 0; i < 2000; ++i) {
    const Eigen::Vector3d p(x(rng), y(rng), z(rng));
    const rigbuild::ClosestPoint a = samples.closest(p), e = exact.closest(p);
    ASSERT_GE(a.distance, e.distance - 1e-12);
    worst = std::max(worst, a.distance - e.distance);
    EXPECT_NEAR((a.point - p).norm(), a.distance, 1e-12);
    EXPECT_NEAR(a.normal.norm(), 1.0, 1e-9);
  }
  EXPECT_LE(worst, spacing);
  EXPECT_GT(samples.sampleCount(), static_cast<std::size_t>(surface.vertexCount()));
}

TEST(MarkerDistanceLimit, FollowsTheMeshSizeUnlessGivenInUnits) {
  const TempDir dir;
  LabelledPoints markers = test::tPoseMarkers();
  markers[0].second.y() += 0.18;  // HEAD 19.5 cm above the head: 7.6 % of the diagonal
  const std::filesystem::path clip = test::writeTClip(dir, "far.c3d", repeat(markers, 2));
  // The clip's own transform as the alignment matrix (device mm -> rig units; writeTClip's inverse),
  // so the distances are known exactly (an automatic fit would spread the error over the markers).
  auto description = [&](double units_per_m, const std::string& unit, const std::string& extra) {
    const double k = units_per_m / 1000.0;
    char m[256];
    std::snprintf(m, sizeof m, "[%.17g, 0, 0, %.17g,  0, 0, %.17g, %.17g,  0, %.17g, 0, %.17g]", k, -0.42 * units_per_m, k,
                  -0.015 * units_per_m, -k, -1.3 * units_per_m);
    return rigbuild::parseRigDescription("{\"mesh_unit\": \"" + unit + "\", \"markers\": {\"alignment\": \"matrix\", \"matrix\": " + m + extra +
                                             "}}",
                                         dir.path() / "r.json");
  };
  rigbuild::BuildRigInputs in = tInputs(dir, clip);
  in.description = description(1.0, "m", "");
  const std::string e = buildError(in);
  EXPECT_CONTAINS(e, "marker HEAD is 0.19");
  EXPECT_CONTAINS(e, "beyond the limit 0.1532 m (6 % of the mesh's diagonal) (too far: HEAD");
  // The same body in centimetres: the same marker, the limit in centimetres.
  rigbuild::BuildRigInputs cm = in;
  cm.mesh = test::writeTTetMesh(dir, "t_cm", 100.0);
  cm.description = description(100.0, "cm", "");
  const std::string e_cm = buildError(cm);
  EXPECT_CONTAINS(e_cm, "marker HEAD is 19");
  EXPECT_CONTAINS(e_cm, "beyond the limit 15.32 cm (6 % of the mesh's diagonal)");
  // Without the far marker both build: the markers sit 1.5 cm off the skin.
  rigbuild::BuildRigInputs near = in;
  near.clip = test::writeTClip(dir, "near.c3d", repeat(test::tPoseMarkers(), 2));
  EXPECT_EQ(buildError(near), "");
  near.mesh = cm.mesh;
  near.description = cm.description;
  EXPECT_EQ(buildError(near), "");
  // An explicit limit is in rig units and replaces the relative one; so does another fraction.
  in.max_marker_distance = 0.25;
  rigbuild::BuildRigReport report;
  (void)rigbuild::buildRig(in, &report);
  EXPECT_EQ(report.marker_distance_limit, 0.25);
  in.max_marker_distance.reset();
  in.description = description(1.0, "m", ", \"max_distance_fraction\": 0.1");
  (void)rigbuild::buildRig(in, &report);
  EXPECT_NEAR(report.marker_distance_limit, 0.1 * kTDiagonal, 1e-12);
  in.description = description(1.0, "m", ", \"max_distance\": 0.12");
  EXPECT_CONTAINS(buildError(in), "beyond the limit 0.12 m (too far: HEAD (0.19");
}

TEST(BuildRigHandles, WithoutHandlesItStopsBeforeReadingTheMesh) {
  const TempDir dir;
  // Not a mesh at all: a build that read it would fail on the import, not on the missing handles.
  const std::filesystem::path junk = dir.write("junk.obj", "this is not a mesh\n");
  rigbuild::BuildRigInputs in;
  in.mesh = junk;
  const std::string e = buildError(in);
  EXPECT_EQ(e.rfind("the rig would have no handles, so nothing could move it: add markers (--markers CLIP.c3d) or a rig description", 0), 0u)
      << e;
  // Rigid groups and stiffness alone do not drive a rig.
  in.description = rigbuild::parseRigDescription(
      R"({"rigid_groups": [{"select": {"vertices": [0]}}], "stiffness": [{"select": {"vertices": [0]}, "value": 2}]})", dir.path() / "r.json");
  EXPECT_CONTAINS(buildError(in), "the rig would have no handles");
  // With a handle the build goes on and meets the bad file.
  in.description = rigbuild::parseRigDescription(R"({"vertex_handles": [{"select": {"vertices": [0]}}]})", dir.path() / "r.json");
  const std::string import = buildError(in);
  EXPECT_NOT_CONTAINS(import, "no handles");
  EXPECT_CONTAINS(import, "junk.obj");
  // A missing mesh file is named first.
  in.mesh = dir.path() / "missing.obj";
  in.description = {};
  EXPECT_CONTAINS(buildError(in), "missing.obj: no such file (--mesh)");
}

TEST(RegionSelections, MinCornersDefaultsToFour) {
  const TempDir dir;
  const rigbuild::RigDescription d =
      rigbuild::parseRigDescription(R"({"region_handles": [{"name": "low", "select": {"box": {"min": [-1, -1, -1], "max": [1, 0.11, 1]}}}]})",
                                    dir.path() / "r.json");
  EXPECT_EQ(d.region_handles[0].select.min_corners, 4);
  rigbuild::BuildRigInputs in;
  in.mesh = test::writeBlockTetMesh(dir, "block");  // cells of 0.1 m: the box holds the lowest layer's vertices
  in.description = d;
  in.check_deformer = false;
  const Rig four = rigbuild::buildRig(in);
  ASSERT_EQ(four.setup.region_handles.size(), 1u);
  std::size_t outside_four = 0;
  for (const std::int32_t t : four.setup.region_handles[0].tets) {
    for (int k = 0; k < 4; ++k) outside_four += four.tet_mesh.vertices(four.tet_mesh.tets(t, k), 1) > 0.11 ? 1 : 0;
  }
  EXPECT_EQ(outside_four, 0u);
  EXPECT_EQ(four.setup.region_handles[0].tets.size(), 3u * 2u * 6u);  // the lowest layer: 3 x 2 cells, 6 tets each
  // min_corners 3 grows the region past the selection: tets with a corner above the box join it.
  in.description.region_handles[0].select.min_corners = 3;
  const Rig three = rigbuild::buildRig(in);
  EXPECT_GT(three.setup.region_handles[0].tets.size(), four.setup.region_handles[0].tets.size());
}

TEST(RigDescription, FrameAutoChecksAndDistanceFraction) {
  auto error = [](const std::string& json) {
    try {
      (void)rigbuild::parseRigDescription(json, "m.json");
    } catch (const rigbuild::RigBuildError& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  const rigbuild::RigDescription def = rigbuild::parseRigDescription("{}", "m.json");
  EXPECT_FALSE(def.markers.frame_auto);
  EXPECT_FALSE(def.markers.max_distance.has_value());
  EXPECT_EQ(def.markers.max_distance_fraction, 0.06);
  EXPECT_TRUE(def.markers.checks.check_scale);
  EXPECT_TRUE(def.markers.checks.check_pose);
  EXPECT_EQ(def.markers.checks.min_fit_scale, 0.85);
  EXPECT_EQ(def.markers.checks.max_fit_scale, 1.18);
  EXPECT_TRUE(rigbuild::parseRigDescription(R"({"markers": {"frame": "auto"}})", "m.json").markers.frame_auto);
  EXPECT_EQ(rigbuild::parseRigDescription(R"({"markers": {"frame": 12}})", "m.json").markers.frame, 12);
  EXPECT_CONTAINS(error(R"({"markers": {"frame": "first"}})"), "m.json: markers.frame: expected an integer in [0, 100000000] or \"auto\"");
  const rigbuild::RigDescription d = rigbuild::parseRigDescription(
      R"({"markers": {"max_distance": 0.2, "max_distance_fraction": 0.1, "checks": {"scale": false, "pose": false, "min_fit_scale": 0.5,
          "max_fit_scale": 2, "max_extent_gap": 0.3, "far_distance_fraction": 0.05, "max_far_fraction": 0.5}}})",
      "m.json");
  EXPECT_EQ(d.markers.max_distance, 0.2);
  EXPECT_EQ(d.markers.max_distance_fraction, 0.1);
  EXPECT_FALSE(d.markers.checks.check_scale);
  EXPECT_FALSE(d.markers.checks.check_pose);
  EXPECT_EQ(d.markers.checks.min_fit_scale, 0.5);
  EXPECT_EQ(d.markers.checks.max_fit_scale, 2.0);
  EXPECT_EQ(d.markers.checks.max_extent_gap, 0.3);
  EXPECT_EQ(d.markers.checks.far_distance_fraction, 0.05);
  EXPECT_EQ(d.markers.checks.max_far_fraction, 0.5);
  EXPECT_CONTAINS(error(R"({"markers": {"checks": {"min_fit_scale": 2, "max_fit_scale": 1}}})"), "markers.checks: min_fit_scale must be positive");
  EXPECT_CONTAINS(error(R"({"markers": {"checks": {"max_extent_gap": 0}}})"), "markers.checks.max_extent_gap: must be in (0, 1]");
  EXPECT_CONTAINS(error(R"({"markers": {"checks": {"max_far_fraction": 1.5}}})"), "markers.checks.max_far_fraction: must be in [0, 1]");
  EXPECT_CONTAINS(error(R"({"markers": {"checks": {"scale": 1}}})"), "markers.checks.scale: expected true or false");
  EXPECT_CONTAINS(error(R"({"markers": {"checks": {"limit": 1}}})"), "markers.checks: unknown key 'limit'");
  EXPECT_CONTAINS(error(R"({"markers": {"max_distance_fraction": 0}})"), "markers.max_distance_fraction: must be in (0, 1]");
  EXPECT_CONTAINS(error(R"({"markers": {"max_distance": 0}})"), "markers.max_distance: must be positive");
}

TEST(Inspect, NoMarkerAlignmentForARigWithoutMarkers) {
  const TempDir dir;
  rigbuild::BuildRigInputs in;
  in.mesh = test::writeBlockTetMesh(dir, "block");
  in.description = rigbuild::parseRigDescription(R"({"vertex_handles": [{"name": "pin", "select": {"vertices": [0]}}]})", dir.path() / "r.json");
  in.check_deformer = false;
  const std::string bare = rigbuild::describeRig(rigbuild::buildRig(in), 0, true);
  EXPECT_CONTAINS(bare, "alignment:     none (no markers or pose sensors)\n");
  EXPECT_NOT_CONTAINS(bare, "device mm");
  const std::string with_markers = rigbuild::describeRig(test::buildSmallRig(dir), 0, true);
  EXPECT_CONTAINS(with_markers, "alignment:     device mm (up y) -> rig m");
}

}  // namespace
}  // namespace tetrig
