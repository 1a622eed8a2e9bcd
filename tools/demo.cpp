// `tetrig demo` (tools/demo.hpp): the live path on the project's own data or on real data.
#include "demo.hpp"

#include "character/character_surface.hpp"
#include "character/default_character.hpp"
#include "demo_report.hpp"
#include "run.hpp"
#include "tetrig/drivers/c3d_reader.hpp"
#include "tetrig/drivers/character_performance.hpp"
#include "tetrig/drivers/synthetic_source.hpp"
#include "tetrig/rigbuild/demo_bar_rig.hpp"
#include "tetrig/rigbuild/build_rig.hpp"
#include "tetrig/rigbuild/progress.hpp"
#include "tetrig/rigbuild/write_file_atomic.hpp"
#include "tetrig/tet_mesh_io.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <stdexcept>
#include <string>
#include <vector>

#include <unistd.h>

namespace tetrig::tools {

namespace {

std::filesystem::path assetsDir() {
  if (const char* env = std::getenv("TETRIG_ASSETS_DIR"); env != nullptr && env[0] != '\0') return env;
  return TETRIG_ASSETS_DIR;
}

// The directory of the running executable (tetrig-shm-cat is built beside tetrig).
std::filesystem::path exeDir() {
  std::error_code ec;
  const std::filesystem::path self = std::filesystem::read_symlink("/proc/self/exe", ec);
  return ec ? std::filesystem::current_path() : self.parent_path();
}

std::filesystem::path cacheDir() {
  if (const char* x = std::getenv("XDG_CACHE_HOME"); x != nullptr && x[0] != '\0') return std::filesystem::path(x) / "tetrig" / "rigs";
  if (const char* h = std::getenv("HOME"); h != nullptr && h[0] != '\0') return std::filesystem::path(h) / ".cache" / "tetrig" / "rigs";
  return std::filesystem::temp_directory_path() / "tetrig-rigs";
}

// A cache key from both inputs' absolute paths, sizes and modification times.
std::string cacheKey(const std::filesystem::path& mesh, const std::filesystem::path& clip) {
  std::string key;
  for (const auto& p : {mesh, clip}) {
    const auto abs = std::filesystem::absolute(p);
    key += abs.string() + "|" + std::to_string(std::filesystem::file_size(abs)) + "|" +
           std::to_string(std::filesystem::last_write_time(abs).time_since_epoch().count()) + "|";
  }
  char hex[17];
  std::snprintf(hex, sizeof hex, "%016zx", std::hash<std::string>{}(key));
  return std::string(hex);
}

// The default character's skin as published against its true skin in the same pose
// (character/character_surface.hpp), over the frames the report's reader copied out of the segment:
// each copy's source frame gives the performance's time, and so the pose the markers came from.
nlohmann::json characterSurfaceJson(const Rig& rig, const std::vector<CapturedFrame>& frames, bool quiet) {
  character::CharacterSurfaceMeasure surface(rig);
  const double rate_hz = drivers::characterSyntheticOptions().rate_hz;
  drivers::CharacterPose pose;
  for (const CapturedFrame& f : frames) {
    drivers::characterPoseAt(std::fmod(static_cast<double>(f.source_frame) / rate_hz, drivers::characterPerformanceSeconds()), pose);
    surface.addFrame(f.positions, pose);
  }
  const rigbuild::Percentiles all = surface.all(), rest = surface.restSurface();
  const auto json = [](const rigbuild::Percentiles& p) {
    return nlohmann::json{{"median", p.median}, {"p90", p.p90}, {"p99", p.p99}, {"max", p.max}, {"count", p.count}};
  };
  if (!quiet) {
    std::printf("tetrig demo: the published skin against the character's true skin in the same pose, %zu frames: "
                "median %.1f, p99 %.1f, max %.1f mm (the rest mesh's own: p99 %.1f mm)\n",
                surface.frames(), all.median, all.p99, all.max, rest.p99);
  }
  nlohmann::json out = json(all);
  out["frames"] = surface.frames();
  out["rest_mesh"] = json(rest);
  return out;
}

}  // namespace

int runDemo(const DemoOptions& options) {
  if (options.mesh.empty() != options.c3d.empty()) throw std::invalid_argument("--mesh and --c3d go together (a mesh and the clip that drives it)");
  // The report's folder and gnuplot are checked before any work.
  if (!options.no_report) checkDemoReportTarget(options.report);
  RunOptions run;
  run.iterations = options.iterations;
  run.solver = options.solver;
  run.budget_ms = options.frame_budget_ms;
  run.quiet = options.quiet;
  run.final_obj = options.out_obj;
  run.publish = options.publish.empty() ? "tetrig-demo-" + std::to_string(getpid()) : options.publish;
  const std::filesystem::path consumer = exeDir() / "tetrig-shm-cat";
  if (std::filesystem::exists(consumer)) run.consumer_command = consumer.string() + " --quiet --timeout-ms 10000";
  if (options.mesh.empty()) {
    // The default character (assets/character, docs/character.md), its rig built once and cached,
    // playing its performance from the synthetic source.
    rigbuild::Progress progress("tetrig demo", options.quiet ? rigbuild::Progress::Mode::kQuiet : rigbuild::Progress::Mode::kAuto);
    const character::DefaultCharacter character = character::prepareDefaultCharacter(assetsDir() / "character", cacheDir(), &progress);
    if (!options.quiet) {
      std::printf("tetrig demo: %s the default character's rig %s\n", character.reused ? "reusing" : "cached", character.rig_path.string().c_str());
    }
    run.rig = loadRigFile(character.rig_path);
    run.source = character.source_spec;
    run.frames = options.frames != 0 ? options.frames : character.performance_frames;
  } else {
    // "-checked-coarse": rigs cached by older builders (before the alignment checks, the stiff
    // marker binding, the rigid marker groups and the default coarse level) are not reused.
    const std::filesystem::path cached =
        cacheDir() / (cacheKey(options.mesh, options.c3d) + "-" + std::to_string(options.max_marker_distance) + "-checked-coarse.rig");
    if (std::filesystem::exists(cached)) {
      if (!options.quiet) std::printf("tetrig demo: reusing the rig %s\n", cached.string().c_str());
    } else {
      rigbuild::BuildRigInputs in;
      in.mesh = options.mesh;
      in.clip = options.c3d;
      if (options.max_marker_distance > 0) in.max_marker_distance = options.max_marker_distance;
      in.coarse_tet_vertices = rigbuild::kDefaultCoarseTetVertices;  // as build-rig builds it
      rigbuild::Progress progress("tetrig demo", options.quiet ? rigbuild::Progress::Mode::kQuiet : rigbuild::Progress::Mode::kAuto);
      const Rig rig = rigbuild::buildRig(in, nullptr, &progress);
      std::filesystem::create_directories(cached.parent_path());
      rigbuild::writeFileAtomically(cached, serializeRig(rig));
      if (!options.quiet) std::printf("tetrig demo: rig cached in %s\n", cached.string().c_str());
    }
    run.rig_path = cached.string();
    run.source = "c3d:" + options.c3d;
    run.frames = options.frames;
  }
  if (options.no_report) return runLive(run);

  // The report: the solver's frame log (sized now, before the loop starts) and a reader of the
  // segment in this process.
  std::size_t log_frames = run.frames;
  int log_markers = run.rig ? static_cast<int>(run.rig->markers.size()) : 64;
  if (run.source.rfind("c3d:", 0) == 0) {
    const drivers::C3DClip clip = drivers::C3DClip::load(run.source.substr(4));
    log_frames = log_frames != 0 ? std::min<std::size_t>(log_frames, clip.frameCount()) : clip.frameCount();
    log_markers = clip.pointCount();
  }
  run.frame_log_capacity = log_frames != 0 ? log_frames : 120 * 120;  // unknown length: the first 2 minutes at 120 Hz
  run.frame_log_markers = std::clamp(log_markers, 0, kMaxMarkers);
  SegmentFrameCapture capture(run.publish, options.sheet_frames);
  capture.start();
  RunOutcome outcome;
  int code = 0;
  try {
    code = runLive(run, &outcome);
  } catch (...) {
    capture.stop();
    throw;
  }
  capture.stop();
  std::fflush(stdout);  // the run's summary before any report error on stderr
  if (code != 0) {
    std::fprintf(stderr, "tetrig demo: error: the run failed (status %d): no report written\n", code);
    return code;
  }
  DemoReportOptions report;
  report.dir = options.report;
  report.demo = {{"data", options.mesh.empty() ? "default" : "mesh and clip"}, {"source", run.source}};
  if (!options.mesh.empty()) {
    report.demo["mesh"] = options.mesh;
    report.demo["c3d"] = options.c3d;
  }
  const std::vector<CapturedFrame> frames = capture.pick();
  if (frames.empty()) throw std::runtime_error("no report written: no frame was read from the segment (" + capture.error() + ")");
  if (options.mesh.empty() && run.rig) report.demo["skin_vs_true_surface_mm"] = characterSurfaceJson(*run.rig, capture.captured(), options.quiet);
  try {
    (void)writeDemoReport(report, outcome, frames, capture.triangles());
  } catch (const std::exception& e) {
    throw std::runtime_error(std::string("no report written in ") + options.report + ": " + e.what());
  }
  std::printf("tetrig demo: report in %s: summary.json, sheet.png (%zu frames), latency.png\n",
              std::filesystem::absolute(options.report).string().c_str(), frames.size());
  return 0;
}

}  // namespace tetrig::tools
