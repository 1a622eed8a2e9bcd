// `tetrig export` (tools/export.hpp) on the small block rig (small_rig.hpp) and a 12-frame clip
// (moving_clip.hpp, written by c3d_test_writer.hpp) in which the markers move and one marker is
// occluded for four frames. Every file written is read back with an independent reader (PC2 and PLY parsed here
// from the format facts, OBJ as text, glTF with tinygltf's loader) and compared with a LiveRig
// fed the same clip frames (C3DPlayback::fillFrame, labels by point index) with the same budget.
// Also: convergence, frame ranges, one-line errors, atomic output (a cancelled export leaves
// nothing behind and never touches an existing file), and the command line.
#include "export.hpp"
#include "export_formats.hpp"
#include "moving_clip.hpp"
#include "small_rig.hpp"
#include "uv_box_asset.hpp"
#include "tetrig/drivers/c3d_playback.hpp"
#include "tetrig/drivers/c3d_reader.hpp"
#include "tetrig/live_rig.hpp"
#include "tetrig/volume_constraint.hpp"

#include <gtest/gtest.h>
#include <tiny_gltf.h>

#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <thread>
#include <cmath>
#include <cstring>
#include <fstream>
#include <map>
#include <set>
#include <sstream>
#include <tuple>

extern char** environ;

