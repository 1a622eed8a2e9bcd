// One frame of the product on real data: the SMPL male (../shared/data, human_man.obj) rigged to the
// 41 labelled markers of the HDM05 clip (as in tests/tools/test_rig_markers_real.cpp: 1500 tet
// vertices, markers up to 15 cm from the skin), driven by the clip itself.
//   BM_RigFrame/smpl_hdm05: per benchmark iteration, the next clip frame (120 Hz, wrapping around):
//   each valid marker -> rig units through rig.alignment -> its vertex handle's target (a marker
//   in a gap keeps its last target); step() with 3 iterations; x_fine = B x_tet with the rig's
//   pose-transfer matrix as loaded (double weights), from the deformer's padded positions
//   (applyPoseTransferPadded). Counters split the frame into the step and the pose transfer.
//   The yardstick of the deformation core's frame cost (kept as it was for comparisons).
//   BM_RigFrame/smpl_hdm05_predicted: the same with the temporal prediction of the warm start;
//   _relaxed, _predicted_relaxed: with the over-relaxation of the rotation update (omega 1.8);
//   _coarse_relaxed, _coarse_predicted_relaxed: with the coarse level too (tetrig/coarse_level.hpp:
//   the same mesh and markers built with 150 tet vertices, the default 2 coarse iterations per
//   frame, counted in the frame and in step_us; coarse_us is its share).
//   _volume: with the volume term (w 0.5) on every tet; _joint_volume: w 0.5 on the body tets of the
//   knees and elbows only (DeformerSetup::volume_weights; the boxes of assets/human_man_fitted.json,
//   by rest centroid; the cost does not depend on w, only on which blocks of tets have one).
//   Every BM_LiveRigFrame run plays the whole clip once from a fresh live rig (kClipFrames).
//   BM_LiveRigFrame/smpl_hdm05_defaults and _plain: the live path as a product runs it, with the
//   default settings (SolverSettings{}: the temporal prediction, omega 1.8, the implicit inversion
//   guard, the volume kept, the 150-vertex coarse level) and with SolverSettings::plain() (the same
//   coarse level, no prediction, guard or volume constraint); prepareNextFrame left to the next
//   processFrame (in the frame's time, and apart as prepare_us); coarse_us, the coarse level's share
//   of step_us.
//   The variants below start from SolverSettings::plain() and add what they measure.
//   BM_LiveRigFrame/smpl_hdm05: the same frames through the live path's own per-frame call,
//   LiveRig::processFrame (clip frame as the C3D playback source fills it -> labels bound once ->
//   targets incl. occlusion prediction -> step(3) -> pose transfer into a float buffer, what
//   `tetrig run` writes into the shared-memory slot, with the compact copy of B); /1: the pose
//   transfer split over two threads.
//   BM_LiveRigFrame/smpl_hdm05_feet: the same live path (no split) on the same rig built with
//   assets/human_man_feet.json (each foot a region driven by its TOE/HEE/MT5 markers; issue #12),
//   against BM_LiveRigFrame/smpl_hdm05/0: what the marker fits and the rotation interpolation of
//   two oriented regions add to a frame.
//   BM_LiveRigFrame/smpl_hdm05_volume_constraint: the same live path (no split) keeping the fine
//   mesh's volume (SolverSettings::volume_constraint: at the published pose, the fine volume, the
//   direction from the body tets' boundary, and one frame in eight the solve for z; LiveRig::prepareNextFrame,
//   which `tetrig run` calls after publishing and this loop leaves to the next processFrame: in the
//   frame's time, and apart as prepare_us).
//   BM_LiveRigFrame/smpl_hdm05_after_publish/<k>: the same live path (no split) with k iterations on
//   each frame's targets after its pose (LiveRigOptions::after_publish_iterations; prepareNextFrame,
//   left here to the next processFrame: in the frame's time, and apart as prepare_us).
//   BM_LiveRigFrame/smpl_hdm05_landing/<k>: the same live path with everything issue #12 adds to a
//   frame (docs/fidelity.md): the 150-vertex coarse level, the temporal prediction, omega 1.9, the
//   inversion guard, and k iterations after publishing (in the frame's time, and apart as prepare_us).
//   BM_LiveRigFrame/smpl_hdm05_landing_implicit/<s>: the same with the implicit inversion guard (k 3,
//   s conjugate-gradient steps per iteration; docs/deformation.md) and no iterations after publishing.
//   BM_LiveRigFrame/smpl_hdm05_landing_implicit_volume/<s>: that and the volume constraint (its
//   linearization after publishing, in the frame's time and apart as prepare_us): every mechanism.
//   BM_LiveRigFrame/smpl_hdm05_landing_kept_volume/1: that (S = 1) with omega 1.8 and the guard
//   holding tets from 0.7 of their volume (inversion_guard_threshold): the configuration recommended
//   with the volume kept (docs/live.md).
//   BM_PoseTransfer/smpl_hdm05/<layout>/<cache>: the pose transfer alone, from the padded positions of
//   one posed frame into a float buffer; layout 0 = the rig's B (double weights, 32-bit columns, 12
//   bytes per entry), 1 = the compact copy (float, 16-bit, 6 bytes: narrowPoseTransfer) from double
//   positions, 2 = the compact copy from float positions (its float kernel, as the live rig ran it
//   until session 22), 3 = the blocked copy (blockPoseTransfer, as the live rig runs it now);
//   cache 0 = back to back (B stays in the caches), 1 = a 64 MB buffer written between calls
//   (untimed), as between two frames of a live run 8 ms apart on a shared machine.
#include "bench_data.hpp"

