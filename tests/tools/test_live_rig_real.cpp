// The live rig (runtime/include/tetrig/live_rig.hpp) on real data from ../shared/data (NOTES.md):
// rigs built from real clips on the SMPL male (human_man.obj, 1500 tet vertices as in
// bench_rig_frame), driven frame by frame through C3DPlayback::fillFrame (ids = C3D point indices,
// device time = the clip's time line), labels bound as a playback source names them.
//  - HDM05 (41 labelled markers, 120 Hz): markers removed on purpose during fast motion, compared
//    with the same frames unoccluded;
//  - c3d.org sample20 (PhaseSpace, 40 unlabelled points, 30 Hz, 226 short real gaps), compared with
//    the same clip whose gaps are filled by linear interpolation;
//  - btkdata PiG walk (30-frame gap on LFHD), rig from the same subject's static trial;
//  - btkdata mocap36 (every marker lost for the last 229 frames: the pose is held exactly).
// The bounds asserted here are the measured values with a margin; docs/live.md, "Occlusion",
// records the measurements and the command.
#include "counting_allocator.hpp"
#include "tetrig/drivers/c3d_playback.hpp"
#include "tetrig/drivers/c3d_reader.hpp"
#include "tetrig/live_rig.hpp"
#include "tetrig/marker_prediction.hpp"
#include "tetrig/rigbuild/build_rig.hpp"
#include "test_data.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <functional>
#include <map>
#include <memory>
#include <random>
#include <string>
#include <vector>

namespace tetrig {
namespace {

constexpr const char* kMan = "meshes/odedstein-meshes/human_man.obj";
constexpr const char* kHdm05 = "mocap/hdm05/HDM_mm_01-02_03_120.c3d";
constexpr const char* kSample20 = "mocap/c3d.org/sample20_phasespace_sample.c3d";
constexpr const char* kPigStatic = "mocap/btkdata/PiG_Calibration-FlatFoot-Full.c3d";
constexpr const char* kPigWalk = "mocap/btkdata/PiG_Motion-FlatFoot-Full.c3d";
constexpr const char* kMocap36 = "mocap/btkdata/mocap36.c3d";
constexpr const char* kCmu85_02 = "mocap/cmu/85_02.c3d";

struct Scene {
  Rig rig;
  drivers::C3DClip clip;
  std::vector<std::string> labels;  // by C3D point index, as a playback source names them
  std::unique_ptr<Rig> coarse;      // the same rig with 300 tet vertices (coarse level), when asked for
};

// Labels by point index: the clip's label, or "point<p>" for a point without one (the name
// `tetrig build-rig` and the playback source give it).
std::vector<std::string> pointLabels(const drivers::C3DClip& clip) {
  std::vector<std::string> labels;
  for (int p = 0; p < clip.pointCount(); ++p) {
    const std::string& l = clip.labels().empty() ? std::string() : clip.labels()[static_cast<std::size_t>(p)];
    labels.push_back(l.empty() ? "point" + std::to_string(p) : l);
  }
  return labels;
}

// Builds a scene once per binary (rig from `rig_clip` frame `frame`, driven by `drive_clip`).
using SceneBuilder = std::function<std::unique_ptr<Scene>()>;
const Scene& cachedScene(const std::string& key, const SceneBuilder& build) {
  static std::map<std::string, std::unique_ptr<Scene>> scenes;
  auto& s = scenes[key];
  if (!s) s = build();
  return *s;
}

// accept_pose_mismatch: the rig frame is not in the mesh's T-pose, or the markers cover only part of
// it (the occlusion tests below need a rig, not a good one; the build refuses such a frame otherwise).
std::unique_ptr<Scene> buildScene(const std::filesystem::path& mesh, const std::filesystem::path& rig_clip, std::int64_t frame,
                                  double max_distance, std::vector<std::string> exclude, const std::filesystem::path& drive_clip,
                                  bool accept_pose_mismatch = false, bool with_coarse = false) {
  rigbuild::BuildRigInputs in;
  in.mesh = mesh;
  in.clip = rig_clip;
  in.frame = frame;
  in.tet_vertices = 1500;
  in.max_marker_distance = max_distance;
  in.description.markers.exclude = std::move(exclude);
  // The occlusion bounds below hold for the soft binding these rigs were built with before the stiff
  // binding became the default; with the default (invisible stiffness 10, 6 faces, rigid regions) an
  // occluded marker's prediction error reaches the skin nearly 1:1 and the bounds are 1.2-5x over
  // (issue 36, open: the prediction must improve before these rigs take the default binding).
  in.description.markers.invisible_stiffness = 0.1;
  in.description.markers.faces_per_marker = 3;
  in.description.markers.rigid_regions = false;
  in.accept_pose_mismatch = accept_pose_mismatch;
  in.check_deformer = false;
  auto scene = std::make_unique<Scene>(Scene{rigbuild::buildRig(in), drivers::C3DClip::load(drive_clip), {}, nullptr});
  scene->labels = pointLabels(scene->clip);
  if (with_coarse) {
    in.tet_vertices = 300;
    scene->coarse = std::make_unique<Rig>(rigbuild::buildRig(in));
  }
  return scene;
}

drivers::C3DPlaybackOptions playbackOptions() {
  drivers::C3DPlaybackOptions o;
  o.pacing = drivers::Pacing::kAsFastAsPossible;
  return o;
}

// One live rig fed clip frames in order.
// The default settings without the temporal prediction (SolverSettings::rotation_extrapolation 0).
LiveRigOptions withoutPrediction() {
  LiveRigOptions o;
  o.solver.rotation_extrapolation = 0.0;
  return o;
}

class ClipRun {
 public:
  ClipRun(const Scene& scene, const LiveRigOptions& options = {})
      : live_(scene.rig, options, scene.coarse.get()), playback_(scene.clip, playbackOptions()) {
    binding_ = live_.bindLabels(scene.labels);
    const std::size_t n = static_cast<std::size_t>(live_.fineVertexCount()) * 3;
    x_.assign(live_.restPositions().begin(), live_.restPositions().end());
    previous_ = x_;
    normals_.resize(n);
  }