namespace tetrig {
namespace {

using test::TempDir;

constexpr std::size_t kFrames = 12;
constexpr float kRate = test::kMovingClipRate;

// The rig and clip, built once per binary (the directory is removed at exit).
const test::MovingScene& scene() { return test::movingScene(); }

// Reference: a LiveRig fed clip frames [first, end) with `iterations` per frame.
// `clip_path`: another clip of the same markers instead of the moving one.
// The live rig with the plain settings (SolverSettings::plain()): the tests below set the export's
// solver flags one by one on top of them, so that each one's effect is its own.
LiveRigOptions plainLive() {
  LiveRigOptions o;
  o.solver = SolverSettings::plain();
  return o;
}

std::vector<std::vector<float>> liveRigFrames(std::size_t first, std::size_t end, int iterations, const LiveRigOptions& live_options = plainLive(),
                                              const std::filesystem::path& clip_path = {}) {
  const test::MovingScene& sc = scene();
  const drivers::C3DClip clip = drivers::C3DClip::load(clip_path.empty() ? sc.clip_path : clip_path);
  drivers::C3DPlaybackOptions po;
  po.pacing = drivers::Pacing::kAsFastAsPossible;
  const drivers::C3DPlayback playback(clip, po);
  LiveRig live(sc.rig, live_options);
  EXPECT_EQ(live.bindLabels(clip.labels()).matched, 5);
  std::vector<std::vector<float>> out;
  MarkerFrame frame{};
  for (std::size_t f = first; f < end; ++f) {
    playback.fillFrame(f, f, frame);
    std::vector<float> x(static_cast<std::size_t>(live.fineVertexCount()) * 3);
    live.processFrame(frame, StepBudget{iterations}, x.data(), nullptr);
    out.push_back(std::move(x));
  }
  return out;
}

std::vector<std::uint8_t> slurp(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::vector<std::uint8_t>(std::istreambuf_iterator<char>(in), {});
}

template <class T>
T readAt(const std::vector<std::uint8_t>& b, std::size_t offset) {
  T v;
  std::memcpy(&v, b.data() + offset, sizeof v);
  return v;
}

struct Pc2 {
  std::int32_t version = 0, points = 0, samples = 0;
  float start = -1, rate = -1;
  std::vector<std::vector<float>> frames;
};
Pc2 readPc2(const std::filesystem::path& p) {
  const auto b = slurp(p);
  Pc2 r;
  EXPECT_GE(b.size(), 32u);
  if (b.size() < 32) return r;
  EXPECT_EQ(std::memcmp(b.data(), "POINTCACHE2\0", 12), 0);
  r.version = readAt<std::int32_t>(b, 12);
  r.points = readAt<std::int32_t>(b, 16);
  r.start = readAt<float>(b, 20);
  r.rate = readAt<float>(b, 24);
  r.samples = readAt<std::int32_t>(b, 28);
  const std::size_t per = static_cast<std::size_t>(r.points) * 3;
  EXPECT_EQ(b.size(), 32 + static_cast<std::size_t>(r.samples) * per * 4);
  for (std::int32_t s = 0; s < r.samples && b.size() >= 32 + (static_cast<std::size_t>(s) + 1) * per * 4; ++s) {
    std::vector<float> f(per);
    std::memcpy(f.data(), b.data() + 32 + static_cast<std::size_t>(s) * per * 4, per * 4);
    r.frames.push_back(std::move(f));
  }
  return r;
}

struct TextMesh {
  std::vector<float> v;
  std::vector<std::int32_t> f;  // 0-based
  std::vector<std::string> comments;
};
TextMesh readObj(const std::filesystem::path& p) {
  std::ifstream in(p);
  TextMesh m;
  std::string line;
  while (std::getline(in, line)) {
    std::istringstream s(line);
    std::string tag;
    s >> tag;
    if (tag == "#") {
      m.comments.push_back(line.substr(2));
    } else if (tag == "v") {
      float x, y, z;
      s >> x >> y >> z;
      m.v.insert(m.v.end(), {x, y, z});
    } else if (tag == "f") {
      std::int32_t a, b, c;
      s >> a >> b >> c;
      m.f.insert(m.f.end(), {a - 1, b - 1, c - 1});
    }
  }
  return m;
}

TextMesh readPly(const std::filesystem::path& p) {
  const auto b = slurp(p);
  const std::string text(b.begin(), b.end());
  const std::size_t end = text.find("end_header\n");
  EXPECT_NE(end, std::string::npos);
  std::istringstream header(text.substr(0, end));
  std::string line;
  std::size_t vertices = 0, faces = 0;
  TextMesh m;
  std::getline(header, line);
  EXPECT_EQ(line, "ply");
  std::getline(header, line);
  EXPECT_EQ(line, "format binary_little_endian 1.0");
  while (std::getline(header, line)) {
    if (line.rfind("element vertex ", 0) == 0) vertices = std::stoul(line.substr(15));
    if (line.rfind("element face ", 0) == 0) faces = std::stoul(line.substr(13));
    if (line.rfind("comment ", 0) == 0) m.comments.push_back(line.substr(8));
  }
  std::size_t at = end + 11;
  EXPECT_EQ(b.size(), at + vertices * 12 + faces * 13);
  if (b.size() != at + vertices * 12 + faces * 13) return m;
  m.v.resize(vertices * 3);
  std::memcpy(m.v.data(), b.data() + at, vertices * 12);
  at += vertices * 12;
  for (std::size_t i = 0; i < faces; ++i, at += 13) {
    EXPECT_EQ(b[at], 3);
    for (int c = 0; c < 3; ++c) m.f.push_back(readAt<std::int32_t>(b, at + 1 + 4 * static_cast<std::size_t>(c)));
  }
  return m;
}

std::vector<std::int32_t> rigTriangles() {
  const LiveRig live(scene().rig);
  return std::vector<std::int32_t>(live.fineTriangles().begin(), live.fineTriangles().end());
}
std::vector<float> rigRest() {
  const LiveRig live(scene().rig);
  return std::vector<float>(live.restPositions().begin(), live.restPositions().end());
}

tools::ExportOptions options(const std::filesystem::path& out, int iterations = 3) {
  tools::ExportOptions o;
  o.rig_path = scene().rig_path;
  o.clip_path = scene().clip_path;
  o.out = out;
  o.iterations = iterations;
  o.quiet = true;
  o.solver = SolverSettings::plain();  // the plain settings: each test adds the flags it checks (as liveRigFrames)
  return o;
}

double maxDifference(const std::vector<float>& a, const std::vector<float>& b) {
  EXPECT_EQ(a.size(), b.size());
  double worst = 0;
  for (std::size_t i = 0; i < std::min(a.size(), b.size()); ++i) worst = std::max(worst, std::abs(static_cast<double>(a[i]) - b[i]));
  return worst;
}

std::vector<std::string> listDir(const std::filesystem::path& dir) {
  std::vector<std::string> names;
  for (const auto& e : std::filesystem::directory_iterator(dir)) names.push_back(e.path().filename().string());
  std::sort(names.begin(), names.end());
  return names;
}

#define EXPECT_THROW_CONTAINS(stmt, needle)                                          \
  do {                                                                               \
    try {                                                                            \
      stmt;                                                                          \
      ADD_FAILURE() << "no exception; expected one containing: " << (needle);       \
    } catch (const std::exception& e) {                                              \
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what(); \
    }                                                                                \
  } while (0)

TEST(Export, Pc2HeaderAndSamplesAreTheLiveRigFrames) {
  const TempDir out;
  const tools::ExportReport r = tools::exportClip(options(out.path() / "anim.pc2"));
  const auto reference = liveRigFrames(0, kFrames, 3);
  const Pc2 pc2 = readPc2(out.path() / "anim.pc2");
  EXPECT_EQ(pc2.version, 1);
  EXPECT_EQ(pc2.points, static_cast<std::int32_t>(reference[0].size() / 3));
  EXPECT_EQ(pc2.start, 0.0f);
  EXPECT_EQ(pc2.rate, 1.0f);  // one sample per frame
  ASSERT_EQ(pc2.samples, static_cast<std::int32_t>(kFrames));
  ASSERT_EQ(pc2.frames.size(), kFrames);
  for (std::size_t f = 0; f < kFrames; ++f) EXPECT_EQ(pc2.frames[f], reference[f]) << "frame " << f;
  // The clip moves the mesh, and the occluded marker was predicted in frames 4..7.
  EXPECT_GT(maxDifference(pc2.frames[kFrames - 1], rigRest()), 0.003);  // measured 6.7 mm
  EXPECT_EQ(r.predicted_frames, 4u);
  EXPECT_EQ(r.held_frames, 0u);
  EXPECT_EQ(r.iterations, 3u * kFrames);
  // The rest mesh beside it, in the same vertex order, with the machine-readable comment.
  const TextMesh obj = readObj(out.path() / "anim.rest.obj");
  EXPECT_EQ(obj.v, rigRest());
  EXPECT_EQ(obj.f, rigTriangles());
  bool keys = false;
  for (const std::string& c : obj.comments)
    keys |= c.find("tetrig-export first_frame=0 frames=12 rate_hz=100 unit=m up=y vertices=" + std::to_string(pc2.points)) == 0;
  EXPECT_TRUE(keys);
  EXPECT_EQ(r.files, (std::vector<std::filesystem::path>{out.path() / "anim.rest.obj", out.path() / "anim.pc2"}));
  EXPECT_EQ(listDir(out.path()), (std::vector<std::string>{"anim.pc2", "anim.rest.obj"}));  // no temporary left
  EXPECT_EQ(r.bytes, std::filesystem::file_size(out.path() / "anim.rest.obj") + std::filesystem::file_size(out.path() / "anim.pc2"));
}

TEST(Export, RangeStartsFromTheRestPoseAtItsFirstFrame) {
  const TempDir out;
  auto o = options(out.path() / "part.pc2", 2);
  o.frames = "3:9";
  (void)tools::exportClip(o);
  const Pc2 pc2 = readPc2(out.path() / "part.pc2");
  EXPECT_EQ(pc2.start, 3.0f);
  ASSERT_EQ(pc2.samples, 6);
  const auto reference = liveRigFrames(3, 9, 2);
  for (std::size_t k = 0; k < 6; ++k) EXPECT_EQ(pc2.frames[k], reference[k]) << "sample " << k;
  // Not the same as frames 3..8 of a run from frame 0 (the pose carries over between frames).
  const auto whole = liveRigFrames(0, 9, 2);
  EXPECT_GT(maxDifference(pc2.frames[0], whole[3]), 1e-6);
}

TEST(Export, ConvergenceGetsCloseToAVeryLongSolve) {
  const TempDir out;
  auto o = options(out.path() / "conv.pc2", 0);  // 0: iterate to convergence (the default)
  const tools::ExportReport r = tools::exportClip(o);
  auto tight = options(out.path() / "tight.pc2", 0);
  tight.tolerance = 1e-6;
  const tools::ExportReport rt = tools::exportClip(tight);
  (void)tools::exportClip(options(out.path() / "one.pc2", 1));
  const auto converged = readPc2(out.path() / "conv.pc2").frames, closer = readPc2(out.path() / "tight.pc2").frames,
             one = readPc2(out.path() / "one.pc2").frames;
  const auto reference = liveRigFrames(0, kFrames, 2000);
  ASSERT_EQ(converged.size(), kFrames);
  ASSERT_EQ(closer.size(), kFrames);
  double worst_converged = 0, worst_closer = 0, worst_one = 0;
  for (std::size_t f = 0; f < kFrames; ++f) {
    worst_converged = std::max(worst_converged, maxDifference(converged[f], reference[f]));
    worst_closer = std::max(worst_closer, maxDifference(closer[f], reference[f]));
    worst_one = std::max(worst_one, maxDifference(one[f], reference[f]));
  }
  std::printf("largest difference from 2000 iterations per frame: tolerance 1e-4 %.3g m (%.2f iterations per frame), 1e-6 %.3g m "
              "(%.2f), 1 iteration %.3g m\n",
              worst_converged, static_cast<double>(r.iterations) / kFrames, worst_closer, static_cast<double>(rt.iterations) / kFrames,
              worst_one);
  // Measured with the live rig's over-relaxation (omega 1.8): 9.3e-7 m at 8.0 iterations per frame (default
  // 1e-4), 1.0e-6 m at 15.0 (1e-6), one iteration 2.3e-4 m; plain (omega 1): 9.6e-6 m at 8.3, 1.0e-6 m at 20.7,
  // 3.7e-4 m. About 1e-6 m is the float floor of the rotation pass here: a tighter tolerance gets closer, down to it.
  EXPECT_LT(worst_converged, 5e-5);
  EXPECT_LT(worst_closer, std::max(worst_converged / 3, 2e-6));
  EXPECT_GT(worst_one, 10 * worst_converged);
  EXPECT_GT(rt.iterations, r.iterations);
  EXPECT_GT(r.iterations, kFrames * static_cast<std::uint64_t>(tools::kConvergeChunkIterations));
  EXPECT_LE(r.max_frame_iterations, o.max_iterations);
  EXPECT_EQ(r.capped_frames, 0u);
  EXPECT_EQ(rt.capped_frames, 0u);
}

// A rig with a coarse level (here the small rig as its own): --iterations N uses it, as tetrig run
// does (the frames differ from the plain rig's), and iterating to convergence does not (the same
// bytes as the plain rig's export).
TEST(Export, TheCoarseLevelIsUsedWithIterationsAndNotWhenConverging) {
  const TempDir out;
  Rig with = scene().rig;
  with.coarse = std::make_shared<const Rig>(scene().rig);
  const std::filesystem::path coarse_rig = out.writeBytes("coarse.rig", serializeRig(with));
  auto fixed = options(out.path() / "fixed.pc2", 3);
  fixed.rig_path = coarse_rig;
  auto converge = options(out.path() / "converge.pc2", 0);
  converge.rig_path = coarse_rig;
  (void)tools::exportClip(fixed);
  (void)tools::exportClip(converge);
  (void)tools::exportClip(options(out.path() / "plain_fixed.pc2", 3));
  (void)tools::exportClip(options(out.path() / "plain_converge.pc2", 0));
  EXPECT_EQ(slurp(out.path() / "converge.pc2"), slurp(out.path() / "plain_converge.pc2"));
  const auto guided = readPc2(out.path() / "fixed.pc2").frames, plain = readPc2(out.path() / "plain_fixed.pc2").frames;
  ASSERT_EQ(guided.size(), plain.size());
  double differ = 0;
  for (std::size_t f = 0; f < guided.size(); ++f) differ = std::max(differ, maxDifference(guided[f], plain[f]));
  EXPECT_GT(differ, 1e-6);
}

// --keep-volume: with --iterations N the frames are the LiveRig's with the volume constraint, bit
// for bit; iterating to convergence (each chunk linearizes the constraint again) every frame ends
// at the rest volume, where the plain export does not.
TEST(Export, KeepVolumeIsTheLiveRigsVolumeConstraint) {
  const TempDir out;
  auto fixed = options(out.path() / "fixed.pc2", 3);
  fixed.solver.volume_constraint = true;
  auto converge = options(out.path() / "converge.pc2", 0);
  converge.solver.volume_constraint = true;
  (void)tools::exportClip(fixed);
  (void)tools::exportClip(converge);
  (void)tools::exportClip(options(out.path() / "plain_converge.pc2", 0));
  LiveRigOptions keep = plainLive();
  keep.solver.volume_constraint = true;
  const auto reference = liveRigFrames(0, kFrames, 3, keep);
  const auto got = readPc2(out.path() / "fixed.pc2").frames;
  ASSERT_EQ(got.size(), kFrames);
  for (std::size_t f = 0; f < kFrames; ++f) EXPECT_EQ(got[f], reference[f]) << "frame " << f;
  EXPECT_NE(got, liveRigFrames(0, kFrames, 3));
  const std::vector<std::int32_t> triangles = rigTriangles();
  const double rest = enclosedVolume(triangles, rigRest().data());
  ASSERT_GT(rest, 0.0);
  const auto kept = readPc2(out.path() / "converge.pc2").frames, plain = readPc2(out.path() / "plain_converge.pc2").frames;
  ASSERT_EQ(kept.size(), kFrames);
  ASSERT_EQ(plain.size(), kFrames);
  double kept_worst = 0.0, plain_worst = 0.0;
  for (std::size_t f = 0; f < kFrames; ++f) {
    kept_worst = std::max(kept_worst, std::abs(enclosedVolume(triangles, kept[f].data()) / rest - 1.0));
    plain_worst = std::max(plain_worst, std::abs(enclosedVolume(triangles, plain[f].data()) / rest - 1.0));
  }
  RecordProperty("kept_volume_change", ::testing::PrintToString(kept_worst));
  RecordProperty("plain_volume_change", ::testing::PrintToString(plain_worst));
  EXPECT_LT(kept_worst, 1e-4);
  EXPECT_GT(plain_worst, 10 * kept_worst);
}

// The export at `path` is, frame for frame and bit for bit, a LiveRig with `live` fed the same clip
// frames with `iterations` per frame, and differs from a plain LiveRig's (so the options reached it).
void expectTheLiveRigsFrames(const std::filesystem::path& path, int iterations, const LiveRigOptions& live,
                             const std::filesystem::path& clip = {}) {
  const auto got = readPc2(path).frames;
  const auto reference = liveRigFrames(0, kFrames, iterations, live, clip);
  ASSERT_EQ(got.size(), kFrames) << path;
  for (std::size_t f = 0; f < kFrames; ++f) EXPECT_EQ(got[f], reference[f]) << path << " frame " << f;
  EXPECT_NE(got, liveRigFrames(0, kFrames, iterations, plainLive(), clip)) << path;
}

// --after-publish-iterations N with --iterations 3: the LiveRig's frames with
// LiveRigOptions::after_publish_iterations, bit for bit (each frame written, then refined); without
// --iterations (convergence) it is refused before anything is written.
TEST(Export, AfterPublishIterationsAreTheLiveRigs) {
  const TempDir out;
  auto refined = options(out.path() / "refined.pc2", 3);
  refined.solver.after_publish_iterations = 2;
  (void)tools::exportClip(refined);
  LiveRigOptions after = plainLive();
  after.solver.after_publish_iterations = 2;
  expectTheLiveRigsFrames(out.path() / "refined.pc2", 3, after);
  auto converging = options(out.path() / "converging.pc2", 0);
  converging.solver.after_publish_iterations = 2;
  EXPECT_THROW_CONTAINS(tools::exportClip(converging), "--after-publish-iterations needs --iterations N");
  EXPECT_FALSE(std::filesystem::exists(out.path() / "converging.pc2"));
}

// --predict, --relax and --inversion-guard with --iterations 3: the LiveRig's frames with the same
// LiveRigOptions, bit for bit; bad values are refused before anything is written.
TEST(Export, PredictRelaxAndTheGuardAreTheLiveRigs) {
  const TempDir out;
  auto tuned = options(out.path() / "tuned.pc2", 3);
  tuned.solver.rotation_extrapolation = 1.0;
  tuned.solver.rotation_relaxation = 1.9;
  tuned.solver.inversion_guard = 1.0;
  (void)tools::exportClip(tuned);
  LiveRigOptions live = plainLive();
  live.solver.rotation_extrapolation = 1.0;
  live.solver.rotation_relaxation = 1.9;
  live.solver.inversion_guard = 1.0;
  expectTheLiveRigsFrames(out.path() / "tuned.pc2", 3, live);
  // Each option on its own changes the frames (so none of them is dropped on the way); the fourth
  // is the implicit guard (k 3, 2 solves) against the explicit one on the crushed block, the fifth
  // that guard holding tets from 0.9 of their volume instead of 0.5.
  constexpr int kGuardIterations = 200;
  for (int which = 0; which < 5; ++which) {
    auto one = options(out.path() / ("one" + std::to_string(which) + ".pc2"), 3);
    LiveRigOptions o = plainLive();
    std::filesystem::path clip;
    if (which == 0) {
      one.solver.rotation_extrapolation = 1.0;
      o.solver.rotation_extrapolation = 1.0;
    } else if (which == 1) {
      one.solver.rotation_relaxation = 1.0;
      o.solver.rotation_relaxation = 1.0;
    } else {
      // The guard acts only on tets squashed below half their volume: the block crushed from the
      // top and the right, frame after frame (TOP pulled 400 mm down through the block, RIGHT 400 mm
      // left through it), iterated long enough to follow.
      test::TestC3DSpec spec;
      spec.floating = true;
      spec.scale = 1.0f;
      spec.rate = kRate;
      spec.frames = kFrames;
      spec.labels = {"TOP", "LEFT", "RIGHT", "FRONT", "BACK"};
      const auto rest = test::smallMarkerPositionsMm();
      for (std::size_t f = 0; f < kFrames; ++f) {
        const float t = static_cast<float>(f + 1) / static_cast<float>(kFrames);
        for (std::size_t m = 0; m < rest.size(); ++m) {
          auto p = rest[m];
          if (m == 0) p[1] -= 400.0f * t;
          if (m == 2) p[0] -= 400.0f * t;
          spec.xyz.push_back(p);
          spec.valid.push_back(true);
        }
      }
      clip = out.path() / "crushed.c3d";
      const auto bytes = test::writeTestC3D(spec);
      std::ofstream(clip, std::ios::binary).write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
      one.clip_path = clip;
      one.iterations = kGuardIterations;  // enough to squash it
      one.solver.inversion_guard = which == 2 ? 1.0 : 3.0;
      o.solver.inversion_guard = one.solver.inversion_guard;
      if (which >= 3) {
        one.solver.inversion_guard_solves = 2;
        o.solver.inversion_guard_solves = 2;
      }
      if (which == 4) {
        one.solver.inversion_guard_threshold = 0.9;
        o.solver.inversion_guard_threshold = 0.9;
      }
    }
    (void)tools::exportClip(one);
    expectTheLiveRigsFrames(one.out, one.iterations, o, clip);
  }
  // The threshold on its own changes the frames (the same guard holding from 0.9 against 0.5).
  EXPECT_NE(readPc2(out.path() / "one4.pc2").frames, readPc2(out.path() / "one3.pc2").frames);
  auto bad = options(out.path() / "bad.pc2", 3);
  bad.solver.rotation_relaxation = 2.0;
  EXPECT_THROW_CONTAINS(tools::exportClip(bad), "--relax must be in [1, 2)");
  bad.solver.rotation_relaxation = 1.8;
  bad.solver.inversion_guard = 1.5;
  EXPECT_THROW_CONTAINS(tools::exportClip(bad), "--inversion-guard must be in [0, 1] (above 1 only with --inversion-guard-solves");
  bad.solver.inversion_guard_solves = 2;
  bad.solver.inversion_guard = 1001.0;
  EXPECT_THROW_CONTAINS(tools::exportClip(bad), "--inversion-guard must be in [0, 1000] with --inversion-guard-solves");
  bad.solver.inversion_guard = 2.0;
  bad.solver.inversion_guard_threshold = 0.0;
  EXPECT_THROW_CONTAINS(tools::exportClip(bad), "--inversion-guard-threshold must be in [0.01, 1]");
  EXPECT_FALSE(std::filesystem::exists(out.path() / "bad.pc2"));
}

// Samples at exactly (0, 0, 0) with residual 0 are gaps (predicted), as in `tetrig run`, unless
// keep_zero_markers (then measured there).
TEST(Export, ZeroSamplesAreGapsUnlessKept) {
  test::TestC3DSpec spec;
  spec.floating = true;
  spec.scale = 1.0f;
  spec.rate = kRate;
  spec.frames = 6;
  spec.labels = {"TOP", "LEFT", "RIGHT", "FRONT", "BACK"};
  for (std::size_t f = 0; f < spec.frames; ++f) {
    for (std::size_t m = 0; m < 5; ++m) {
      const bool zero = m == 0 && (f == 2 || f == 3);
      spec.xyz.push_back(zero ? std::array<float, 3>{0, 0, 0} : test::smallMarkerPositionsMm()[m]);
      spec.fourth_words.push_back(zero ? 0.0 : 515.0);  // residual word: 0 for the zero samples
    }
  }
  const TempDir out;
  auto o = options(out.path() / "z.pc2");
  o.clip_path = out.writeBytes("zero.c3d", test::writeTestC3D(spec));
  EXPECT_EQ(tools::exportClip(o).predicted_frames, 2u);
  o.keep_zero_markers = true;
  EXPECT_EQ(tools::exportClip(o).predicted_frames, 0u);
}

TEST(Export, ObjSequenceHoldsEveryFrame) {
  const TempDir out;
  const tools::ExportReport r = tools::exportClip(options(out.path() / "anim_###.obj"));
  const auto reference = liveRigFrames(0, kFrames, 3);
  const auto tris = rigTriangles();
  std::vector<std::string> expected;
  for (std::size_t f = 0; f < kFrames; ++f) {
    char name[32];
    std::snprintf(name, sizeof name, "anim_%03zu.obj", f);
    expected.push_back(name);
    const TextMesh m = readObj(out.path() / name);
    EXPECT_EQ(m.v, reference[f]) << name;  // shortest round-trip decimals: exact floats
    EXPECT_EQ(m.f, tris) << name;
  }
  EXPECT_EQ(listDir(out.path()), expected);  // the staging directory is gone
  EXPECT_EQ(r.files.size(), kFrames);
}

TEST(Export, PlySequenceWithFrameNumbersOfTheRange) {
  const TempDir out;
  auto o = options(out.path() / "f#.ply");
  o.frames = "8:";
  (void)tools::exportClip(o);
  const auto reference = liveRigFrames(8, kFrames, 3);
  EXPECT_EQ(listDir(out.path()), (std::vector<std::string>{"f10.ply", "f11.ply", "f8.ply", "f9.ply"}));
  for (std::size_t k = 0; k < 4; ++k) {
    const TextMesh m = readPly(out.path() / ("f" + std::to_string(8 + k) + ".ply"));
    EXPECT_EQ(m.v, reference[k]);
    EXPECT_EQ(m.f, rigTriangles());
    ASSERT_FALSE(m.comments.empty());
  }
}

void checkGltf(const std::filesystem::path& path, bool binary) {
  tinygltf::Model model;
  tinygltf::TinyGLTF loader;
  std::string err, warn;
  const bool ok = binary ? loader.LoadBinaryFromFile(&model, &err, &warn, path.string())
                         : loader.LoadASCIIFromFile(&model, &err, &warn, path.string());
  ASSERT_TRUE(ok) << err;
  EXPECT_TRUE(err.empty()) << err;
  EXPECT_TRUE(warn.empty()) << warn;
  ASSERT_EQ(model.meshes.size(), 1u);
  ASSERT_EQ(model.meshes[0].primitives.size(), 1u);
  const tinygltf::Primitive& prim = model.meshes[0].primitives[0];
  auto floats = [&](int accessor_index) {
    const tinygltf::Accessor& a = model.accessors[static_cast<std::size_t>(accessor_index)];
    const tinygltf::BufferView& v = model.bufferViews[static_cast<std::size_t>(a.bufferView)];
    EXPECT_EQ(a.componentType, TINYGLTF_COMPONENT_TYPE_FLOAT);
    const std::size_t n = a.count * static_cast<std::size_t>(tinygltf::GetNumComponentsInType(static_cast<std::uint32_t>(a.type)));
    std::vector<float> out(n);
    std::memcpy(out.data(), model.buffers[static_cast<std::size_t>(v.buffer)].data.data() + v.byteOffset + a.byteOffset, n * 4);
    return out;
  };
  const std::vector<float> rest = floats(prim.attributes.at("POSITION"));
  EXPECT_EQ(rest, rigRest());
  // A rig without texture coordinates: no split, no TEXCOORD_0, no material; normals all the same.
  EXPECT_EQ(prim.attributes.count("NORMAL"), 1u);
  EXPECT_EQ(prim.attributes.count("TEXCOORD_0"), 0u);
  EXPECT_TRUE(model.materials.empty());
  EXPECT_EQ(prim.material, -1);
  EXPECT_EQ(model.asset.extras.Get("tetrig_export").Get("seam_copies").ArrayLen(), 0u);
  const tinygltf::Accessor& ia = model.accessors[static_cast<std::size_t>(prim.indices)];
  ASSERT_EQ(ia.componentType, TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT);
  const tinygltf::BufferView& iv = model.bufferViews[static_cast<std::size_t>(ia.bufferView)];
  std::vector<std::int32_t> indices(ia.count);
  std::memcpy(indices.data(), model.buffers[0].data.data() + iv.byteOffset + ia.byteOffset, ia.count * 4);
  EXPECT_EQ(indices, rigTriangles());
  // One morph target per frame: rest + delta = the frame (float rounding of the sum: 1e-7 m).
  const auto reference = liveRigFrames(0, kFrames, 3);
  ASSERT_EQ(prim.targets.size(), kFrames);
  for (std::size_t f = 0; f < kFrames; ++f) {
    std::vector<float> pos = floats(prim.targets[f].at("POSITION"));
    for (std::size_t i = 0; i < pos.size(); ++i) pos[i] += rest[i];
    EXPECT_LT(maxDifference(pos, reference[f]), 1e-7) << "frame " << f;
    EXPECT_EQ(prim.targets[f].count("NORMAL"), 1u);
  }
  // The animation: sample k at k / rate has weight 1 on target k only.
  ASSERT_EQ(model.animations.size(), 1u);
  ASSERT_EQ(model.animations[0].channels.size(), 1u);
  EXPECT_EQ(model.animations[0].channels[0].target_path, "weights");
  EXPECT_EQ(model.animations[0].channels[0].target_node, 0);
  const tinygltf::AnimationSampler& s = model.animations[0].samplers[0];
  EXPECT_EQ(s.interpolation, "LINEAR");
  const std::vector<float> times = floats(s.input), weights = floats(s.output);
  ASSERT_EQ(times.size(), kFrames);
  ASSERT_EQ(weights.size(), kFrames * kFrames);
  for (std::size_t k = 0; k < kFrames; ++k) {
    EXPECT_FLOAT_EQ(times[k], static_cast<float>(k) / kRate);
    for (std::size_t t = 0; t < kFrames; ++t) EXPECT_EQ(weights[k * kFrames + t], k == t ? 1.0f : 0.0f);
  }
  ASSERT_EQ(model.nodes.size(), 1u);
  EXPECT_EQ(model.nodes[0].mesh, 0);
  const tinygltf::Value& info = model.asset.extras.Get("tetrig_export");
  ASSERT_TRUE(info.IsObject());
  EXPECT_EQ(info.Get("rate_hz").GetNumberAsDouble(), kRate);
  EXPECT_EQ(info.Get("first_frame").GetNumberAsInt(), 0);
  EXPECT_EQ(info.Get("frames").GetNumberAsInt(), static_cast<int>(kFrames));
}

TEST(Export, GlbParsesBackWithTheSamePositions) {
  const TempDir out;
  (void)tools::exportClip(options(out.path() / "anim.glb"));
  checkGltf(out.path() / "anim.glb", true);
  const auto b = slurp(out.path() / "anim.glb");
  ASSERT_GE(b.size(), 12u);
  EXPECT_EQ(std::memcmp(b.data(), "glTF", 4), 0);
  EXPECT_EQ(readAt<std::uint32_t>(b, 8), b.size());
}

TEST(Export, GltfIsOneSelfContainedFile) {
  const TempDir out;
  (void)tools::exportClip(options(out.path() / "anim.gltf"));
  checkGltf(out.path() / "anim.gltf", false);
  EXPECT_EQ(listDir(out.path()), std::vector<std::string>{"anim.gltf"});
}

// ---- the asset's texture coordinates and materials (uv_box_asset.hpp: a UV-mapped OBJ with seams,
// quads, two materials used alternately, relative indices) ----

// The rig built from the UV box, once per binary; the asset lies in a folder of its own, the
// exports go elsewhere (their references to box.mtl and the texture are relative paths with "..").
struct UvScene {
  UvScene() : asset(test::writeUvBoxAsset(asset_dir)), rig(test::buildUvBoxRig(dir, asset, &report)) {
    rig_path = dir.writeBytes("uv.rig", serializeRig(rig));
  }
  TempDir asset_dir, dir;
  test::UvBoxAsset asset;
  rigbuild::BuildRigReport report;
  Rig rig;
  std::filesystem::path rig_path;
};
const UvScene& uvScene() {
  static const UvScene s;
  return s;
}

// Reference frames of the UV rig (as liveRigFrames), and its live normals when `normals`.
std::vector<std::vector<float>> uvRigFrames(int iterations, std::vector<std::vector<float>>* normals = nullptr) {
  const drivers::C3DClip clip = drivers::C3DClip::load(scene().clip_path);
  drivers::C3DPlaybackOptions po;
  po.pacing = drivers::Pacing::kAsFastAsPossible;
  const drivers::C3DPlayback playback(clip, po);
  LiveRigOptions lo = plainLive();  // as uvOptions
  lo.normals = normals != nullptr;
  LiveRig live(uvScene().rig, lo);
  EXPECT_EQ(live.bindLabels(clip.labels()).matched, 5);
  std::vector<std::vector<float>> out;
  if (normals) normals->assign(1, std::vector<float>(live.restNormals().begin(), live.restNormals().end()));  // [0]: rest
  MarkerFrame frame{};
  for (std::size_t f = 0; f < kFrames; ++f) {
    playback.fillFrame(f, f, frame);
    std::vector<float> x(static_cast<std::size_t>(live.fineVertexCount()) * 3), n(x.size());
    live.processFrame(frame, StepBudget{iterations}, x.data(), normals ? n.data() : nullptr);
    out.push_back(std::move(x));
    if (normals) normals->push_back(std::move(n));
  }
  return out;
}

tools::ExportOptions uvOptions(const std::filesystem::path& out) {
  auto o = options(out);
  o.rig_path = uvScene().rig_path;
  return o;
}

// An OBJ with texture coordinates, read as text: v, vt, mtllib, and per face its (v, vt) corners
// (vt -1 when absent) and the material in force.
struct TexturedObj {
  std::vector<float> v;
  std::vector<std::array<double, 2>> vt;
  std::vector<std::string> mtllib;
  std::vector<std::vector<std::array<int, 2>>> faces;
  std::vector<std::string> materials;
};
TexturedObj readTexturedObj(const std::filesystem::path& p) {
  std::ifstream in(p);
  TexturedObj m;
  std::string line, material;
  while (std::getline(in, line)) {
    std::istringstream s(line);
    std::string tag;
    s >> tag;
    if (tag == "v") {
      float x, y, z;
      s >> x >> y >> z;
      m.v.insert(m.v.end(), {x, y, z});
    } else if (tag == "vt") {
      std::string u, w;
      s >> u >> w;
      m.vt.push_back({std::stod(u), std::stod(w)});
    } else if (tag == "mtllib") {
      m.mtllib.push_back(line.substr(7));
    } else if (tag == "usemtl") {
      material = line.substr(7);
    } else if (tag == "f") {
      std::vector<std::array<int, 2>> face;
      std::string corner;
      while (s >> corner) {
        const std::size_t slash = corner.find('/');
        face.push_back({std::stoi(corner.substr(0, slash)) - 1, slash == std::string::npos ? -1 : std::stoi(corner.substr(slash + 1)) - 1});
      }
      m.faces.push_back(face);
      m.materials.push_back(material);
    }
  }
  return m;
}

// The source face holding fine vertices a, b, c (the UV box has no duplicate or unused vertex:
// fine vertex i is file vertex i), or -1.
int sourceFace(const test::UvBoxAsset& asset, int a, int b, int c) {
  for (std::size_t f = 0; f < asset.faces.size(); ++f) {
    int found = 0;
    for (const int v : {a, b, c})
      for (const auto& corner : asset.faces[f]) found += corner[0] == v ? 1 : 0;
    if (found == 3) return static_cast<int>(f);
  }
  return -1;
}
// The vt of source face f at vertex v.
int sourceUv(const test::UvBoxAsset& asset, int f, int v) {
  for (const auto& corner : asset.faces[static_cast<std::size_t>(f)])
    if (corner[0] == v) return corner[1];
  return -1;
}

// Triangles that each lie on one source face, with each corner's vt the source face's at that
// vertex and the face's material, in the source's face order, every quad covered by two.
void expectTheSourcesFaces(const TexturedObj& obj, const test::UvBoxAsset& asset, const std::string& what) {
  SCOPED_TRACE(what);
  ASSERT_EQ(obj.faces.size(), 2 * asset.faces.size());
  std::vector<int> covered(asset.faces.size(), 0);
  int previous = -1;
  for (std::size_t t = 0; t < obj.faces.size(); ++t) {
    const auto& tri = obj.faces[t];
    ASSERT_EQ(tri.size(), 3u);
    const int f = sourceFace(asset, tri[0][0], tri[1][0], tri[2][0]);
    ASSERT_GE(f, 0) << "triangle " << t << " lies on no source face";
    EXPECT_GE(f, previous) << "triangle " << t << ": not in the source's face order";
    previous = f;
    ++covered[static_cast<std::size_t>(f)];
    for (const auto& [v, vt] : tri) EXPECT_EQ(vt, sourceUv(asset, f, v)) << "triangle " << t << " vertex " << v;
    EXPECT_EQ(obj.materials[t], asset.face_materials[static_cast<std::size_t>(f)]) << "triangle " << t;
  }
  EXPECT_EQ(covered, std::vector<int>(asset.faces.size(), 2));
}

std::filesystem::path resolved(const std::filesystem::path& p) { return std::filesystem::weakly_canonical(p); }

TEST(ExportUv, TheRigKeepsTheAssetsUvsMaterialsAndFaceOrder) {
  const UvScene& uv = uvScene();
  const RigSurfaceAttributes& s = uv.rig.surface;
  ASSERT_FALSE(s.empty());
  // The fine mesh is the asset's vertex list, in its order.
  ASSERT_EQ(uv.rig.fine_vertices.rows(), static_cast<Eigen::Index>(uv.asset.vertices.size()));
  for (std::size_t i = 0; i < uv.asset.vertices.size(); ++i)
    for (int k = 0; k < 3; ++k) EXPECT_EQ(uv.rig.fine_vertices(static_cast<Eigen::Index>(i), k), uv.asset.vertices[i][static_cast<std::size_t>(k)]);
  // The vt list, exactly, in file order.
  ASSERT_EQ(s.uvs.rows(), static_cast<Eigen::Index>(uv.asset.uvs.size()));
  for (std::size_t i = 0; i < uv.asset.uvs.size(); ++i) {
    EXPECT_EQ(s.uvs(static_cast<Eigen::Index>(i), 0), uv.asset.uvs[i][0]);
    EXPECT_EQ(s.uvs(static_cast<Eigen::Index>(i), 1), uv.asset.uvs[i][1]);
  }
  // Materials in order of first use, with the .mtl's colour and texture (relative to the asset's folder).
  ASSERT_EQ(s.materials.size(), 2u);
  EXPECT_EQ(s.materials[0].name, "paint");
  EXPECT_EQ(s.materials[0].diffuse_color, Eigen::Vector3d(0.8, 0.1, 0.1));
  EXPECT_EQ(s.materials[0].diffuse_texture, "");
  EXPECT_EQ(s.materials[1].name, "skin");
  EXPECT_EQ(s.materials[1].diffuse_texture, "textures/skin.png");
  EXPECT_EQ(s.material_libraries, std::vector<std::string>{"box.mtl"});
  EXPECT_EQ(std::filesystem::path(s.asset), resolved(uv.asset.obj));
  // Every fine triangle in the source's face order with its corners' vt and its face's material.
  TexturedObj as_obj;
  for (Eigen::Index t = 0; t < uv.rig.fine_triangles.rows(); ++t) {
    std::vector<std::array<int, 2>> tri;
    for (int k = 0; k < 3; ++k) tri.push_back({uv.rig.fine_triangles(t, k), s.corner_uvs(t, k)});
    as_obj.faces.push_back(tri);
    as_obj.materials.push_back(s.materials[static_cast<std::size_t>(s.triangle_materials[static_cast<std::size_t>(t)])].name);
  }
  expectTheSourcesFaces(as_obj, uv.asset, "rig");
  // Kept through the file.
  const Rig back = loadRigFile(uv.rig_path);
  EXPECT_EQ(back.surface.uvs, s.uvs);
  EXPECT_EQ(back.surface.corner_uvs, s.corner_uvs);
  EXPECT_EQ(back.surface.triangle_materials, s.triangle_materials);
  bool noted = false;
  for (const std::string& n : uv.report.notes) noted |= n.find("texture coordinates and materials of box.obj kept: ") == 0;
  EXPECT_TRUE(noted) << ::testing::PrintToString(uv.report.notes);
}

TEST(ExportUv, RestObjAndObjSequenceCarryTheAssetsUvsAndMaterials) {
  const UvScene& uv = uvScene();
  const TempDir out;
  (void)tools::exportClip(uvOptions(out.path() / "anim.pc2"));
  (void)tools::exportClip(uvOptions(out.path() / "seq_##.obj"));
  const auto reference = uvRigFrames(3);
  const TexturedObj rest = readTexturedObj(out.path() / "anim.rest.obj");
  // The same vertex order (the PC2 plays on it), the asset's vt list exactly, its faces with their
  // vt and materials, and the asset's material library referenced from the export's folder.
  const LiveRig live(uv.rig);
  EXPECT_EQ(rest.v, std::vector<float>(live.restPositions().begin(), live.restPositions().end()));
  EXPECT_EQ(rest.vt, uv.asset.uvs);
  expectTheSourcesFaces(rest, uv.asset, "anim.rest.obj");
  ASSERT_EQ(rest.mtllib.size(), 1u);
  EXPECT_EQ(rest.mtllib[0].rfind("../", 0), 0u) << rest.mtllib[0];  // relative, out of the export's folder
  EXPECT_EQ(resolved(out.path() / rest.mtllib[0]), resolved(uv.asset.mtl));
  EXPECT_EQ(readPc2(out.path() / "anim.pc2").frames, reference);
  for (std::size_t f = 0; f < kFrames; ++f) {
    char name[32];
    std::snprintf(name, sizeof name, "seq_%02zu.obj", f);
    const TexturedObj frame = readTexturedObj(out.path() / name);
    EXPECT_EQ(frame.v, reference[f]) << name;
    EXPECT_EQ(frame.vt, rest.vt) << name;
    EXPECT_EQ(frame.faces, rest.faces) << name;
    EXPECT_EQ(frame.materials, rest.materials) << name;
    EXPECT_EQ(frame.mtllib, rest.mtllib) << name;
  }
}

// glTF: vertices split at the seams (vertex i < #V is fine vertex i, the copies follow), TEXCOORD_0
// = the source corner's (u, 1 - v), NORMAL and per-frame NORMAL deltas the live rig's normals, a
// material per asset material (the texture by a relative URI), a primitive per material; every
// morph target moves each copy as its vertex (rest + delta = the PC2's frame).
TEST(ExportUv, GltfSplitsAtSeamsAndCarriesUvsNormalsAndMaterials) {
  const UvScene& uv = uvScene();
  const TempDir out;
  (void)tools::exportClip(uvOptions(out.path() / "anim.glb"));
  std::vector<std::vector<float>> normals;
  const auto reference = uvRigFrames(3, &normals);
  tinygltf::Model model;
  tinygltf::TinyGLTF loader;
  std::string err, warn;
  ASSERT_TRUE(loader.LoadBinaryFromFile(&model, &err, &warn, (out.path() / "anim.glb").string())) << err;
  EXPECT_TRUE(warn.empty()) << warn;
  auto floats = [&](int accessor_index) {
    const tinygltf::Accessor& a = model.accessors[static_cast<std::size_t>(accessor_index)];
    const tinygltf::BufferView& v = model.bufferViews[static_cast<std::size_t>(a.bufferView)];
    const std::size_t n = a.count * static_cast<std::size_t>(tinygltf::GetNumComponentsInType(static_cast<std::uint32_t>(a.type)));
    std::vector<float> values(n);
    std::memcpy(values.data(), model.buffers[0].data.data() + v.byteOffset + a.byteOffset, n * 4);
    return values;
  };
  const std::size_t fine = uv.asset.vertices.size();
  const tinygltf::Value& info = model.asset.extras.Get("tetrig_export");
  EXPECT_EQ(info.Get("vertices").GetNumberAsInt(), static_cast<int>(fine));
  std::vector<int> source(fine);
  for (std::size_t v = 0; v < fine; ++v) source[v] = static_cast<int>(v);
  const tinygltf::Value& copies = info.Get("seam_copies");
  for (std::size_t c = 0; c < copies.ArrayLen(); ++c) source.push_back(copies.Get(static_cast<int>(c)).GetNumberAsInt());
  EXPECT_GT(source.size(), fine);  // the box's edges are seams
  // Materials: paint (its colour, not metal), skin (the texture by a relative URI, not embedded).
  ASSERT_EQ(model.materials.size(), 2u);
  EXPECT_EQ(model.materials[0].name, "paint");
  EXPECT_EQ(model.materials[0].pbrMetallicRoughness.metallicFactor, 0.0);
  EXPECT_EQ(model.materials[0].pbrMetallicRoughness.baseColorFactor, (std::vector<double>{0.8, 0.1, 0.1, 1.0}));
  EXPECT_EQ(model.materials[1].name, "skin");
  EXPECT_EQ(model.materials[1].pbrMetallicRoughness.metallicFactor, 0.0);
  const int texture = model.materials[1].pbrMetallicRoughness.baseColorTexture.index;
  ASSERT_GE(texture, 0);
  const tinygltf::Image& image = model.images[static_cast<std::size_t>(model.textures[static_cast<std::size_t>(texture)].source)];
  EXPECT_EQ(image.uri.rfind("../", 0), 0u) << image.uri;
  EXPECT_EQ(resolved(out.path() / image.uri), resolved(uv.asset.texture));
  EXPECT_EQ(image.bufferView, -1);
  ASSERT_EQ(model.meshes.size(), 1u);
  const auto& prims = model.meshes[0].primitives;
  ASSERT_EQ(prims.size(), 2u);
  std::size_t triangles = 0;
  for (const tinygltf::Primitive& prim : prims) {
    // Every primitive shares the vertices and the morph targets.
    EXPECT_EQ(prim.attributes, prims[0].attributes);
    EXPECT_EQ(prim.targets, prims[0].targets);
    ASSERT_TRUE(prim.attributes.count("TEXCOORD_0") && prim.attributes.count("NORMAL"));
    const std::vector<float> texcoord = floats(prim.attributes.at("TEXCOORD_0")), position = floats(prim.attributes.at("POSITION"));
    ASSERT_EQ(texcoord.size(), 2 * source.size());
    ASSERT_EQ(position.size(), 3 * source.size());
    const std::string material = model.materials[static_cast<std::size_t>(prim.material)].name;
    const tinygltf::Accessor& ia = model.accessors[static_cast<std::size_t>(prim.indices)];
    std::vector<std::uint32_t> indices(ia.count);
    std::memcpy(indices.data(), model.buffers[0].data.data() + model.bufferViews[static_cast<std::size_t>(ia.bufferView)].byteOffset, ia.count * 4);
    for (std::size_t t = 0; t < indices.size(); t += 3, ++triangles) {
      int v[3];
      for (int k = 0; k < 3; ++k) v[k] = source[indices[t + static_cast<std::size_t>(k)]];
      const int f = sourceFace(uv.asset, v[0], v[1], v[2]);
      ASSERT_GE(f, 0);
      EXPECT_EQ(material, uv.asset.face_materials[static_cast<std::size_t>(f)]);
      for (int k = 0; k < 3; ++k) {
        const std::size_t split = indices[t + static_cast<std::size_t>(k)];
        const auto& src = uv.asset.uvs[static_cast<std::size_t>(sourceUv(uv.asset, f, v[k]))];
        EXPECT_NEAR(texcoord[2 * split], src[0], 1e-7) << "split vertex " << split;
        EXPECT_NEAR(1.0 - texcoord[2 * split + 1], src[1], 1e-7) << "split vertex " << split;
      }
    }
  }
  EXPECT_EQ(triangles, 2 * uv.asset.faces.size());
  // Positions and normals: the rest and every frame, each split vertex as its source vertex.
  const tinygltf::Primitive& prim = prims[0];
  auto expectPerSource = [&](const std::vector<float>& got, const std::vector<float>& fine_values, double tolerance, const std::string& what) {
    ASSERT_EQ(got.size(), 3 * source.size()) << what;
    double worst = 0;
    for (std::size_t v = 0; v < source.size(); ++v)
      for (std::size_t k = 0; k < 3; ++k)
        worst = std::max(worst, std::abs(double{got[3 * v + k]} - fine_values[3 * static_cast<std::size_t>(source[v]) + k]));
    EXPECT_LE(worst, tolerance) << what;
  };
  const std::vector<float> rest = floats(prim.attributes.at("POSITION")), rest_normals = floats(prim.attributes.at("NORMAL"));
  const LiveRig live(uv.rig);
  expectPerSource(rest, std::vector<float>(live.restPositions().begin(), live.restPositions().end()), 0.0, "rest");
  expectPerSource(rest_normals, normals[0], 0.0, "rest normals");
  ASSERT_EQ(prim.targets.size(), kFrames);
  for (std::size_t f = 0; f < kFrames; ++f) {
    std::vector<float> pos = floats(prim.targets[f].at("POSITION")), nrm = floats(prim.targets[f].at("NORMAL"));
    for (std::size_t i = 0; i < pos.size(); ++i) {
      pos[i] += rest[i];
      nrm[i] += rest_normals[i];
    }
    expectPerSource(pos, reference[f], 1e-7, "frame " + std::to_string(f));
    expectPerSource(nrm, normals[f + 1], 1e-6, "normals of frame " + std::to_string(f));
  }
}

// PLY holds one uv per vertex: the UV box (seams) exports none, an asset whose vertices each have
// one uv exports them as s, t.
TEST(ExportUv, PlyCarriesUvsOnlyWithoutSeams) {
  const TempDir out;
  (void)tools::exportClip(uvOptions(out.path() / "seams_#.ply"));
  auto header = [](const std::filesystem::path& p) {
    const auto b = slurp(p);
    const std::string text(b.begin(), b.end());
    return text.substr(0, text.find("end_header\n"));
  };
  EXPECT_EQ(header(out.path() / "seams_0.ply").find("property float s"), std::string::npos);
  const TempDir asset_dir, dir;
  const test::UvBoxAsset seamless = test::writeUvBoxAsset(asset_dir, false);
  const Rig rig = test::buildUvBoxRig(dir, seamless);
  ASSERT_FALSE(rig.surface.empty());
  auto o = options(out.path() / "one_#.ply");
  o.rig_path = dir.writeBytes("seamless.rig", serializeRig(rig));
  (void)tools::exportClip(o);
  const auto b = slurp(out.path() / "one_3.ply");
  const std::string h = header(out.path() / "one_3.ply");
  EXPECT_NE(h.find("property float z\nproperty float s\nproperty float t\n"), std::string::npos) << h;
  const std::size_t at = h.size() + std::string("end_header\n").size();
  ASSERT_GE(b.size(), at + seamless.vertices.size() * 20);
  for (std::size_t v = 0; v < seamless.vertices.size(); ++v) {
    EXPECT_EQ(readAt<float>(b, at + 20 * v + 12), static_cast<float>(seamless.uvs[v][0])) << v;
    EXPECT_EQ(readAt<float>(b, at + 20 * v + 16), static_cast<float>(seamless.uvs[v][1])) << v;
  }
}

// The encoders on their own: OBJ lines, the seam split, per-vertex uvs.
TEST(ExportUv, EncodersFromArrays) {
  // Two triangles sharing the edge 1-2; vertex 2's corners disagree on their uv (a seam), vertex 1's agree.
  const std::vector<float> v = {0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 1, 0};
  const std::vector<std::int32_t> f = {0, 1, 2, 2, 1, 3};
  const std::vector<double> uvs = {0, 0, 1, 0, 0, 1, 0.5, 0.75, 1, 1};
  const std::vector<std::int32_t> corner_uvs = {0, 1, 2, 3, 1, 4}, materials = {1, 0};
  tools::SurfaceLayout s;
  s.material_libraries = {"../assets/a b.mtl"};
  s.materials = {{"red", "", {1, 0, 0}}, {"skin", "tex/skin 1.png", {1, 1, 1}}};
  s.uvs = uvs;
  s.corner_uvs = corner_uvs;
  s.triangle_materials = materials;
  const std::vector<std::string> comment = {"c"};
  EXPECT_EQ(tools::objText(v, f, comment, &s),
            "# c\nmtllib ../assets/a b.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nvt 0.5 0.75\nvt 1 1\n"
            "usemtl skin\nf 1/1 2/2 3/3\nusemtl red\nf 3/4 2/2 4/5\n");
  const tools::SeamSplit split = tools::splitAtSeams(4, f, s);
  EXPECT_EQ(split.source, (std::vector<std::int32_t>{0, 1, 2, 3, 2}));
  EXPECT_EQ(split.triangles, (std::vector<std::int32_t>{0, 1, 2, 4, 1, 3}));
  EXPECT_EQ(split.uvs, (std::vector<float>{0, 0, 1, 0, 0, 1, 1, 1, 0.5f, 0.75f}));
  EXPECT_FALSE(tools::perVertexUvs(4, f, s).has_value());  // vertex 2 has two uvs
  const std::vector<std::int32_t> agreeing = {0, 1, 2, 2, 1, 4};
  s.corner_uvs = agreeing;
  EXPECT_EQ(tools::perVertexUvs(4, f, s), (std::vector<float>{0, 0, 1, 0, 0, 1, 1, 1}));
  const std::vector<std::int32_t> partial = {0, 1, 2, -1, 1, 4};
  s.corner_uvs = partial;
  EXPECT_FALSE(tools::perVertexUvs(4, f, s).has_value());  // a corner without a uv
  EXPECT_EQ(tools::objText(v, f, {}, &s),
            "mtllib ../assets/a b.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nvt 0.5 0.75\nvt 1 1\n"
            "usemtl skin\nf 1/1 2/2 3/3\nusemtl red\nf 3 2 4\n");
  const std::vector<std::int32_t> bad = {0, 1, 5, 2, 1, 4};
  s.corner_uvs = bad;
  EXPECT_THROW((void)tools::objText(v, f, {}, &s), std::invalid_argument);
  // The texture's URI is percent-encoded (a space), the image not embedded.
  s.corner_uvs = corner_uvs;
  tools::GltfAnimation a;
  a.name = "t";
  a.rest = v;
  a.triangles = f;
  a.frames = v;
  a.frame_count = 1;
  a.rate_hz = 30;
  a.surface = &s;
  const std::vector<std::uint8_t> gltf = tools::gltfBytes(a, false);
  const std::string json(gltf.begin(), gltf.end());
  EXPECT_NE(json.find("\"uri\":\"tex/skin%201.png\""), std::string::npos) << json.substr(0, 2000);
}

TEST(Export, ClearErrorsAndNothingWritten) {
  const TempDir out;
  auto with = [&](const std::string& name, const std::string& frames = "") {
    auto o = options(out.path() / name);
    o.frames = frames;
    return o;
  };
  EXPECT_THROW_CONTAINS(tools::exportClip(with("anim.fbx")), "unknown output format '.fbx'");
  EXPECT_THROW_CONTAINS(tools::exportClip(with("anim")), "unknown output format '(no extension)'");
  EXPECT_THROW_CONTAINS(tools::exportClip(with("anim.obj")), "needs a frame-number pattern such as");
  EXPECT_THROW_CONTAINS(tools::exportClip(with("a#_#.obj")), "one run of '#' only");
  EXPECT_THROW_CONTAINS(tools::exportClip(with("a##.pc2")), "for OBJ and PLY sequences only");
  EXPECT_THROW_CONTAINS(tools::exportClip(with("missing/a.pc2")), "does not exist");
  EXPECT_THROW_CONTAINS(tools::exportClip(with("a.pc2", "12:")), "first frame 12 is past the end; the clip has 12 frames (0..11)");
  EXPECT_THROW_CONTAINS(tools::exportClip(with("a.pc2", "0:13")), "end 13 is past the end");
  EXPECT_THROW_CONTAINS(tools::exportClip(with("a.pc2", "5:5")), "the range is empty");
  EXPECT_THROW_CONTAINS(tools::exportClip(with("a.pc2", "x:3")), "'x' is not a frame number");
  EXPECT_THROW_CONTAINS(tools::exportClip(with("a.pc2", "3")), "expected A:B");
  {
    auto o = with("a.pc2");
    o.out = out.path();
    EXPECT_THROW_CONTAINS(tools::exportClip(o), "is a directory");
  }
  // A clip of other markers.
  test::TestC3DSpec other;
  other.floating = true;
  other.scale = 1.0f;
  other.frames = 2;
  other.labels = {"ELBOW", "KNEE"};
  other.xyz = {{0, 0, 0}, {1, 1, 1}, {0, 0, 0}, {1, 1, 1}};
  other.valid = {true, true, true, true};
  const TempDir clips;
  {
    auto o = with("a.pc2");
    o.clip_path = clips.writeBytes("other.c3d", test::writeTestC3D(other));
    EXPECT_THROW_CONTAINS(tools::exportClip(o), "the clip's markers share no label with the rig (rig: TOP, LEFT, RIGHT, FRONT, BACK; clip other.c3d: ELBOW, KNEE)");
  }
  // Frames in which no marker is measured: nothing to export (all would be the rest pose).
  {
    auto o = with("a.pc2", "8:12");
    o.clip_path = clips.writeBytes("lost.c3d", test::movingClip(kFrames, true));
    EXPECT_THROW_CONTAINS(tools::exportClip(o), "no frame in 8..11 measures any rig marker");
  }
  // glTF beyond its frame limit is refused before any frame is solved.
  {
    auto o = with("a.glb");
    o.clip_path = clips.writeBytes("long.c3d", test::movingClip(tools::kMaxGltfFrames + 1));
    o.on_frame = [](std::size_t, std::size_t) { ADD_FAILURE() << "a frame was solved"; };
    EXPECT_THROW_CONTAINS(tools::exportClip(o), "1001 frames is more than 1000; export a range with --range A:B");
    o.frames = "0:1000";
    o.on_frame = {};
    (void)tools::exportClip(o);  // the limit itself is fine
    EXPECT_TRUE(std::filesystem::exists(out.path() / "a.glb"));
    std::filesystem::remove(out.path() / "a.glb");
  }
  EXPECT_TRUE(listDir(out.path()).empty());
}

// A failure after some frames were written (here: the progress callback throws) leaves no file
// and no temporary, and an existing output keeps its old content.
TEST(Export, CancelledExportTouchesNothing) {
  struct Case {
    const char* out;
    std::vector<std::string> existing;  // sorted
  };
  const Case cases[] = {{"anim.pc2", {"anim.pc2", "anim.rest.obj"}}, {"anim_##.obj", {"anim_05.obj"}}, {"anim_##.ply", {"anim_05.ply"}},
                        {"anim.glb", {"anim.glb"}}, {"anim.gltf", {"anim.gltf"}}};
  for (const Case& c : cases) {
    SCOPED_TRACE(c.out);
    const TempDir out;
    for (const std::string& e : c.existing) out.write(e, "old " + e + "\n");
    auto o = options(out.path() / c.out);
    o.force = true;  // the old files are not tetrig's: without it they are refused before any work
    o.on_frame = [](std::size_t done, std::size_t) {
      if (done == 6) throw std::runtime_error("cancelled at frame 6");
    };
    EXPECT_THROW_CONTAINS(tools::exportClip(o), "cancelled at frame 6");
    EXPECT_EQ(listDir(out.path()), c.existing);  // no new file, no temporary
    for (const std::string& e : c.existing) {
      const auto bytes = slurp(out.path() / e);
      EXPECT_EQ(std::string(bytes.begin(), bytes.end()), "old " + e + "\n");
    }
  }
}

// The user's files are never lost: the rest mesh beside a point cache has a name of its own, an
// existing file tetrig did not write is refused before any work (unless --force), a file tetrig
// wrote is replaced, and an input is never an output, even with --force.
TEST(Export, NeverReplacesAUsersFile) {
  const TempDir out;
  auto user = [&](const std::string& name) {
    const std::string text = "# Blender v3.4 OBJ File: '" + name + "'\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
    out.write(name, text);
    return text;
  };
  auto content = [&](const std::string& name) {
    const auto b = slurp(out.path() / name);
    return std::string(b.begin(), b.end());
  };
  auto noWork = [](tools::ExportOptions o) {
    o.on_frame = [](std::size_t, std::size_t) { ADD_FAILURE() << "a frame was solved before the refusal"; };
    return o;
  };
  // FILE.pc2 beside the user's FILE.obj (the mesh they made the cache for): the OBJ stays.
  const std::string mesh = user("human.obj");
  const tools::ExportReport r = tools::exportClip(options(out.path() / "human.pc2"));
  EXPECT_EQ(content("human.obj"), mesh);
  EXPECT_EQ(r.files, (std::vector<std::filesystem::path>{out.path() / "human.rest.obj", out.path() / "human.pc2"}));
  // Exported again: both files are tetrig's and are replaced.
  (void)tools::exportClip(options(out.path() / "human.pc2", 2));
  EXPECT_EQ(readPc2(out.path() / "human.pc2").frames, liveRigFrames(0, kFrames, 2));
  EXPECT_EQ(content("human.obj"), mesh);

  // Files tetrig did not write, each format: refused in one line, nothing written, nothing solved.
  const std::string walk_rest = user("walk.rest.obj");
  EXPECT_THROW_CONTAINS(tools::exportClip(noWork(options(out.path() / "walk.pc2"))),
                        "walk.rest.obj exists and tetrig did not write it: refusing to replace it; give another name, or add --force");
  EXPECT_FALSE(std::filesystem::exists(out.path() / "walk.pc2"));
  out.write("cache.pc2", "POINTCACHE2");  // a point cache with no rest mesh of tetrig's beside it
  EXPECT_THROW_CONTAINS(tools::exportClip(noWork(options(out.path() / "cache.pc2"))), "cache.pc2 exists and tetrig did not write it");
  user("seq_05.obj");
  EXPECT_THROW_CONTAINS(tools::exportClip(noWork(options(out.path() / "seq_##.obj"))), "seq_05.obj exists and tetrig did not write it");
  EXPECT_FALSE(std::filesystem::exists(out.path() / "seq_00.obj"));
  out.write("seq_07.ply", "ply\nformat ascii 1.0\ncomment made by hand\nend_header\n");
  EXPECT_THROW_CONTAINS(tools::exportClip(noWork(options(out.path() / "seq_##.ply"))), "seq_07.ply exists and tetrig did not write it");
  out.write("scene.gltf", "{\"asset\":{\"generator\":\"Khronos glTF Blender I/O\",\"version\":\"2.0\"}}");
  EXPECT_THROW_CONTAINS(tools::exportClip(noWork(options(out.path() / "scene.gltf"))), "scene.gltf exists and tetrig did not write it");
  EXPECT_EQ(content("walk.rest.obj"), walk_rest);

  // With --force the user's file is replaced.
  auto forced = options(out.path() / "walk.pc2");
  forced.force = true;
  (void)tools::exportClip(forced);
  EXPECT_NE(content("walk.rest.obj"), walk_rest);
  EXPECT_EQ(readPc2(out.path() / "walk.pc2").frames, liveRigFrames(0, kFrames, 3));

  // Every format tetrig wrote is replaced without --force on a second export.
  for (const char* name : {"again_##.obj", "again_##.ply", "again.gltf", "again.glb"}) {
    SCOPED_TRACE(name);
    (void)tools::exportClip(options(out.path() / name));
    EXPECT_NO_THROW((void)tools::exportClip(options(out.path() / name, 2)));
  }

  // An input is never an output, whatever its name and even with --force.
  const std::filesystem::path rig_as_glb = out.path() / "rig.glb";
  std::filesystem::copy_file(scene().rig_path, rig_as_glb);
  auto onto_input = noWork(options(rig_as_glb));
  onto_input.rig_path = rig_as_glb;
  onto_input.force = true;
  EXPECT_THROW_CONTAINS(tools::exportClip(onto_input), "rig.glb is also an input of this command: writing it would lose the input");
  const std::filesystem::path clip_frame = out.path() / "take_03.obj";
  std::filesystem::create_hard_link(scene().clip_path, clip_frame);
  auto onto_clip = noWork(options(out.path() / "take_##.obj"));
  onto_clip.force = true;
  EXPECT_THROW_CONTAINS(tools::exportClip(onto_clip), "take_03.obj is the same file as the input ");
}

TEST(Export, FormatsFromBytes) {
  // PC2 header layout, byte for byte.
  const auto h = tools::pc2Header(7, 2.0f, 1.0f, 5);
  ASSERT_EQ(h.size(), tools::kPc2HeaderBytes);
  EXPECT_EQ(std::string(reinterpret_cast<const char*>(h.data()), 12), std::string("POINTCACHE2\0", 12));
  EXPECT_EQ(readAt<std::int32_t>(h, 12), 1);
  EXPECT_EQ(readAt<std::int32_t>(h, 16), 7);
  EXPECT_EQ(readAt<float>(h, 20), 2.0f);
  EXPECT_EQ(readAt<float>(h, 24), 1.0f);
  EXPECT_EQ(readAt<std::int32_t>(h, 28), 5);
  EXPECT_THROW((void)tools::pc2Header(0, 0, 1, 1), std::invalid_argument);
  // OBJ: values that need all nine digits read back exactly; bad indices are refused.
  const std::vector<float> v = {0.1f, 1.0f / 3.0f, -2.5e-7f, 1e8f, 0, -0.0f, 3, 4, 5};
  const std::vector<std::int32_t> f = {0, 1, 2};
  const TempDir dir;
  const std::vector<std::string> comment = {"hello"};
  dir.write("t.obj", tools::objText(v, f, comment));
  const TextMesh m = readObj(dir.path() / "t.obj");
  EXPECT_EQ(m.v, v);
  EXPECT_EQ(m.f, f);
  EXPECT_EQ(m.comments, comment);
  const std::vector<std::int32_t> bad = {0, 1, 3};
  EXPECT_THROW((void)tools::objText(v, bad, {}), std::invalid_argument);
  EXPECT_THROW((void)tools::plyBytes(v, bad, {}), std::invalid_argument);
}

TEST(Export, GltfUpAxisIsY) {
  std::vector<float> p = {1, 2, 3, 4, 5, 6};
  tools::rotateUpToY("y", p);
  EXPECT_EQ(p, (std::vector<float>{1, 2, 3, 4, 5, 6}));
  const std::map<std::string, std::vector<float>> expected = {
      {"z", {1, 3, -2}}, {"-z", {1, -3, 2}}, {"x", {-2, 1, 3}}, {"-x", {2, -1, 3}}, {"-y", {1, -2, -3}}};
  for (const auto& [up, xyz] : expected) {
    std::vector<float> q = {1, 2, 3};
    tools::rotateUpToY(up, q);
    EXPECT_EQ(q, xyz) << up;
    // The up axis itself lands on +Y.
    std::vector<float> u = {0, 0, 0};
    u[static_cast<std::size_t>(up.back() - 'x')] = up[0] == '-' ? -1.0f : 1.0f;
    tools::rotateUpToY(up, u);
    EXPECT_EQ(u, (std::vector<float>{0, 1, 0})) << up;
  }
  EXPECT_THROW_CONTAINS(tools::rotateUpToY("w", p), "unknown up axis 'w'");
}

TEST(Export, TargetsAndRanges) {
  const auto seq = tools::parseExportTarget("out/anim_####.ply");
  EXPECT_EQ(seq.format, tools::ExportFormat::kPlySequence);
  EXPECT_EQ(tools::sequenceFramePath(seq, 7), std::filesystem::path("out/anim_0007.ply"));
  EXPECT_EQ(tools::sequenceFramePath(seq, 123456), std::filesystem::path("out/anim_123456.ply"));
  const auto pc2 = tools::parseExportTarget("x/walk.PC2");
  EXPECT_EQ(pc2.format, tools::ExportFormat::kPc2);
  EXPECT_EQ(pc2.rest_obj, std::filesystem::path("x/walk.rest.obj"));
  EXPECT_EQ(tools::parseExportTarget("a.GLB").format, tools::ExportFormat::kGlb);
  EXPECT_EQ(tools::parseExportTarget("a.gltf").format, tools::ExportFormat::kGltf);
  EXPECT_THROW_CONTAINS((void)tools::parseExportTarget("d#/a_#.obj"), "not in a directory");
  const auto all = tools::parseFrameRange("", 10);
  EXPECT_EQ(all.first, 0u);
  EXPECT_EQ(all.end, 10u);
  const auto tail = tools::parseFrameRange("4:", 10);
  EXPECT_EQ(tail.first, 4u);
  EXPECT_EQ(tail.end, 10u);
  const auto head = tools::parseFrameRange(":3", 10);
  EXPECT_EQ(head.first, 0u);
  EXPECT_EQ(head.end, 3u);
  EXPECT_THROW_CONTAINS((void)tools::parseFrameRange("1:2:3", 10), "expected A:B");
  EXPECT_THROW_CONTAINS((void)tools::parseFrameRange("-1:3", 10), "not a frame number");
}

// The command line: a successful export, and one-line errors with exit status 1.
TEST(Export, CommandLine) {
  const TempDir out;
  auto run = [&](const std::string& args) {
    const std::string err = (out.path() / "stderr.txt").string(), std_out = (out.path() / "stdout.txt").string();
    const std::string cmd = std::string("'") + TETRIG_EXE + "' export " + args + " >'" + std_out + "' 2>'" + err + "'";
    const int raw = std::system(cmd.c_str());
    const auto text = [](const std::string& p) {
      const auto b = slurp(p);
      std::filesystem::remove(p);
      return std::string(b.begin(), b.end());
    };
    const std::string o_text = text(std_out);
    return std::make_tuple(WIFEXITED(raw) ? WEXITSTATUS(raw) : -1, text(err), o_text);
  };
  const std::string io = "--rig '" + scene().rig_path.string() + "' --c3d '" + scene().clip_path.string() + "' ";
  const auto ok = run(io + "--out '" + (out.path() / "a.pc2").string() + "' --iterations 3 --frames 2:6 --simple-progress");
  EXPECT_EQ(std::get<0>(ok), 0) << std::get<1>(ok);
  EXPECT_NE(std::get<2>(ok).find("clip frames 2..5 (4 frames, 100 Hz)"), std::string::npos) << std::get<2>(ok);
  EXPECT_NE(std::get<1>(ok).find("tetrig export: solving 4 frames (3 iterations each)"), std::string::npos) << std::get<1>(ok);
  const Pc2 pc2 = readPc2(out.path() / "a.pc2");
  EXPECT_EQ(pc2.samples, 4);
  EXPECT_EQ(pc2.frames, liveRigFrames(2, 6, 3, LiveRigOptions{}));  // the command's defaults are the live rig's
  const auto bad = run(io + "--out '" + (out.path() / "a.fbx").string() + "'");
  const std::string& bad_err = std::get<1>(bad);
  EXPECT_EQ(std::get<0>(bad), 1);
  EXPECT_EQ(bad_err.rfind("tetrig export: error: --out ", 0), 0u) << bad_err;
  EXPECT_NE(bad_err.find("unknown output format '.fbx'"), std::string::npos) << bad_err;
  EXPECT_EQ(std::count(bad_err.begin(), bad_err.end(), '\n'), 1) << bad_err;
  const auto range = run(io + "--out '" + (out.path() / "b.pc2").string() + "' --frames 20:30");
  EXPECT_EQ(std::get<0>(range), 1);
  EXPECT_NE(std::get<1>(range).find("past the end; the clip has 12 frames"), std::string::npos) << std::get<1>(range);
  EXPECT_FALSE(std::filesystem::exists(out.path() / "b.pc2"));
  const auto help = run("--help");
  EXPECT_EQ(std::get<0>(help), 0);
  for (const char* flag : {"--rig", "--c3d", "--out", "--frames", "--iterations", "--tolerance", "--max-iterations", "--rate"})
    EXPECT_NE(std::get<2>(help).find(flag), std::string::npos) << flag;
  // Which file for which tool, texture coordinates and materials included.
  for (const char* text : {"Which file for which tool", "Mesh Cache modifier", "game engines", "texture coordinates", "no seams"})
    EXPECT_NE(std::get<2>(help).find(text), std::string::npos) << text;
}

// Ctrl-C (SIGINT) during a long export: one line, exit 1, and no file or temporary left.
TEST(Export, InterruptedCommandLeavesNothing) {
  for (const char* name : {"long.pc2", "long_####.ply"}) {
    SCOPED_TRACE(name);
    const TempDir out, in;
    const auto clip = in.writeBytes("long.c3d", test::movingClip(2000));
    const auto err = in.path() / "stderr.txt";
    const std::vector<std::string> args = {TETRIG_EXE, "export", "--rig", scene().rig_path.string(), "--c3d", clip.string(), "--out",
                                           (out.path() / name).string(), "--iterations", "300", "--quiet"};
    std::vector<char*> argv;
    for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    posix_spawn_file_actions_addopen(&fa, STDERR_FILENO, err.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    pid_t pid = -1;
    ASSERT_EQ(posix_spawn(&pid, argv[0], &fa, nullptr, argv.data(), environ), 0);
    posix_spawn_file_actions_destroy(&fa);
    // Wait until it is writing (the staged files exist), then interrupt.
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
    while (listDir(out.path()).empty() && std::chrono::steady_clock::now() < deadline)
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    EXPECT_FALSE(listDir(out.path()).empty()) << "the export never started writing";
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
    kill(pid, SIGINT);
    int status = 0;
    ASSERT_EQ(waitpid(pid, &status, 0), pid);
    ASSERT_TRUE(WIFEXITED(status)) << "killed by the signal instead of ending cleanly";
    EXPECT_EQ(WEXITSTATUS(status), 1);
    const auto text = slurp(err);
    const std::string message(text.begin(), text.end());
    EXPECT_EQ(message.rfind("tetrig export: error: interrupted (SIGINT) after ", 0), 0u) << message;
    EXPECT_NE(message.find("nothing was written"), std::string::npos) << message;
    EXPECT_TRUE(listDir(out.path()).empty()) << ::testing::PrintToString(listDir(out.path()));
  }
}

}  // namespace
}  // namespace tetrig