#include "tetrig/coarse_level.hpp"
#include "tetrig/deformer.hpp"
#include "tetrig/drivers/c3d_playback.hpp"
#include "tetrig/live_rig.hpp"
#include "tetrig/drivers/c3d_reader.hpp"
#include "tetrig/pose_transfer.hpp"
#include "tetrig/pose_transfer_padded.hpp"
#include "tetrig/pose_transfer_blocked.hpp"
#include "tetrig/rig_file.hpp"
#include "tetrig/rigbuild/build_rig.hpp"
#include "tetrig/rigbuild/rig_description.hpp"

#include <benchmark/benchmark.h>

#include <chrono>
#include <cstring>
#include <memory>
#include <stdexcept>
#include <string>

namespace {

constexpr const char* kMan = "meshes/odedstein-meshes/human_man.obj";
constexpr const char* kClip = "mocap/hdm05/HDM_mm_01-02_03_120.c3d";

struct RigScene {
  tetrig::Rig rig;  // or, for the feet variant, the same built with assets/human_man_feet.json
  tetrig::drivers::C3DClip clip;
  std::vector<int> clip_point;  // per rig marker: its point in the clip
  tetrig::Rig coarse;           // the same with 150 tet vertices (the coarse level)
};

std::unique_ptr<RigScene> makeRigScene(bool feet) {
  const auto man = tetrig::bench::requireBenchData(kMan), clip = tetrig::bench::requireBenchData(kClip);
  tetrig::rigbuild::BuildRigInputs in;
  in.mesh = man;
  in.clip = clip;
  in.tet_vertices = 1500;
  in.max_marker_distance = 0.15;  // the subject's wider stance: see test_rig_markers_real.cpp
  in.check_deformer = false;
  if (feet) in.description = tetrig::rigbuild::readRigDescription(std::string(TETRIG_SOURCE_DIR) + "/assets/human_man_feet.json");
  auto s = std::make_unique<RigScene>(RigScene{tetrig::rigbuild::buildRig(in), tetrig::drivers::C3DClip::load(clip), {}, {}});
  if (!feet) {
    in.tet_vertices = 150;
    s->coarse = tetrig::rigbuild::buildRig(in);
  }
  for (const tetrig::RigMarker& m : s->rig.markers) {
    const int point = s->clip.findPoint(m.label);  // subject prefixes ("meinard:LFHD") allowed
    if (point < 0) throw std::runtime_error("marker " + m.label + " is not in the clip");
    s->clip_point.push_back(point);
  }
  return s;
}

// Built once (the rig build takes seconds); null with `error` set when the data is absent.
const RigScene* rigScene(std::string& error) { return tetrig::bench::buildOnce<RigScene>([] { return makeRigScene(false); }, error); }

// The rig with its feet driven by their markers (BM_LiveRigFrame/smpl_hdm05_feet); its own build
// (buildOnce keeps one scene per lambda).
const RigScene* feetRigScene(std::string& error) { return tetrig::bench::buildOnce<RigScene>([] { return makeRigScene(true); }, error); }

// The scene, or null after marking the benchmark skipped (the data is absent).
const RigScene* sceneOrSkip(benchmark::State& state, bool feet = false) {
  std::string error;
  const RigScene* scene = feet ? feetRigScene(error) : rigScene(error);
  if (scene == nullptr) state.SkipWithError(error.c_str());
  return scene;
}

// Rest positions of a setup's vertex handles: the targets before any marker is seen.
std::vector<Eigen::Vector3d> restVertexTargets(const tetrig::TetMesh& mesh, const tetrig::DeformerSetup& setup) {
  std::vector<Eigen::Vector3d> targets;
  for (const std::int32_t v : setup.vertex_handles) targets.push_back(mesh.vertices.row(v).transpose());
  return targets;
}

// Rig marker m's target at a clip frame, in rig units; false when the clip has it occluded.
bool markerTarget(const RigScene& scene, std::size_t frame, std::size_t m, Eigen::Vector3d& target) {
  const int point = scene.clip_point[m];
  if (!scene.clip.isValid(frame, point)) return false;
  const float* p = scene.clip.positions(frame);
  const double to_mm = scene.clip.unitsToMm();
  target = scene.rig.alignment.apply(Eigen::Vector3d(to_mm * p[3 * point], to_mm * p[3 * point + 1], to_mm * p[3 * point + 2]));
  return true;
}

enum class Volume { kNone, kEverywhere, kJoints };

// Per-tet volume weights w on the body tets whose rest centroid lies in the knee band or an elbow
// box of assets/human_man_fitted.json (rig units, the SMPL's T-pose).
std::vector<double> jointVolumeWeights(const tetrig::Rig& rig, double w) {
  std::vector<double> weights(static_cast<std::size_t>(rig.tet_mesh.tetCount()), 0.0);
  for (std::int32_t t = 0; t < rig.body_tet_count; ++t) {
    Eigen::Vector3d c = Eigen::Vector3d::Zero();
    for (int k = 0; k < 4; ++k) c += 0.25 * rig.tet_mesh.vertices.row(rig.tet_mesh.tets(t, k)).transpose();
    const bool knee = c.y() >= 0.30 && c.y() <= 0.60;
    const bool elbow = std::abs(c.x()) >= 0.38 && std::abs(c.x()) <= 0.56 && c.y() >= 1.1 && c.y() <= 1.7;
    if (knee || elbow) weights[static_cast<std::size_t>(t)] = w;
  }
  return weights;
}

void rigFrame(benchmark::State& state, double extrapolation, double relaxation = 1.0, bool with_coarse = false,
              Volume volume = Volume::kNone) {
  const RigScene* scene = sceneOrSkip(state);
  if (scene == nullptr) return;
  const tetrig::Rig& rig = scene->rig;
  tetrig::DeformerSetup setup = rig.setup;
  if (volume == Volume::kEverywhere) setup.options.volume_weight = 0.5;
  if (volume == Volume::kJoints) setup.volume_weights = jointVolumeWeights(rig, 0.5);
  setup.options.padded_positions = true;  // the input of applyPoseTransferPadded
  setup.options.rotation_extrapolation = extrapolation;
  setup.options.rotation_relaxation = relaxation;
  setup.options.frame_guide = with_coarse;
  tetrig::Deformer deformer(rig.tet_mesh, setup);
  std::vector<Eigen::Vector3d> targets = restVertexTargets(rig.tet_mesh, rig.setup);
  tetrig::HandleTargets handle_targets;
  handle_targets.vertex_positions = targets;
  // Coarse level: its deformer, its handle targets and per rig marker its coarse vertex handle.
  const tetrig::Rig& coarse_rig = scene->coarse;
  std::unique_ptr<tetrig::CoarseLevel> coarse;
  std::vector<Eigen::Vector3d> coarse_targets;
  std::vector<std::int32_t> coarse_handle(rig.markers.size(), -1);
  tetrig::HandleTargets coarse_handle_targets;
  if (with_coarse) {
    tetrig::DeformerSetup cs = coarse_rig.setup;
    cs.options.rotation_relaxation = relaxation;
    coarse = std::make_unique<tetrig::CoarseLevel>(rig.tet_mesh, deformer, coarse_rig.tet_mesh, cs);
    coarse_targets = restVertexTargets(coarse_rig.tet_mesh, cs);
    for (std::size_t m = 0; m < rig.markers.size(); ++m)
      for (const tetrig::RigMarker& c : coarse_rig.markers)
        if (c.label == rig.markers[m].label) coarse_handle[m] = c.vertex_handle;
    coarse_handle_targets.vertex_positions = coarse_targets;
  }
  std::int64_t coarse_ns = 0;
  const auto b = rig.pose_transfer.view();
  std::vector<double> fine(static_cast<std::size_t>(rig.pose_transfer.rows) * 3);
  const std::size_t frames = scene->clip.frameCount();
  std::size_t frame = 0;
  std::int64_t step_ns = 0, pose_ns = 0, iterations = 0, solve_ns = 0, exact = 0;
  for (auto _ : state) {
    for (std::size_t m = 0; m < rig.markers.size(); ++m) {
      Eigen::Vector3d target;
      if (!markerTarget(*scene, frame, m, target)) continue;
      targets[static_cast<std::size_t>(rig.markers[m].vertex_handle)] = target;
      if (coarse && coarse_handle[m] >= 0) coarse_targets[static_cast<std::size_t>(coarse_handle[m])] = target;
    }
    std::int64_t frame_coarse_ns = 0;
    if (coarse) frame_coarse_ns = coarse->guide(coarse_handle_targets).total_ns;
    tetrig::StepStats stats = deformer.step(handle_targets, tetrig::StepBudget{3});
    stats.total_ns += frame_coarse_ns;
    coarse_ns += frame_coarse_ns;
    const auto t1 = std::chrono::steady_clock::now();
    tetrig::applyPoseTransferPadded(b, deformer.paddedPositions().data(), fine.data());
    benchmark::DoNotOptimize(fine.data());
    benchmark::ClobberMemory();
    pose_ns += std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now() - t1).count();
    step_ns += stats.total_ns;
    iterations += stats.iterations;
    solve_ns += stats.solve_ns;
    exact += stats.exact_rotations;
    frame = (frame + 1) % frames;
  }
  const auto n = static_cast<double>(state.iterations());
  state.counters["step_us"] = static_cast<double>(step_ns) / n * 1e-3;
  if (with_coarse) {
    state.counters["coarse_us"] = static_cast<double>(coarse_ns) / n * 1e-3;
    state.counters["coarse_tets"] = coarse_rig.tet_mesh.tetCount();
  }
  state.counters["pose_transfer_us"] = static_cast<double>(pose_ns) / n * 1e-3;
  state.counters["solve_us"] = static_cast<double>(solve_ns) / n * 1e-3;
  state.counters["exact_rotations"] = static_cast<double>(exact) / n;
  state.counters["iterations"] = static_cast<double>(iterations) / n;
  state.counters["tets"] = rig.tet_mesh.tetCount();
  state.counters["fine_vertices"] = rig.pose_transfer.rows;
  state.counters["B_nnz_per_row"] = static_cast<double>(rig.pose_transfer.weights.size()) / rig.pose_transfer.rows;
}
void BM_RigFrame(benchmark::State& state) { rigFrame(state, 0.0); }
BENCHMARK(BM_RigFrame)->Name("BM_RigFrame/smpl_hdm05")->Unit(benchmark::kMicrosecond);
// The same with the temporal prediction of the warm start (DeformerOptions::rotation_extrapolation = 1,
// issue #12): what it adds to a frame.
void BM_RigFrameVolume(benchmark::State& state) { rigFrame(state, 0.0, 1.0, false, Volume::kEverywhere); }
BENCHMARK(BM_RigFrameVolume)->Name("BM_RigFrame/smpl_hdm05_volume")->Unit(benchmark::kMicrosecond);
void BM_RigFrameJointVolume(benchmark::State& state) { rigFrame(state, 0.0, 1.0, false, Volume::kJoints); }
BENCHMARK(BM_RigFrameJointVolume)->Name("BM_RigFrame/smpl_hdm05_joint_volume")->Unit(benchmark::kMicrosecond);
void BM_RigFramePredicted(benchmark::State& state) { rigFrame(state, 1.0); }
BENCHMARK(BM_RigFramePredicted)->Name("BM_RigFrame/smpl_hdm05_predicted")->Unit(benchmark::kMicrosecond);
// With the over-relaxation of the rotation update (DeformerOptions::rotation_relaxation = 1.8, the live
// rig's default), alone and with the temporal prediction.
void BM_RigFrameRelaxed(benchmark::State& state) { rigFrame(state, 0.0, 1.8); }
BENCHMARK(BM_RigFrameRelaxed)->Name("BM_RigFrame/smpl_hdm05_relaxed")->Unit(benchmark::kMicrosecond);
void BM_RigFramePredictedRelaxed(benchmark::State& state) { rigFrame(state, 1.0, 1.8); }
BENCHMARK(BM_RigFramePredictedRelaxed)->Name("BM_RigFrame/smpl_hdm05_predicted_relaxed")->Unit(benchmark::kMicrosecond);
void BM_RigFrameCoarseRelaxed(benchmark::State& state) { rigFrame(state, 0.0, 1.8, true); }
BENCHMARK(BM_RigFrameCoarseRelaxed)->Name("BM_RigFrame/smpl_hdm05_coarse_relaxed")->Unit(benchmark::kMicrosecond);
void BM_RigFrameCoarsePredictedRelaxed(benchmark::State& state) { rigFrame(state, 1.0, 1.8, true); }
BENCHMARK(BM_RigFrameCoarsePredictedRelaxed)->Name("BM_RigFrame/smpl_hdm05_coarse_predicted_relaxed")->Unit(benchmark::kMicrosecond);