  // Clip frame f as the next frame; `edit` may change the markers (occlusion, filling) first.
  LiveFrameStats frame(std::size_t f, const std::function<void(MarkerFrame&)>& edit = {}) {
    playback_.fillFrame(f, counter_++, frame_);
    if (edit) edit(frame_);
    previous_.swap(x_);
    const LiveFrameStats s = live_.processFrame(frame_, StepBudget{3}, x_.data(), live_.options().normals ? normals_.data() : nullptr);
    rejected_samples_ += s.rejected_marker_samples;
    rejected_poses_ += (s.flags & kLivePoseRejected) ? 1 : 0;
    return s;
  }
  // Over every frame so far: marker samples rejected as implausible, poses refused by the bound.
  std::uint64_t rejectedSamples() const { return rejected_samples_; }
  std::uint64_t rejectedPoses() const { return rejected_poses_; }

  // Largest displacement of any fine vertex in the last frame.
  double lastStep() const { return maxDistance(x_, previous_); }
  static double maxDistance(const std::vector<float>& a, const std::vector<float>& b, const std::vector<std::int32_t>* only = nullptr) {
    double worst = 0.0;
    auto at = [&](std::size_t v) {
      const double dx = a[3 * v] - b[3 * v], dy = a[3 * v + 1] - b[3 * v + 1], dz = a[3 * v + 2] - b[3 * v + 2];
      worst = std::max(worst, std::sqrt(dx * dx + dy * dy + dz * dz));
    };
    if (only) {
      for (const std::int32_t v : *only) at(static_cast<std::size_t>(v));
    } else {
      for (std::size_t v = 0; v < a.size() / 3; ++v) at(v);
    }
    return worst;
  }
  // Largest difference of any fine vertex's last-frame displacement from `other`'s.
  double extraStep(const ClipRun& other) const {
    double worst = 0.0;
    for (std::size_t i = 0; i + 2 < x_.size(); i += 3) {
      double s = 0.0;
      for (int c = 0; c < 3; ++c) {
        const double d = (x_[i + c] - previous_[i + c]) - (other.x_[i + c] - other.previous_[i + c]);
        s += d * d;
      }
      worst = std::max(worst, std::sqrt(s));
    }
    return worst;
  }
  // |prediction - measurement| of every marker measured (and not blending) in the last frame.
  void collectPredictionErrors(std::vector<double>& out) {
    for (std::size_t k = 0; k < live_.rig().markers.size(); ++k) {
      if (live_.markerState(static_cast<std::int32_t>(k)) != MarkerTrackState::kMeasured || !live_.markerMeasured()[k]) continue;
      out.push_back((live_.markerPredictions()[k] - live_.markerTargets()[k]).norm());
    }
  }
  static double percentile(std::vector<double> v, double q) {
    if (v.empty()) return 0.0;
    std::sort(v.begin(), v.end());
    return v[static_cast<std::size_t>(q * static_cast<double>(v.size() - 1))];
  }
  bool allFinite() const {
    const auto finite = [](float v) { return std::isfinite(v); };
    return std::all_of(x_.begin(), x_.end(), finite) && std::all_of(normals_.begin(), normals_.end(), finite);
  }

  LiveRig& live() { return live_; }
  const std::vector<float>& positions() const { return x_; }
  const std::vector<float>& normals() const { return normals_; }
  const MarkerBindingReport& binding() const { return binding_; }
  const drivers::C3DPlayback& playback() const { return playback_; }

