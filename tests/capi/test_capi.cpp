// The C API (capi/include/tetrig.h, libtetrig.so) from C++:
//  - on the small block rig and its moving clip (generated, always available): the positions equal
//    a LiveRig fed the same frames (C3DPlayback::fillFrame) bit for bit, occluded markers included;
//    every bad input is a status and a text, never a crash, and leaves the rig unchanged;
//  - on the real SMPL + HDM05 rig (built by the capi_rig fixture, tests/capi/make_rig.py): no
//    allocation per frame (the counting allocator sees operator new inside libtetrig.so too), and
//    the budget stops the iterations.
#include "tetrig.h"

#include "counting_allocator.hpp"
#include "moving_clip.hpp"
#include "small_rig.hpp"
#include "test_data.hpp"
#include "tetrig/drivers/c3d_playback.hpp"
#include "tetrig/drivers/c3d_reader.hpp"
#include "tetrig/live_rig.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <memory>
#include <string>
#include <thread>
#include <vector>

namespace tetrig {
namespace {

using test::TempDir;

#define EXPECT_CONTAINS(haystack, needle) \
  EXPECT_NE(std::string(haystack).find(needle), std::string::npos) << "text: " << (haystack)

struct RigCloser {
  void operator()(tetrig_rig* r) const { tetrig_rig_close(r); }
};
struct ClipCloser {
  void operator()(tetrig_clip* c) const { tetrig_clip_close(c); }
};
using RigHandle = std::unique_ptr<tetrig_rig, RigCloser>;
using ClipHandle = std::unique_ptr<tetrig_clip, ClipCloser>;

// The small rig and the moving clip (12 frames; RIGHT occluded in frames 4..7), once per binary.
const test::MovingScene& small() { return test::movingScene(); }

// The clip's labels through the C API, as C strings for tetrig_rig_bind_labels.
std::vector<const char*> clipLabels(const tetrig_clip* clip) {
  std::vector<const char*> labels;
  for (int32_t i = 0; i < tetrig_clip_marker_count(clip); ++i) labels.push_back(tetrig_clip_marker_label(clip, i));
  return labels;
}

TEST(CApi, VersionIsTheHeaders) { EXPECT_STREQ(tetrig_version(), TETRIG_VERSION_STRING); }

// The C API gives the positions a LiveRig gives for the same frames (`tetrig export`'s path:
// fillFrame with counter = frame, labels as the playback source names them), bit for bit, with the
// default (accurate) settings and with the fast ones; the occluded frames are predicted.
TEST(CApi, FramesEqualTheLiveRigBitForBit) {
  const test::MovingScene& sc = small();
  for (const int fast : {0, 1}) {
    SCOPED_TRACE(fast ? "fast settings" : "accurate settings");
    tetrig_rig_options options;
    tetrig_rig_options_init(&options);
    options.fast_settings = fast;
    RigHandle rig(tetrig_rig_open(sc.rig_path.c_str(), &options));
    ASSERT_NE(rig.get(), nullptr) << tetrig_last_error();
    ClipHandle clip(tetrig_clip_open(sc.clip_path.c_str()));
    ASSERT_NE(clip.get(), nullptr) << tetrig_last_error();
    const std::vector<const char*> labels = clipLabels(clip.get());
    ASSERT_EQ(labels.size(), 5u);
    EXPECT_EQ(tetrig_rig_bind_labels(rig.get(), labels.data(), labels.size()), 5);
    EXPECT_EQ(tetrig_rig_marker_count(rig.get()), 5);
    EXPECT_STREQ(tetrig_rig_unit(rig.get()), sc.rig.unit.c_str());
    EXPECT_STREQ(tetrig_rig_up_axis(rig.get()), sc.rig.alignment.rig_up.c_str());

    LiveRigOptions live_options;
    if (fast) live_options.solver = SolverSettings::plain();
    LiveRig live(sc.rig, live_options);
    const drivers::C3DClip c3d = drivers::C3DClip::load(sc.clip_path);
    drivers::C3DPlaybackOptions po;
    po.pacing = drivers::Pacing::kAsFastAsPossible;
    const drivers::C3DPlayback playback(c3d, po);
    ASSERT_EQ(live.bindLabels(c3d.labels()).matched, 5);

    const auto n = static_cast<std::size_t>(live.fineVertexCount()) * 3;
    ASSERT_EQ(static_cast<std::size_t>(tetrig_rig_vertex_count(rig.get())) * 3, n);
    std::vector<float> expected(n), got(n), rest(n), xyz(labels.size() * 3);
    ASSERT_EQ(tetrig_rig_rest_positions(rig.get(), rest.data(), rest.size()), TETRIG_OK);
    EXPECT_EQ(std::memcmp(rest.data(), live.restPositions().data(), n * sizeof(float)), 0);
    MarkerFrame frame{};
    bool predicted = false;
    float moved = 0.0f;  // the largest coordinate change of any vertex from rest, rig units (metres)
    for (std::size_t f = 0; f < c3d.frameCount(); ++f) {
      playback.fillFrame(f, f, frame);
      const LiveFrameStats s = live.processFrame(frame, StepBudget{3}, expected.data(), nullptr);
      int64_t t = -1;
      ASSERT_EQ(tetrig_clip_frame(clip.get(), static_cast<int64_t>(f), xyz.data(), xyz.size(), &t), TETRIG_OK) << tetrig_last_error();
      EXPECT_EQ(t, frame.device_timestamp_ns);
      tetrig_frame_stats stats{};
      ASSERT_EQ(tetrig_rig_process_frame(rig.get(), xyz.data(), labels.size(), t, 3, 0, got.data(), got.size(), nullptr, 0, &stats), TETRIG_OK)
          << tetrig_last_error();
      ASSERT_EQ(std::memcmp(got.data(), expected.data(), n * sizeof(float)), 0) << "frame " << f;
      EXPECT_EQ(stats.frames, f + 1);
      EXPECT_EQ(stats.flags, s.flags);
      EXPECT_EQ(stats.iterations, s.step.iterations);
      EXPECT_EQ(stats.measured_markers, static_cast<int32_t>(s.measured_markers));
      EXPECT_EQ(stats.occluded_markers, static_cast<int32_t>(s.occluded_markers));
      predicted = predicted || (stats.flags & TETRIG_FRAME_MARKERS_PREDICTED);
      for (std::size_t i = 0; i < n; ++i) moved = std::max(moved, std::abs(got[i] - rest[i]));
      tetrig_frame_stats again{};
      ASSERT_EQ(tetrig_rig_frame_stats(rig.get(), &again), TETRIG_OK);
      EXPECT_EQ(again.frames, stats.frames);
      EXPECT_EQ(again.flags, stats.flags);
      EXPECT_EQ(again.total_ns, stats.total_ns);
      EXPECT_EQ(again.energy, stats.energy);
    }
    EXPECT_TRUE(predicted) << "RIGHT is occluded in frames 4..7: it must have been predicted";
    EXPECT_GT(moved, 0.005f) << "the markers move by up to 33 mm: the mesh must leave its rest pose";
  }
}

// The triangles are the live rig's; the normals come when the rig was opened with them.
TEST(CApi, TrianglesAndNormals) {
  const test::MovingScene& sc = small();
  tetrig_rig_options options;
  tetrig_rig_options_init(&options);
  options.normals = 1;
  RigHandle rig(tetrig_rig_open(sc.rig_path.c_str(), &options));
  ASSERT_NE(rig.get(), nullptr) << tetrig_last_error();
  LiveRig live(sc.rig);
  const auto tris = live.fineTriangles();
  ASSERT_EQ(static_cast<std::size_t>(tetrig_rig_triangle_count(rig.get())) * 3, tris.size());
  std::vector<int32_t> got(tris.size());
  ASSERT_EQ(tetrig_rig_triangles(rig.get(), got.data(), got.size()), TETRIG_OK);
  EXPECT_TRUE(std::equal(got.begin(), got.end(), tris.begin()));
  // No labels bound: a frame of no markers holds the rest pose and writes its normals.
  const auto n = static_cast<std::size_t>(tetrig_rig_vertex_count(rig.get())) * 3;
  std::vector<float> x(n), normals(n, 0.0f);
  tetrig_frame_stats stats{};
  ASSERT_EQ(tetrig_rig_process_frame(rig.get(), nullptr, 0, 0, 3, 0, x.data(), n, normals.data(), n, &stats), TETRIG_OK) << tetrig_last_error();
  EXPECT_TRUE(stats.flags & TETRIG_FRAME_POSE_HELD);
  for (std::size_t v = 0; v < n; v += 3) {
    const double len = std::sqrt(double(normals[v]) * normals[v] + double(normals[v + 1]) * normals[v + 1] + double(normals[v + 2]) * normals[v + 2]);
    ASSERT_NEAR(len, 1.0, 1e-5) << "vertex " << v / 3;
  }
}

// Bad input is a status and one line of text, never a crash; a failed frame changes nothing.
TEST(CApi, BadInputIsAnErrorNeverACrash) {
  const test::MovingScene& sc = small();
  const TempDir dir;
  // Files: missing, a directory, not a rig, a truncated rig.
  EXPECT_EQ(tetrig_rig_open((dir.path() / "missing.rig").c_str(), nullptr), nullptr);
  EXPECT_CONTAINS(tetrig_last_error(), "missing.rig");
  EXPECT_EQ(tetrig_rig_open(dir.path().c_str(), nullptr), nullptr);
  EXPECT_STRNE(tetrig_last_error(), "");
  const auto text = dir.write("text.rig", "not a rig at all");
  EXPECT_EQ(tetrig_rig_open(text.c_str(), nullptr), nullptr);
  EXPECT_CONTAINS(tetrig_last_error(), "text.rig");
  const std::vector<std::uint8_t> bytes = serializeRig(sc.rig);
  const auto cut = dir.writeBytes("cut.rig", std::vector<std::uint8_t>(bytes.begin(), bytes.begin() + static_cast<std::ptrdiff_t>(bytes.size() / 2)));
  EXPECT_EQ(tetrig_rig_open(cut.c_str(), nullptr), nullptr);
  EXPECT_CONTAINS(tetrig_last_error(), "cut.rig");
  EXPECT_EQ(tetrig_rig_open(nullptr, nullptr), nullptr);
  EXPECT_CONTAINS(tetrig_last_error(), "path is NULL");
  EXPECT_EQ(tetrig_clip_open((dir.path() / "missing.c3d").c_str()), nullptr);
  EXPECT_CONTAINS(tetrig_last_error(), "missing.c3d");
  EXPECT_EQ(tetrig_clip_open(text.c_str()), nullptr);
  EXPECT_STRNE(tetrig_last_error(), "");
  // Options.
  tetrig_rig_options options;
  tetrig_rig_options_init(&options);
  options.struct_size = 3;
  EXPECT_EQ(tetrig_rig_open(sc.rig_path.c_str(), &options), nullptr);
  EXPECT_CONTAINS(tetrig_last_error(), "struct_size");
  tetrig_rig_options_init(&options);
  options.occlusion_blend_ms = std::numeric_limits<double>::quiet_NaN();
  EXPECT_EQ(tetrig_rig_open(sc.rig_path.c_str(), &options), nullptr);
  EXPECT_CONTAINS(tetrig_last_error(), "occlusion_blend_ms");

  // NULL handles.
  EXPECT_EQ(tetrig_rig_vertex_count(nullptr), -1);
  EXPECT_CONTAINS(tetrig_last_error(), "NULL");
  EXPECT_EQ(tetrig_rig_triangle_count(nullptr), -1);
  EXPECT_EQ(tetrig_rig_marker_count(nullptr), -1);
  EXPECT_EQ(tetrig_rig_marker_label(nullptr, 0), nullptr);
  EXPECT_EQ(tetrig_rig_unit(nullptr), nullptr);
  EXPECT_EQ(tetrig_rig_bind_labels(nullptr, nullptr, 0), -1);
  float buffer[3] = {1, 2, 3};
  EXPECT_EQ(tetrig_rig_process_frame(nullptr, nullptr, 0, 0, 3, 0, buffer, 3, nullptr, 0, nullptr), TETRIG_ERROR_INVALID_ARGUMENT);
  EXPECT_EQ(tetrig_rig_frame_stats(nullptr, nullptr), TETRIG_ERROR_INVALID_ARGUMENT);
  EXPECT_EQ(tetrig_rig_prepare_next_frame(nullptr, 0), -1);
  EXPECT_EQ(tetrig_clip_frame(nullptr, 0, buffer, 3, nullptr), TETRIG_ERROR_INVALID_ARGUMENT);
  EXPECT_EQ(tetrig_clip_frame_count(nullptr), -1);
  tetrig_rig_close(nullptr);
  tetrig_clip_close(nullptr);

  RigHandle rig(tetrig_rig_open(sc.rig_path.c_str(), nullptr));
  ASSERT_NE(rig.get(), nullptr) << tetrig_last_error();
  ClipHandle clip(tetrig_clip_open(sc.clip_path.c_str()));
  ASSERT_NE(clip.get(), nullptr) << tetrig_last_error();
  // Indices and sizes.
  EXPECT_EQ(tetrig_rig_marker_label(rig.get(), 5), nullptr);
  EXPECT_CONTAINS(tetrig_last_error(), "out of range");
  EXPECT_EQ(tetrig_rig_marker_label(rig.get(), -1), nullptr);
  EXPECT_EQ(tetrig_clip_marker_label(clip.get(), 99), nullptr);
  std::vector<float> xyz(15);
  EXPECT_EQ(tetrig_clip_frame(clip.get(), 12, xyz.data(), xyz.size(), nullptr), TETRIG_ERROR_OUT_OF_RANGE);
  EXPECT_EQ(tetrig_clip_frame(clip.get(), -1, xyz.data(), xyz.size(), nullptr), TETRIG_ERROR_OUT_OF_RANGE);
  EXPECT_EQ(tetrig_clip_frame(clip.get(), 0, xyz.data(), 14, nullptr), TETRIG_ERROR_BUFFER_SIZE);
  EXPECT_CONTAINS(tetrig_last_error(), "14");
  const auto vertices = static_cast<std::size_t>(tetrig_rig_vertex_count(rig.get()));
  std::vector<int32_t> tris(static_cast<std::size_t>(tetrig_rig_triangle_count(rig.get())) * 3);
  EXPECT_EQ(tetrig_rig_triangles(rig.get(), tris.data(), tris.size() - 1), TETRIG_ERROR_BUFFER_SIZE);
  EXPECT_EQ(tetrig_rig_triangles(rig.get(), nullptr, tris.size()), TETRIG_ERROR_INVALID_ARGUMENT);
  std::vector<float> rest_short(vertices * 3 - 1);
  EXPECT_EQ(tetrig_rig_rest_positions(rig.get(), rest_short.data(), rest_short.size()), TETRIG_ERROR_BUFFER_SIZE);
  // Binding: NULL labels, too many labels; a NULL label names nothing.
  EXPECT_EQ(tetrig_rig_bind_labels(rig.get(), nullptr, 3), -1);
  std::vector<const char*> many(257, "TOP");
  EXPECT_EQ(tetrig_rig_bind_labels(rig.get(), many.data(), many.size()), -1);
  EXPECT_CONTAINS(tetrig_last_error(), "256");
  std::vector<const char*> labels = clipLabels(clip.get());
  labels[1] = nullptr;
  EXPECT_EQ(tetrig_rig_bind_labels(rig.get(), labels.data(), labels.size()), 4);
  labels = clipLabels(clip.get());
  ASSERT_EQ(tetrig_rig_bind_labels(rig.get(), labels.data(), labels.size()), 5);

  // Frames: a good frame first, then each bad call leaves the output buffer and the rig alone.
  ASSERT_EQ(tetrig_clip_frame(clip.get(), 0, xyz.data(), xyz.size(), nullptr), TETRIG_OK);
  std::vector<float> x(vertices * 3);
  ASSERT_EQ(tetrig_rig_process_frame(rig.get(), xyz.data(), 5, 1, 3, 0, x.data(), x.size(), nullptr, 0, nullptr), TETRIG_OK);
  tetrig_frame_stats before{};
  ASSERT_EQ(tetrig_rig_frame_stats(rig.get(), &before), TETRIG_OK);
  std::vector<float> sentinel(vertices * 3, -7.0f), out = sentinel;
  auto frame = [&](const float* markers, std::size_t count, int32_t iterations, int64_t budget, float* positions, std::size_t positions_count,
                   float* normals, std::size_t normals_count) {
    return tetrig_rig_process_frame(rig.get(), markers, count, 2, iterations, budget, positions, positions_count, normals, normals_count, nullptr);
  };
  EXPECT_EQ(frame(xyz.data(), 4, 3, 0, out.data(), out.size(), nullptr, 0), TETRIG_ERROR_NOT_BOUND);
  EXPECT_CONTAINS(tetrig_last_error(), "4 markers given; the labels bound were 5");
  EXPECT_EQ(frame(nullptr, 5, 3, 0, out.data(), out.size(), nullptr, 0), TETRIG_ERROR_INVALID_ARGUMENT);
  EXPECT_EQ(frame(xyz.data(), 5, 0, 0, out.data(), out.size(), nullptr, 0), TETRIG_ERROR_INVALID_ARGUMENT);
  EXPECT_CONTAINS(tetrig_last_error(), "max_iterations");
  EXPECT_EQ(frame(xyz.data(), 5, 3, -1, out.data(), out.size(), nullptr, 0), TETRIG_ERROR_INVALID_ARGUMENT);
  EXPECT_EQ(frame(xyz.data(), 5, 3, 0, nullptr, out.size(), nullptr, 0), TETRIG_ERROR_INVALID_ARGUMENT);
  EXPECT_EQ(frame(xyz.data(), 5, 3, 0, out.data(), out.size() - 1, nullptr, 0), TETRIG_ERROR_BUFFER_SIZE);
  EXPECT_CONTAINS(tetrig_last_error(), "positions holds " + std::to_string(out.size() - 1) + " floats");
  std::vector<float> normals(vertices * 3);
  EXPECT_EQ(frame(xyz.data(), 5, 3, 0, out.data(), out.size(), normals.data(), normals.size()), TETRIG_ERROR_INVALID_ARGUMENT);
  EXPECT_CONTAINS(tetrig_last_error(), "normals");
  EXPECT_EQ(out, sentinel) << "a refused frame wrote into the buffer";
  tetrig_frame_stats after{};
  ASSERT_EQ(tetrig_rig_frame_stats(rig.get(), &after), TETRIG_OK);
  EXPECT_EQ(after.frames, before.frames) << "a refused frame counted";

  // Markers that are not numbers: NaN is occluded; infinities and absurd values are refused samples
  // (predicted instead); the output stays finite.
  std::vector<float> odd = xyz;
  odd[0] = std::numeric_limits<float>::quiet_NaN();
  odd[4] = std::numeric_limits<float>::infinity();
  odd[6] = 3e30f;
  tetrig_frame_stats stats{};
  ASSERT_EQ(tetrig_rig_process_frame(rig.get(), odd.data(), 5, 3, 3, 0, out.data(), out.size(), nullptr, 0, &stats), TETRIG_OK);
  EXPECT_EQ(stats.measured_markers, 2);
  EXPECT_EQ(stats.occluded_markers, 3);
  EXPECT_EQ(stats.rejected_marker_samples, 2);
  EXPECT_TRUE(stats.flags & TETRIG_FRAME_MARKERS_PREDICTED);
  for (const float v : out) ASSERT_TRUE(std::isfinite(v));
}

// The error text belongs to the thread that failed.
TEST(CApi, LastErrorIsPerThread) {
  EXPECT_EQ(tetrig_rig_vertex_count(nullptr), -1);
  std::string other;
  std::thread([&] { other = tetrig_last_error(); }).join();
  EXPECT_EQ(other, "");
  EXPECT_CONTAINS(tetrig_last_error(), "tetrig_rig_vertex_count");
}

// ---- the real rig (SMPL male + HDM05, tests/capi/make_rig.py) ----

constexpr const char* kHdm05 = "mocap/hdm05/HDM_mm_01-02_03_120.c3d";

// No allocation per frame: after a warm-up, tetrig_rig_process_frame (and the clip's frames)
// make no operator new call, while binding does (the counter sees inside libtetrig.so).
TEST(CApiReal, NoAllocationPerFrame) {
  TETRIG_REQUIRE_DATA(clip_path, kHdm05);
  ASSERT_TRUE(std::filesystem::exists(TETRIG_CAPI_RIG)) << "the capi_rig fixture did not build " << TETRIG_CAPI_RIG;
  RigHandle rig(tetrig_rig_open(TETRIG_CAPI_RIG, nullptr));
  ASSERT_NE(rig.get(), nullptr) << tetrig_last_error();
  ClipHandle clip(tetrig_clip_open(clip_path.c_str()));
  ASSERT_NE(clip.get(), nullptr) << tetrig_last_error();
  const std::vector<const char*> labels = clipLabels(clip.get());
  const std::uint64_t before_bind = test::allocationCount();
  ASSERT_EQ(tetrig_rig_bind_labels(rig.get(), labels.data(), labels.size()), tetrig_rig_marker_count(rig.get())) << tetrig_last_error();
  EXPECT_GT(test::allocationCount(), before_bind) << "binding allocates: the counter must see allocations inside libtetrig.so";
  std::vector<float> xyz(labels.size() * 3), x(static_cast<std::size_t>(tetrig_rig_vertex_count(rig.get())) * 3);
  int64_t t = 0;
  for (int64_t f = 0; f < 3; ++f) {  // warm-up
    ASSERT_EQ(tetrig_clip_frame(clip.get(), f, xyz.data(), xyz.size(), &t), TETRIG_OK);
    ASSERT_EQ(tetrig_rig_process_frame(rig.get(), xyz.data(), labels.size(), t, 3, 0, x.data(), x.size(), nullptr, 0, nullptr), TETRIG_OK);
  }
  std::uint32_t flags = 0;
  const std::uint64_t before = test::allocationCount();
  for (int64_t f = 3; f < 300; ++f) {
    ASSERT_EQ(tetrig_clip_frame(clip.get(), f, xyz.data(), xyz.size(), &t), TETRIG_OK);
    if (f >= 100 && f < 130) xyz[0] = xyz[1] = xyz[2] = std::numeric_limits<float>::quiet_NaN();  // a dropout and its return
    tetrig_frame_stats stats{};
    ASSERT_EQ(tetrig_rig_process_frame(rig.get(), xyz.data(), labels.size(), t, 3, 0, x.data(), x.size(), nullptr, 0, &stats), TETRIG_OK);
    flags |= stats.flags;
    EXPECT_GE(tetrig_rig_prepare_next_frame(rig.get(), 0), 0);
  }
  EXPECT_EQ(test::allocationCount() - before, 0u);
  EXPECT_TRUE(flags & TETRIG_FRAME_MARKERS_PREDICTED) << "the dropout was meant to run";
  EXPECT_TRUE(flags & TETRIG_FRAME_MARKERS_BLENDING) << "the dropout's fade and return blend were meant to run";
}

// A budget of 1 ns stops the iterations at the first check of the deadline (after an iteration).
TEST(CApiReal, TheBudgetStopsTheIterations) {
  TETRIG_REQUIRE_DATA(clip_path, kHdm05);
  ASSERT_TRUE(std::filesystem::exists(TETRIG_CAPI_RIG)) << "the capi_rig fixture did not build " << TETRIG_CAPI_RIG;
  RigHandle rig(tetrig_rig_open(TETRIG_CAPI_RIG, nullptr));
  ASSERT_NE(rig.get(), nullptr) << tetrig_last_error();
  ClipHandle clip(tetrig_clip_open(clip_path.c_str()));
  ASSERT_NE(clip.get(), nullptr) << tetrig_last_error();
  const std::vector<const char*> labels = clipLabels(clip.get());
  ASSERT_GT(tetrig_rig_bind_labels(rig.get(), labels.data(), labels.size()), 0);
  std::vector<float> xyz(labels.size() * 3), x(static_cast<std::size_t>(tetrig_rig_vertex_count(rig.get())) * 3);
  int64_t t = 0;
  tetrig_frame_stats unlimited{}, budgeted{};
  ASSERT_EQ(tetrig_clip_frame(clip.get(), 0, xyz.data(), xyz.size(), &t), TETRIG_OK);
  ASSERT_EQ(tetrig_rig_process_frame(rig.get(), xyz.data(), labels.size(), t, 20, 0, x.data(), x.size(), nullptr, 0, &unlimited), TETRIG_OK);
  ASSERT_EQ(tetrig_clip_frame(clip.get(), 1, xyz.data(), xyz.size(), &t), TETRIG_OK);
  ASSERT_EQ(tetrig_rig_process_frame(rig.get(), xyz.data(), labels.size(), t, 20, 1, x.data(), x.size(), nullptr, 0, &budgeted), TETRIG_OK);
  EXPECT_FALSE(unlimited.flags & TETRIG_FRAME_DEADLINE_HIT);
  EXPECT_GT(unlimited.iterations, 2);
  EXPECT_TRUE(budgeted.flags & TETRIG_FRAME_DEADLINE_HIT);
  EXPECT_LE(budgeted.iterations, 2);
  for (const float v : x) ASSERT_TRUE(std::isfinite(v));
}

}  // namespace
}  // namespace tetrig