// The live-path benchmarks run the whole HDM05 clip once per run (its 3990 frames, from a fresh live
// rig): a frame's cost depends on the pose (the squats hold twice as many tets in the guard as the
// walk), so a run timed by min_time would cover more of the clip the faster the build, and two builds
// would be timed on different frames.
constexpr benchmark::IterationCount kClipFrames = 3990;

// The settings a product runs with: SolverSettings{} (the default), or SolverSettings::plain().
enum class Settings { kVariant, kDefaults, kPlain };

void liveRigFrame(benchmark::State& state, bool feet, bool volume_constraint = false, bool after_publish = false,
                  bool landing = false, bool implicit_guard = false, bool kept_volume_flags = false,
                  Settings settings = Settings::kVariant) {
  const RigScene* scene = sceneOrSkip(state, feet);
  if (scene == nullptr) return;
  tetrig::LiveRigOptions live_options;
  // The variants below measure what each part adds to the plain settings.
  live_options.solver = settings == Settings::kDefaults ? tetrig::SolverSettings{} : tetrig::SolverSettings::plain();
  tetrig::SolverSettings& solver = live_options.solver;
  if (settings != Settings::kVariant) {
    // As a product runs (with the coarse level: the scene's, when the rig has none of its own).
  } else if (landing) {
    solver.volume_constraint = volume_constraint;
    // Everything issue #12 adds to a frame, as docs/fidelity.md measures it: the coarse level, the
    // temporal prediction, omega 1.9, the inversion guard, and k iterations after publishing.
    solver.rotation_extrapolation = 1.0;
    solver.rotation_relaxation = 1.9;
    solver.inversion_guard = 1.0;
    if (implicit_guard) {
      // The implicit guard instead (docs/deformation.md): k 3, range(0) conjugate-gradient steps.
      solver.inversion_guard = 3.0;
      solver.inversion_guard_solves = static_cast<int>(state.range(0));
      if (kept_volume_flags) {
        // The configuration recommended with the volume kept (docs/live.md): omega 1.8 and the guard
        // holding tets from 0.7 of their volume (the defaults).
        solver.rotation_relaxation = 1.8;
        solver.inversion_guard_threshold = 0.7;
      }
    } else {
      solver.after_publish_iterations = static_cast<int>(state.range(0));
    }
  } else if (volume_constraint) {
    solver.volume_constraint = true;
  } else if (after_publish) {
    solver.after_publish_iterations = static_cast<int>(state.range(0));
  } else {
    live_options.split_pose_transfer = state.range(0) != 0;
  }
  const bool with_coarse = landing || (settings != Settings::kVariant && scene->rig.coarse == nullptr);
  tetrig::LiveRig live(scene->rig, live_options, with_coarse ? &scene->coarse : nullptr);
  tetrig::drivers::C3DPlaybackOptions options;
  options.pacing = tetrig::drivers::Pacing::kAsFastAsPossible;
  const tetrig::drivers::C3DPlayback playback(scene->clip, options);
  std::vector<std::string> labels(static_cast<std::size_t>(scene->clip.pointCount()));
  for (int p : playback.selectedPoints()) labels[static_cast<std::size_t>(p)] = scene->clip.labels()[static_cast<std::size_t>(p)];
  live.bindLabels(labels);
  std::vector<float> fine(static_cast<std::size_t>(live.fineVertexCount()) * 3);
  auto frame = std::make_unique<tetrig::MarkerFrame>();
  const std::size_t frames = scene->clip.frameCount();
  if (frames != static_cast<std::size_t>(kClipFrames)) {
    state.SkipWithError(("the HDM05 clip has " + std::to_string(frames) + " frames, not the " + std::to_string(kClipFrames) +
                         " each run covers")
                            .c_str());
    return;
  }
  std::size_t f = 0;
  std::uint64_t counter = 0;
  std::int64_t step_ns = 0, pose_ns = 0, prepare_ns = 0, coarse_ns = 0, iterations = 0, guarded_solves = 0, guarded_tets = 0;
  for (auto _ : state) {
    playback.fillFrame(f, counter++, *frame);
    const tetrig::LiveFrameStats s = live.processFrame(*frame, tetrig::StepBudget{3}, fine.data(), nullptr);
    benchmark::DoNotOptimize(fine.data());
    benchmark::ClobberMemory();
    step_ns += s.step.total_ns;
    pose_ns += s.pose_transfer_ns;
    prepare_ns += s.prepare_ns;
    coarse_ns += s.coarse_ns;
    iterations += s.step.iterations;
    guarded_solves += s.step.guarded_solves;
    guarded_tets += s.step.guarded_tets;
    f = (f + 1) % frames;
  }
  const auto n = static_cast<double>(state.iterations());
  state.counters["step_us"] = static_cast<double>(step_ns) / n * 1e-3;
  state.counters["pose_transfer_us"] = static_cast<double>(pose_ns) / n * 1e-3;
  if (coarse_ns > 0) state.counters["coarse_us"] = static_cast<double>(coarse_ns) / n * 1e-3;  // also in step_us
  if (volume_constraint || after_publish || landing || settings != Settings::kVariant) state.counters["prepare_us"] = static_cast<double>(prepare_ns) / n * 1e-3;
  state.counters["iterations"] = static_cast<double>(iterations) / n;
  if (implicit_guard || settings == Settings::kDefaults) {
    state.counters["guarded_solves"] = static_cast<double>(guarded_solves) / n;  // global steps that held tets
    state.counters["guarded_tets"] = static_cast<double>(guarded_tets) / n;      // tets held at the frame's last rotation pass
  }
}
void BM_LiveRigFrame(benchmark::State& state) { liveRigFrame(state, false); }
void BM_LiveRigFrameFeet(benchmark::State& state) { liveRigFrame(state, true); }
void BM_LiveRigFrameVolumeConstraint(benchmark::State& state) { liveRigFrame(state, false, true); }
void BM_LiveRigFrameAfterPublish(benchmark::State& state) { liveRigFrame(state, false, false, true); }
void BM_LiveRigFrameLanding(benchmark::State& state) { liveRigFrame(state, false, false, false, true); }
// What a product runs: the default settings (SolverSettings{}: prediction, omega 1.8, the implicit
// guard, the volume kept, the coarse level), against SolverSettings::plain() with the same coarse level.
void BM_LiveRigFrameDefaults(benchmark::State& state) { liveRigFrame(state, false, false, false, false, false, false, Settings::kDefaults); }
BENCHMARK(BM_LiveRigFrameDefaults)->Name("BM_LiveRigFrame/smpl_hdm05_defaults")->Iterations(kClipFrames)->Unit(benchmark::kMicrosecond);
void BM_LiveRigFramePlain(benchmark::State& state) { liveRigFrame(state, false, false, false, false, false, false, Settings::kPlain); }
BENCHMARK(BM_LiveRigFramePlain)->Name("BM_LiveRigFrame/smpl_hdm05_plain")->Iterations(kClipFrames)->Unit(benchmark::kMicrosecond);
// Argument: iterations after publishing, on top of the coarse level, the prediction, omega 1.9 and the guard.
BENCHMARK(BM_LiveRigFrameLanding)->Name("BM_LiveRigFrame/smpl_hdm05_landing")->DenseRange(0, 3)->Iterations(kClipFrames)->Unit(benchmark::kMicrosecond);
void BM_LiveRigFrameLandingImplicit(benchmark::State& state) { liveRigFrame(state, false, false, false, true, true); }
// Argument: the implicit guard's conjugate-gradient steps (k 3), with no iterations after publishing.
BENCHMARK(BM_LiveRigFrameLandingImplicit)->Name("BM_LiveRigFrame/smpl_hdm05_landing_implicit")->DenseRange(1, 2)->Iterations(kClipFrames)->Unit(benchmark::kMicrosecond);
void BM_LiveRigFrameLandingImplicitVolume(benchmark::State& state) { liveRigFrame(state, false, true, false, true, true); }
// The same with the volume constraint too (its after-publish work in the frame's time): all of it.
BENCHMARK(BM_LiveRigFrameLandingImplicitVolume)->Name("BM_LiveRigFrame/smpl_hdm05_landing_implicit_volume")->DenseRange(1, 2)->Iterations(kClipFrames)->Unit(benchmark::kMicrosecond);
void BM_LiveRigFrameLandingKeptVolume(benchmark::State& state) { liveRigFrame(state, false, true, false, true, true, true); }
// The same with omega 1.8 and the guard's threshold at 0.7: the configuration recommended with the
// volume kept (docs/live.md, "What the default settings cost").
BENCHMARK(BM_LiveRigFrameLandingKeptVolume)->Name("BM_LiveRigFrame/smpl_hdm05_landing_kept_volume")->Arg(1)->Iterations(kClipFrames)->Unit(benchmark::kMicrosecond);
// Argument: iterations after publishing (LiveRigOptions::after_publish_iterations).
BENCHMARK(BM_LiveRigFrameAfterPublish)->Name("BM_LiveRigFrame/smpl_hdm05_after_publish")->Arg(1)->Arg(2)->Iterations(kClipFrames)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_LiveRigFrameVolumeConstraint)->Name("BM_LiveRigFrame/smpl_hdm05_volume_constraint")->Iterations(kClipFrames)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_LiveRigFrameFeet)->Name("BM_LiveRigFrame/smpl_hdm05_feet")->Arg(0)->Iterations(kClipFrames)->Unit(benchmark::kMicrosecond);
// Argument: 0 = pose transfer on the calling thread, 1 = split with one worker (PoseTransferSplit).
BENCHMARK(BM_LiveRigFrame)->Name("BM_LiveRigFrame/smpl_hdm05")->Arg(0)->Arg(1)->Iterations(kClipFrames)->Unit(benchmark::kMicrosecond);