 private:
  LiveRig live_;
  drivers::C3DPlayback playback_;
  MarkerBindingReport binding_;
  MarkerFrame frame_{};
  std::uint64_t counter_ = 0;
  std::uint64_t rejected_samples_ = 0, rejected_poses_ = 0;
  std::vector<float> x_, previous_, normals_;
};

// Fine vertices within `radius` (rig units) of the rest positions of the named rig markers.
std::vector<std::int32_t> fineVerticesNear(const Rig& rig, const std::vector<std::string>& markers, double radius) {
  std::vector<std::int32_t> out;
  for (Eigen::Index v = 0; v < rig.fine_vertices.rows(); ++v) {
    for (const RigMarker& m : rig.markers) {
      if (std::find(markers.begin(), markers.end(), m.label) == markers.end()) continue;
      if ((rig.fine_vertices.row(v).transpose() - m.rest_position).norm() <= radius) {
        out.push_back(static_cast<std::int32_t>(v));
        break;
      }
    }
  }
  return out;
}

const Scene* smplHdm05() {
  return &cachedScene("hdm05", [] {
    return buildScene(test::dataPath(kMan), test::dataPath(kHdm05), 0, 0.15, {}, test::dataPath(kHdm05));
  });
}

// ---------------------------------------------------------------------------------------------
// HDM05: one wrist, one knee, the head removed on purpose during the clip's fastest motion.

struct Window {
  const char* name;
  std::vector<std::string> markers;  // rig labels
  std::size_t begin, end;            // clip frames [begin, end) occluded
};

TEST(LiveRigReal, Hdm05OccludedMarkersAgainstTheUnoccludedRun) {
  TETRIG_REQUIRE_DATA(man, kMan);
  TETRIG_REQUIRE_DATA(clip, kHdm05);
  const Scene& scene = *smplHdm05();
  ASSERT_EQ(scene.rig.markers.size(), 41u);
  {
    std::vector<std::int32_t> anchors;
    std::vector<std::int32_t> marker_vertices;
    for (const RigMarker& m : scene.rig.markers) marker_vertices.push_back(m.tet_vertex);
    const MarkerPredictor predictor(scene.rig.tet_mesh, scene.rig.body_vertex_count, scene.rig.body_tet_count, marker_vertices,
                                    MarkerPredictionOptions{});
    for (std::int32_t k = 0; k < predictor.markerCount(); ++k) anchors.push_back(static_cast<std::int32_t>(predictor.anchorVertices(k).size()));
    std::sort(anchors.begin(), anchors.end());
    std::printf("[ measured ] SMPL rig: %d tet vertices; anchor vertices per marker (rings %d): min %d, median %d, max %d\n",
                scene.rig.tet_mesh.vertexCount(), MarkerPredictionOptions{}.rings, anchors.front(), anchors[anchors.size() / 2], anchors.back());
  }
  // Frames 1200-1920 are the clip's fastest (mean marker step 8.3-8.8 mm per frame at 120 Hz;
  // wrists and fingers up to 57-68 mm). The run starts at frame 0 (the T-pose the rig was built in).
  const std::vector<Window> windows{{"left wrist (LWRA, LWRB), 120 frames", {"LWRA", "LWRB"}, 1250, 1370},
                                    {"right knee (RKNE), 60 frames", {"RKNE"}, 1450, 1510},
                                    {"head (LFHD, RFHD, LBHD, RBHD), 90 frames", {"LFHD", "RFHD", "LBHD", "RBHD"}, 1600, 1690}};
  constexpr std::size_t kEnd = 1920;
  constexpr std::size_t kAfter = 120;  // frames after a return over which the errors still count
  constexpr std::size_t kEdge = 24;    // frames after an edge that count as its jump (blend: 18)
  // Occlusion with the temporal prediction is an open problem (its bounds fail with
  // rotation_extrapolation 0.6 and 1): these runs keep every other default and no prediction.
  const LiveRigOptions unpredicted = withoutPrediction();
  LiveRigOptions all = unpredicted;
  all.predict_all_markers = true;  // the measured markers' predictions are collected (printed) below
  ClipRun reference(scene, all), occluded(scene, unpredicted);
  LiveRigOptions no_blend = unpredicted;
  no_blend.occlusion_blend_s = 0.0;
  ClipRun popping(scene, no_blend);
  EXPECT_EQ(occluded.binding().matched, 41);
  EXPECT_TRUE(occluded.binding().missing.empty());
  EXPECT_EQ(occluded.binding().unknown.size(), 3u);  // the virtual points *0..*2 are not physical: not in frames
  // Point index -> window, for the occlusion.
  std::vector<int> window_of(static_cast<std::size_t>(scene.clip.pointCount()), -1);
  for (std::size_t w = 0; w < windows.size(); ++w)
    for (const std::string& label : windows[w].markers) window_of[static_cast<std::size_t>(scene.clip.findPoint(label))] = static_cast<int>(w);
  std::vector<std::vector<std::int32_t>> near(windows.size());
  for (std::size_t w = 0; w < windows.size(); ++w) near[w] = fineVerticesNear(scene.rig, windows[w].markers, 0.10);

  std::vector<double> error(windows.size(), 0.0), jump(windows.size(), 0.0), extra(windows.size(), 0.0), pop(windows.size(), 0.0),
      reference_near(windows.size(), 0.0);
  double reference_motion = 0.0;
  std::vector<double> prediction_errors;
  std::int64_t reference_ns = 0, occluded_ns = 0, pose_ns = 0, timed = 0;
  const std::vector<float> rest(reference.live().restPositions().begin(), reference.live().restPositions().end());
  for (std::size_t f = 0; f < kEnd; ++f) {
    const auto occlude = [&](MarkerFrame& frame) {
      for (int k = 0; k < frame.marker_count; ++k) {
        Marker& m = frame.markers[static_cast<std::size_t>(k)];
        const int w = window_of[m.id];
        if (w >= 0 && f >= windows[static_cast<std::size_t>(w)].begin && f < windows[static_cast<std::size_t>(w)].end) m.valid = 0;
      }
    };
    const LiveFrameStats r = reference.frame(f);
    reference.collectPredictionErrors(prediction_errors);
    const LiveFrameStats s = occluded.frame(f, occlude);
    if (s.occluded_markers > 0 || s.blending_markers > 0) {
      // Timing, printed only (no timing assertions): the occluded run steps twice (refresh).
      reference_ns += r.step.total_ns;
      occluded_ns += s.step.total_ns;
      pose_ns += s.pose_transfer_ns;
      ++timed;
    }
    popping.frame(f, occlude);
    ASSERT_TRUE(occluded.allFinite()) << "frame " << f;
    reference_motion = std::max(reference_motion, reference.lastStep());
    for (std::size_t w = 0; w < windows.size(); ++w) {
      const Window& win = windows[w];
      if (f >= win.begin && f < win.end) {
        EXPECT_EQ(s.occluded_markers, win.markers.size()) << "frame " << f;
        EXPECT_TRUE(s.flags & kLiveMarkersPredicted);
      }
      if (f >= win.begin && f < win.end + kAfter) {
        error[w] = std::max(error[w], ClipRun::maxDistance(occluded.positions(), reference.positions(), &near[w]));
        reference_near[w] = std::max(reference_near[w], ClipRun::maxDistance(reference.positions(), rest, &near[w]));
      }
      const bool edge = (f >= win.begin && f < win.begin + kEdge) || (f >= win.end && f < win.end + kEdge);
      if (edge) {
        jump[w] = std::max(jump[w], occluded.lastStep());
        extra[w] = std::max(extra[w], occluded.extraStep(reference));
        pop[w] = std::max(pop[w], popping.extraStep(reference));
      }
    }
  }
  std::printf("[ measured ] HDM05 on SMPL, frames 0-%zu: largest per-frame fine-vertex motion of the unoccluded run %.1f mm\n", kEnd,
              1e3 * reference_motion);
  for (std::size_t w = 0; w < windows.size(); ++w) {
    std::printf("[ measured ] %s: %zu fine vertices within 10 cm; max error there %.1f mm (they move up to %.0f mm from rest); "
                "largest per-frame step at the edges %.1f mm, extra step over the unoccluded run %.2f mm (without blends %.2f mm)\n",
                windows[w].name, near[w].size(), 1e3 * error[w], 1e3 * reference_near[w], 1e3 * jump[w], 1e3 * extra[w], 1e3 * pop[w]);
  }
  std::printf("[ measured ] prediction - measurement of the measured markers (unoccluded run): median %.1f mm, 95 %% %.1f mm, max %.1f mm\n",
              1e3 * ClipRun::percentile(prediction_errors, 0.5), 1e3 * ClipRun::percentile(prediction_errors, 0.95),
              1e3 * ClipRun::percentile(prediction_errors, 1.0));
  std::printf("[ measured ] in the %lld frames with predicted or blending markers: step %.0f us (the same frames unoccluded %.0f us), "
              "pose transfer %.0f us (means; shared machine)\n",
              static_cast<long long>(timed), 1e-3 * static_cast<double>(occluded_ns) / static_cast<double>(timed),
              1e-3 * static_cast<double>(reference_ns) / static_cast<double>(timed), 1e-3 * static_cast<double>(pose_ns) / static_cast<double>(timed));
  // After the last window the two runs agree again.
  const double final_difference = ClipRun::maxDistance(occluded.positions(), reference.positions());
  std::printf("[ measured ] %zu frames after the last return: max difference %.3f mm\n", kEnd - windows.back().end, 1e3 * final_difference);
  for (std::size_t w = 0; w < windows.size(); ++w) {
    EXPECT_GE(near[w].size(), 10u);
    EXPECT_LE(jump[w], reference_motion) << windows[w].name;
  }
  // Measured bounds (docs/live.md, "Occlusion"), with a margin over the printed values. They
  // belong to one tessellation: across five tet meshes of the same budget (issue 13's decimation
  // and interior points, docs/live.md) the wrist error ranged 14-30 mm, the knee 5-8, the head 57-98.
  EXPECT_LE(error[0], 0.035);
  EXPECT_LE(error[1], 0.012);
  EXPECT_LE(error[2], 0.085);  // all four head markers: nothing measures the head's own turn
  EXPECT_LE(extra[0], 0.0025);
  EXPECT_LE(extra[1], 0.0010);
  EXPECT_LE(extra[2], 0.0050);
  EXPECT_GT(*std::max_element(pop.begin(), pop.end()), 2.0 * *std::max_element(extra.begin(), extra.end()))
      << "without blends the edges must show a larger extra step, or the measure proves nothing";
  EXPECT_LE(final_difference, 0.002);
  // Deliberate occlusions: every return is taken.
  for (const ClipRun* run : {&reference, &occluded, &popping}) {
    EXPECT_EQ(run->rejectedSamples(), 0u);
    EXPECT_EQ(run->rejectedPoses(), 0u);
  }
}

// ---------------------------------------------------------------------------------------------
// Implausible samples (docs/live.md, "Implausible marker samples"): none in the clean clips; a
// marker thrown 100 m, or garbage coordinates of several markers, for one frame leave that frame's
// published pose where the clean run has it.

// Sets one point's sample 100 m off along the device's x axis.
std::function<void(MarkerFrame&)> thrown(int point) {
  return [point](MarkerFrame& frame) {
    for (int k = 0; k < frame.marker_count; ++k)
      if (frame.markers[static_cast<std::size_t>(k)].id == point) frame.markers[static_cast<std::size_t>(k)].position_mm[0] += 1e5f;
  };
}

// Random coordinates for the given points: random bit patterns (any float, NaN and infinities
// included) for the first half, uniform within 5 m of the device origin for the others.
std::function<void(MarkerFrame&)> garbage(std::vector<int> points, std::uint32_t seed) {
  return [points, seed](MarkerFrame& frame) {
    std::mt19937 rng(seed);
    for (int k = 0; k < frame.marker_count; ++k) {
      Marker& m = frame.markers[static_cast<std::size_t>(k)];
      const auto it = std::find(points.begin(), points.end(), m.id);
      if (it == points.end()) continue;
      const bool bits = static_cast<std::size_t>(it - points.begin()) < points.size() / 2;
      for (float& c : m.position_mm) {
        if (bits) {
          const auto word = static_cast<std::uint32_t>(rng());
          std::memcpy(&c, &word, sizeof c);
        } else {
          c = std::uniform_real_distribution<float>(-5000.0f, 5000.0f)(rng);
        }
      }
    }
  };
}

TEST(LiveRigReal, Hdm05GlitchedFramesPublishTheCleanPose) {
  TETRIG_REQUIRE_DATA(man, kMan);
  TETRIG_REQUIRE_DATA(clip, kHdm05);
  const Scene& scene = *smplHdm05();
  const drivers::C3DClip& c = scene.clip;
  struct Glitch {
    const char* name;
    std::size_t frame;
    std::function<void(MarkerFrame&)> edit;
    std::uint16_t rejected;  // samples the frame must reject
  };
  // RFIN at 1694 is the clip's fastest sample (8.9 m/s); LWRA at 1300 is in its fastest stretch.
  const std::vector<int> six{c.findPoint("LFHD"), c.findPoint("C7"), c.findPoint("LELB"),
                             c.findPoint("RKNE"), c.findPoint("LTOE"), c.findPoint("RWRB")};
  const std::vector<Glitch> glitches{{"RFIN thrown 100 m at frame 1694", 1694, thrown(c.findPoint("RFIN")), 1},
                                     {"LWRA thrown 100 m at frame 1300", 1300, thrown(c.findPoint("LWRA")), 1},
                                     {"LTOE thrown 100 m at frame 600", 600, thrown(c.findPoint("LTOE")), 1},
                                     {"six markers' coordinates garbage at frame 1500", 1500, garbage(six, 37), 6},
                                     {"six markers' coordinates garbage at frame 2400", 2400, garbage(six, 38), 6}};
  for (const int p : six) ASSERT_GE(p, 0);
  ClipRun clean(scene);
  std::vector<std::unique_ptr<ClipRun>> runs;
  for (std::size_t g = 0; g < glitches.size(); ++g) runs.push_back(std::make_unique<ClipRun>(scene));
  constexpr std::size_t kAfter = 120;  // frames compared after the glitch (the return blend is 18)
  std::vector<double> at(glitches.size(), 0.0), after(glitches.size(), 0.0), end(glitches.size(), 0.0);
  for (std::size_t f = 0; f < c.frameCount(); ++f) {
    const LiveFrameStats s = clean.frame(f);
    ASSERT_EQ(s.rejected_marker_samples, 0) << "clean frame " << f;
    for (std::size_t g = 0; g < glitches.size(); ++g) {
      const Glitch& glitch = glitches[g];
      if (f > glitch.frame + kAfter) continue;
      ClipRun& run = *runs[g];
      const LiveFrameStats r = f == glitch.frame ? run.frame(f, glitch.edit) : run.frame(f);
      ASSERT_FALSE(r.flags & kLivePoseRejected) << glitch.name << ", frame " << f;
      const double d = ClipRun::maxDistance(run.positions(), clean.positions());
      if (f < glitch.frame) {
        ASSERT_EQ(d, 0.0) << glitch.name << ": the same frames before, frame " << f;
      } else if (f == glitch.frame) {
        EXPECT_EQ(r.rejected_marker_samples, glitch.rejected) << glitch.name;
        EXPECT_TRUE(r.flags & kLiveMarkersRejected) << glitch.name;
        EXPECT_EQ(r.occluded_markers, s.occluded_markers + glitch.rejected) << glitch.name;
        at[g] = d;
      } else {
        EXPECT_EQ(r.rejected_marker_samples, 0) << glitch.name << ": the next real samples are taken, frame " << f;
        after[g] = std::max(after[g], d);
        end[g] = d;
      }
    }
  }
  std::printf("[ measured ] HDM05 on SMPL, whole clip (%zu frames) clean: %llu samples rejected, %llu poses refused\n", c.frameCount(),
              static_cast<unsigned long long>(clean.rejectedSamples()), static_cast<unsigned long long>(clean.rejectedPoses()));
  for (std::size_t g = 0; g < glitches.size(); ++g) {
    std::printf("[ measured ] %s: largest vertex distance from the clean run in that frame %.2f mm, in the %zu frames after %.2f mm, "
                "%zu frames after %.4f mm\n",
                glitches[g].name, 1e3 * at[g], kAfter, 1e3 * after[g], kAfter, 1e3 * end[g]);
    // The rejected marker follows its anchor for that frame: the finger's own motion in the clip's
    // fastest frame (74 mm) is what its prediction misses (measured 7.6 mm; elsewhere 0.1-1.6 mm).
    EXPECT_LE(at[g], g == 0 ? 0.010 : 0.005) << glitches[g].name;
    // The frames after are the return blend's (docs/live.md): back on the clean run within 120 frames.
    EXPECT_LE(end[g], 0.001) << glitches[g].name;
  }
  EXPECT_EQ(clean.rejectedSamples(), 0u);
  EXPECT_EQ(clean.rejectedPoses(), 0u);
}

// CMU 85_02 (120 Hz, 41 markers, no gaps): its right toe reaches 12.4 m/s in frames 484-487 (a
// smooth leg swing, the fastest samples of the clips in ../shared/data). The clip has no T-pose
// (arms down, fit scale 0.843: tools/test_rig_markers_real.cpp): the rig is built from frame 0
// anyway, since only its size and scale bear on the samples of a clip without gaps.
TEST(LiveRigReal, Cmu85_02CleanClipRejectsNothing) {
  TETRIG_REQUIRE_DATA(man, kMan);
  TETRIG_REQUIRE_DATA(clip, kCmu85_02);
  const Scene& scene = cachedScene("cmu85_02", [&] {
    rigbuild::BuildRigInputs in;
    in.mesh = man;
    in.clip = clip;
    in.frame = 0;
    in.tet_vertices = 1500;
    in.max_marker_distance = 0.15;
    in.accept_implausible_alignment = true;
    in.check_deformer = false;
    auto built = std::make_unique<Scene>(Scene{rigbuild::buildRig(in), drivers::C3DClip::load(clip), {}, nullptr});
    built->labels = pointLabels(built->clip);
    return built;
  });
  ClipRun run(scene);
  EXPECT_EQ(run.binding().matched, static_cast<std::int32_t>(scene.rig.markers.size()));
  for (std::size_t f = 0; f < scene.clip.frameCount(); ++f) {
    const LiveFrameStats s = run.frame(f);
    ASSERT_TRUE(run.allFinite()) << "frame " << f;
    EXPECT_EQ(s.rejected_marker_samples, 0) << "frame " << f;
  }
  std::printf("[ measured ] CMU 85_02 on SMPL (%zu frames, %zu markers): %llu samples rejected, %llu poses refused\n",
              scene.clip.frameCount(), scene.rig.markers.size(), static_cast<unsigned long long>(run.rejectedSamples()),
              static_cast<unsigned long long>(run.rejectedPoses()));
  EXPECT_EQ(run.rejectedSamples(), 0u);
  EXPECT_EQ(run.rejectedPoses(), 0u);
}

const Scene* smplHdm05WithCoarseLevel() {
  return &cachedScene("hdm05+coarse", [] {
    return buildScene(test::dataPath(kMan), test::dataPath(kHdm05), 0, 0.15, {}, test::dataPath(kHdm05), false, true);
  });
}

// Every path of the frame (prediction, blends, held poses, a rejected sample), with and without the coarse level
// (and the temporal prediction with it).
class LiveRigRealAllocations : public ::testing::TestWithParam<bool> {};

TEST_P(LiveRigRealAllocations, Hdm05NoAllocationPerFrame) {
  TETRIG_REQUIRE_DATA(man, kMan);
  TETRIG_REQUIRE_DATA(clip, kHdm05);
  const bool coarse = GetParam();
  const Scene& scene = coarse ? *smplHdm05WithCoarseLevel() : *smplHdm05();
  ASSERT_EQ(scene.coarse != nullptr, coarse);
  LiveRigOptions options;
  options.normals = true;
  // Without the coarse level: the plain settings; with it: the defaults (every mechanism).
  if (!coarse) options.solver = SolverSettings::plain();
  ClipRun run(scene, options);
  const int lwra = scene.clip.findPoint("LWRA");
  const auto occlude = [&](std::size_t f) {
    return [f, lwra](MarkerFrame& frame) {
      for (int k = 0; k < frame.marker_count; ++k) {
        Marker& m = frame.markers[static_cast<std::size_t>(k)];
        if ((m.id == lwra && f >= 1250 && f < 1280) || (f >= 1300 && f < 1310)) m.valid = 0;
        if (m.id == lwra && f == 1350) m.position_mm[0] += 1e5f;  // rejected as implausible
      }
    };
  };
  run.frame(1200);  // warm-up
  std::uint32_t flags = 0;
  Eigen::internal::set_is_malloc_allowed(false);
  const std::uint64_t before = test::allocationCount();
  for (std::size_t f = 1201; f < 1400; ++f) flags |= run.frame(f, occlude(f)).flags;
  const std::uint64_t after = test::allocationCount();
  Eigen::internal::set_is_malloc_allowed(true);
  EXPECT_EQ(after - before, 0u);
  EXPECT_TRUE(flags & kLiveMarkersPredicted);
  EXPECT_TRUE(flags & kLiveMarkersBlending);
  EXPECT_TRUE(flags & kLivePoseHeld);
  EXPECT_TRUE(flags & kLiveMarkersRejected);
  EXPECT_TRUE(run.allFinite());
}
INSTANTIATE_TEST_SUITE_P(CoarseLevel, LiveRigRealAllocations, ::testing::Bool(),
                         [](const ::testing::TestParamInfo<bool>& i) { return i.param ? "WithCoarseLevel" : "Plain"; });

// ---------------------------------------------------------------------------------------------
// Real gaps. Edges: the frames from a marker's dropout or return until its blend is over (+2).

struct GapRunResult {
  double edge_step = 0.0;    // largest per-frame fine-vertex step in edge frames
  double other_step = 0.0;   // ... in the other frames
  std::size_t edge_frames = 0, gap_edges = 0;
};

TEST(LiveRigReal, Sample20ShortGapsAgainstInterpolatedGaps) {
  TETRIG_REQUIRE_DATA(man, kMan);
  TETRIG_REQUIRE_DATA(clip, kSample20);
  // No T-pose anywhere in this clip (arms down, largest horizontal span 1.35 m): the rig is built
  // from frame 20 (all 39 points valid; median marker distance 5.3 cm, max 12.4 cm after the
  // automatic alignment); point39 is never valid and left out. The points have no labels: the rig
  // and the source both call them "point<p>".
  const Scene& scene = cachedScene("sample20", [&] { return buildScene(man, clip, 20, 0.15, {"point39"}, clip, true); });
  ASSERT_EQ(scene.rig.markers.size(), 39u);
  const drivers::C3DClip& c = scene.clip;
  // The reference: every gap with samples on both sides filled by linear interpolation (gaps are
  // 1-5 frames at 30 Hz).
  const std::size_t frames = c.frameCount();
  std::vector<std::vector<float>> filled(frames, std::vector<float>(static_cast<std::size_t>(c.pointCount()) * 3, 0.0f));
  std::vector<std::vector<std::uint8_t>> filled_valid(frames, std::vector<std::uint8_t>(static_cast<std::size_t>(c.pointCount()), 0));
  std::size_t gap_runs = 0;
  for (int p = 0; p < c.pointCount(); ++p) {
    std::size_t f = 0;
    while (f < frames) {
      if (c.isValid(f, p)) {
        for (int k = 0; k < 3; ++k) filled[f][static_cast<std::size_t>(3 * p + k)] = c.positions(f)[3 * p + k] * static_cast<float>(c.unitsToMm());
        filled_valid[f][static_cast<std::size_t>(p)] = 1;
        ++f;
        continue;
      }
      std::size_t g = f;
      while (g < frames && !c.isValid(g, p)) ++g;
      if (f > 0 && g < frames) {
        ++gap_runs;
        for (std::size_t h = f; h < g; ++h) {
          const double u = static_cast<double>(h - f + 1) / static_cast<double>(g - f + 1);
          for (int k = 0; k < 3; ++k) {
            const double a = c.positions(f - 1)[3 * p + k], b = c.positions(g)[3 * p + k];
            filled[h][static_cast<std::size_t>(3 * p + k)] = static_cast<float>(c.unitsToMm() * ((1.0 - u) * a + u * b));
          }
          filled_valid[h][static_cast<std::size_t>(p)] = 1;
        }
      }
      f = g;
    }
  }
  EXPECT_GE(gap_runs, 200u);
  // Occlusion with the temporal prediction is an open problem (its bounds fail with
  // rotation_extrapolation 0.6 and 1): these runs keep every other default and no prediction.
  const LiveRigOptions unpredicted = withoutPrediction();
  LiveRigOptions options = unpredicted;
  options.normals = true;
  options.predict_all_markers = true;  // the measured markers' predictions are collected (printed) below
  LiveRigOptions no_blend = unpredicted;
  no_blend.occlusion_blend_s = 0.0;
  ClipRun gaps(scene, options), reference(scene, unpredicted), popping(scene, no_blend);
  EXPECT_EQ(gaps.binding().matched, 39);
  const std::size_t blend_frames = static_cast<std::size_t>(std::ceil(0.15 * c.frameRate())) + 2;
  std::vector<std::uint8_t> was_measured(scene.rig.markers.size(), 1);
  std::size_t edge_until = 0, edges = 0, edge_frames = 0;
  double edge_extra = 0.0, other_extra = 0.0, edge_step = 0.0, reference_step = 0.0, worst_error = 0.0, pop_extra = 0.0;
  double edge_extra_sum = 0.0, pop_extra_sum = 0.0;
  std::vector<double> prediction_errors;
  constexpr std::size_t kSettle = 10;
  for (std::size_t f = 0; f < frames; ++f) {
    const LiveFrameStats s = gaps.frame(f);
    gaps.collectPredictionErrors(prediction_errors);
    popping.frame(f);
    reference.frame(f, [&](MarkerFrame& frame) {
      for (int k = 0; k < frame.marker_count; ++k) {
        Marker& m = frame.markers[static_cast<std::size_t>(k)];
        m.valid = filled_valid[f][m.id];
        for (int i = 0; i < 3; ++i) m.position_mm[i] = filled[f][static_cast<std::size_t>(3 * m.id + i)];
      }
    });
    ASSERT_TRUE(gaps.allFinite()) << "frame " << f;
    EXPECT_FALSE(s.flags & kLivePoseHeld);
    for (std::size_t k = 0; k < scene.rig.markers.size(); ++k) {
      const std::uint8_t now = gaps.live().markerMeasured()[k];
      if (now != was_measured[k]) {
        ++edges;
        edge_until = f + blend_frames;
      }
      was_measured[k] = now;
    }
    if (f < kSettle) continue;
    const bool edge = f < edge_until;
    edge_frames += edge;
    (edge ? edge_extra : other_extra) = std::max(edge ? edge_extra : other_extra, gaps.extraStep(reference));
    if (edge) {
      edge_step = std::max(edge_step, gaps.lastStep());
      pop_extra = std::max(pop_extra, popping.extraStep(reference));
      edge_extra_sum += gaps.extraStep(reference);
      pop_extra_sum += popping.extraStep(reference);
    }
    reference_step = std::max(reference_step, reference.lastStep());
    worst_error = std::max(worst_error, ClipRun::maxDistance(gaps.positions(), reference.positions()));
  }
  std::printf("[ measured ] sample20 (30 Hz, %zu gap runs filled in the reference): %zu marker edges, %zu edge frames; largest step at "
              "edges %.1f mm (reference's largest step %.1f mm); extra step over the reference at edges %.1f mm (without blends "
              "%.1f mm), elsewhere %.1f mm; mean extra step over the edge frames %.2f mm (without blends %.2f mm); max difference %.1f mm\n",
              gap_runs, edges, edge_frames, 1e3 * edge_step, 1e3 * reference_step, 1e3 * edge_extra, 1e3 * pop_extra, 1e3 * other_extra,
              1e3 * edge_extra_sum / static_cast<double>(edge_frames), 1e3 * pop_extra_sum / static_cast<double>(edge_frames), 1e3 * worst_error);
  std::printf("[ measured ] sample20: prediction - measurement of the measured markers: median %.1f mm, 95 %% %.1f mm, max %.1f mm\n",
              1e3 * ClipRun::percentile(prediction_errors, 0.5), 1e3 * ClipRun::percentile(prediction_errors, 0.95),
              1e3 * ClipRun::percentile(prediction_errors, 1.0));
  EXPECT_GE(edges, 300u);
  EXPECT_LE(edge_step, 1.1 * reference_step);
  // Real gaps: every return is taken (judged by its own last sample or by its prediction).
  EXPECT_EQ(gaps.rejectedSamples(), 0u);
  EXPECT_EQ(reference.rejectedSamples(), 0u);
  EXPECT_EQ(gaps.rejectedPoses() + reference.rejectedPoses() + popping.rejectedPoses(), 0u);
  EXPECT_LE(edge_extra, 0.030);
  EXPECT_LT(edge_extra_sum, 0.85 * pop_extra_sum);
  EXPECT_LE(worst_error, 0.065);
}

TEST(LiveRigReal, PigWalkLfhdGapRigFromTheStaticTrial) {
  TETRIG_REQUIRE_DATA(man, kMan);
  TETRIG_REQUIRE_DATA(still, kPigStatic);
  TETRIG_REQUIRE_DATA(walk, kPigWalk);
  // The walk has no standing frame facing one way with all markers, and its frame 0 lacks LFHD:
  // the rig is built from the same subject's static trial (same lab axes), frame 0, without the
  // arm markers (arms hang down there, the mesh's are horizontal; with them the automatic heading
  // comes out 180 degrees off). The walk's arm markers are then unknown labels, ignored.
  const std::vector<std::string> arms{"LELB", "LWRA", "LWRB", "LFIN", "RELB", "RWRA", "RWRB", "RFIN"};
  const Scene& scene = cachedScene("pig", [&] { return buildScene(man, still, 0, 0.10, arms, walk, true); });
  ASSERT_EQ(scene.rig.markers.size(), 27u);
  // Occlusion with the temporal prediction is an open problem (its bounds fail with
  // rotation_extrapolation 0.6 and 1): this run keeps every other default and no prediction.
  ClipRun run(scene, withoutPrediction());
  EXPECT_EQ(run.binding().matched, 27);
  for (const std::string& arm : arms) {
    EXPECT_NE(std::find(run.binding().unknown.begin(), run.binding().unknown.end(), arm), run.binding().unknown.end()) << arm;
  }
  const int lfhd = scene.rig.markers.empty() ? -1 : [&] {
    for (std::size_t k = 0; k < scene.rig.markers.size(); ++k)
      if (scene.rig.markers[k].label == "LFHD") return static_cast<int>(k);
    return -1;
  }();
  ASSERT_GE(lfhd, 0);
  const std::size_t frames = scene.clip.frameCount();
  const std::size_t blend_frames = static_cast<std::size_t>(std::ceil(0.15 * scene.clip.frameRate())) + 2;
  constexpr std::size_t kSettle = 10;
  std::size_t gap_begin = frames, gap_end = frames;
  double edge_step = 0.0, other_step = 0.0;
  bool was = true;
  std::size_t edge_until = 0;
  for (std::size_t f = 0; f < frames; ++f) {
    const LiveFrameStats s = run.frame(f);
    ASSERT_TRUE(run.allFinite()) << "frame " << f;
    EXPECT_EQ(s.unknown_markers, arms.size()) << "frame " << f;  // arm markers; modelled points are not in the frames
    const bool now = run.live().markerMeasured()[static_cast<std::size_t>(lfhd)] != 0;
    if (!now && was) gap_begin = f;
    if (now && !was) gap_end = f;
    if (now != was) edge_until = f + blend_frames;
    was = now;
    if (f < kSettle) continue;
    (f < edge_until ? edge_step : other_step) = std::max(f < edge_until ? edge_step : other_step, run.lastStep());
  }
  std::printf("[ measured ] PiG walk on SMPL (100 Hz): LFHD gap frames %zu-%zu; largest per-frame step in the %zu frames after the "
              "return %.1f mm, elsewhere (after %zu frames of settling) %.1f mm\n",
              gap_begin, gap_end, blend_frames, 1e3 * edge_step, kSettle, 1e3 * other_step);
  EXPECT_EQ(gap_end - gap_begin, 30u);
  EXPECT_LE(edge_step, other_step);
  EXPECT_EQ(run.rejectedSamples(), 0u);
  EXPECT_EQ(run.rejectedPoses(), 0u);
}

TEST(LiveRigReal, Mocap36TotalLossHoldsThePoseExactly) {
  TETRIG_REQUIRE_DATA(man, kMan);
  TETRIG_REQUIRE_DATA(clip, kMocap36);
  // Frame 0 is a T-pose: the automatic alignment fits (median 1.6 cm, max 7.6 cm).
  const Scene& scene = cachedScene("mocap36", [&] { return buildScene(man, clip, 0, 0.10, {}, clip); });
  ASSERT_EQ(scene.rig.markers.size(), 36u);
  LiveRigOptions options;
  options.normals = true;
  ClipRun run(scene, options);
  EXPECT_EQ(run.binding().matched, 36);
  std::vector<float> last, last_normals;
  std::size_t held = 0, first_held = 0;
  for (std::size_t f = 0; f < scene.clip.frameCount(); ++f) {
    const LiveFrameStats s = run.frame(f);
    ASSERT_TRUE(run.allFinite()) << "frame " << f;
    if (s.flags & kLivePoseHeld) {
      if (held++ == 0) first_held = f;
      EXPECT_EQ(s.step.iterations, 0);
      EXPECT_EQ(s.occluded_markers, 36);
      ASSERT_EQ(std::memcmp(run.positions().data(), last.data(), last.size() * sizeof(float)), 0) << "frame " << f;
      ASSERT_EQ(std::memcmp(run.normals().data(), last_normals.data(), last_normals.size() * sizeof(float)), 0) << "frame " << f;
    } else {
      EXPECT_EQ(held, 0u) << "a frame stepped after the loss, frame " << f;
      last = run.positions();
      last_normals = run.normals();
    }
  }
  std::printf("[ measured ] mocap36: pose held bit for bit in %zu frames from frame %zu; %llu samples rejected, %llu poses refused\n", held,
              first_held, static_cast<unsigned long long>(run.rejectedSamples()), static_cast<unsigned long long>(run.rejectedPoses()));
  EXPECT_EQ(held, 229u);
  EXPECT_EQ(first_held, 1151u);
  EXPECT_EQ(run.rejectedSamples(), 0u) << "a clean clip (its fastest marker: 6.1 m/s)";
  EXPECT_EQ(run.rejectedPoses(), 0u);
}

}  // namespace
}  // namespace tetrig