void BM_PoseTransfer(benchmark::State& state) {
  const RigScene* scene = sceneOrSkip(state);
  if (scene == nullptr) return;
  const tetrig::Rig& rig = scene->rig;
  const bool compact = state.range(0) != 0, cold = state.range(1) != 0;
  // The input: the clip's frame 600 after 10 iterations from rest.
  constexpr std::size_t kFrame = 600;
  tetrig::DeformerSetup setup = rig.setup;
  setup.options.padded_positions = true;
  tetrig::Deformer deformer(rig.tet_mesh, setup);
  std::vector<Eigen::Vector3d> targets = restVertexTargets(rig.tet_mesh, rig.setup);
  for (std::size_t m = 0; m < rig.markers.size(); ++m) {
    Eigen::Vector3d target;
    if (markerTarget(*scene, kFrame, m, target)) targets[static_cast<std::size_t>(rig.markers[m].vertex_handle)] = target;
  }
  tetrig::HandleTargets handle_targets;
  handle_targets.vertex_positions = targets;
  deformer.step(handle_targets, tetrig::StepBudget{10});
  const tetrig::CompactPoseTransfer narrow = tetrig::narrowPoseTransfer(rig.pose_transfer);
  const tetrig::BlockedPoseTransfer blocked = tetrig::blockPoseTransfer(
      rig.pose_transfer, std::span<const double>(rig.fine_vertices.data(), static_cast<std::size_t>(rig.fine_vertices.size())));
  std::vector<float> fine(static_cast<std::size_t>(rig.pose_transfer.rows) * 3);
  std::vector<unsigned char> evict(cold ? std::size_t{64} << 20 : 0);
  const double* x4 = deformer.paddedPositions().data();
  unsigned char fill = 0;
  std::vector<float> x4f(deformer.paddedPositions().begin(), deformer.paddedPositions().end());
  for (auto _ : state) {
    if (cold) {
      std::memset(evict.data(), ++fill, evict.size());
      benchmark::ClobberMemory();
    }
    const auto t0 = std::chrono::steady_clock::now();
    if (state.range(0) == 3) {
      tetrig::applyPoseTransferBlocked(blocked.view(), x4f.data(), fine.data());
    } else if (state.range(0) == 2) {
      tetrig::applyPoseTransferPadded(narrow.view(), x4f.data(), fine.data());
    } else if (compact) {
      tetrig::applyPoseTransferPadded(narrow.view(), x4, fine.data());
    } else {
      tetrig::applyPoseTransferPadded(rig.pose_transfer.view(), x4, fine.data());
    }
    benchmark::DoNotOptimize(fine.data());
    benchmark::ClobberMemory();
    state.SetIterationTime(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
  }
  state.counters["B_bytes"] = static_cast<double>(state.range(0) == 3 ? blocked.bytes() : compact ? narrow.bytes() : rig.pose_transfer.bytes());
  if (state.range(0) == 3) state.counters["fill"] = blocked.fill(rig.pose_transfer.nonzeros());
}
BENCHMARK(BM_PoseTransfer)
    ->Name("BM_PoseTransfer/smpl_hdm05")
    ->ArgsProduct({{0, 1, 2, 3}, {0, 1}})
    ->UseManualTime()
    ->Unit(benchmark::kMicrosecond);

}  // namespace
