// `tetrig run` (tools/run.hpp): source -> mailbox -> solver thread -> shared memory.
#include "run.hpp"
#include "run_dds.hpp"
#include "signal_scope.hpp"
#include "solver_flags.hpp"

#include "tetrig/clock.hpp"
#include "tetrig/drivers/c3d_reader.hpp"
#include "tetrig/drivers/source_factory.hpp"
#include "tetrig/frame_loop.hpp"
#include "tetrig/live_rig.hpp"
#include "tetrig/printable_text.hpp"
#include "tetrig/rigbuild/output_guard.hpp"
#include "tetrig/rigbuild/write_file_atomic.hpp"
#include "tetrig/shm_publisher.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <fstream>
#include <memory>
#include <stdexcept>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

extern char** environ;

namespace tetrig::tools {

namespace {

// Labels come from files and devices: shown escaped (tetrig/printable_text.hpp) and cut short.
std::string joinLabels(const std::vector<std::string>& labels, std::size_t max_shown = 12) {
  std::string out;
  for (std::size_t i = 0; i < labels.size() && i < max_shown; ++i) out += (i ? ", " : "") + printableText(labels[i], 64);
  if (labels.size() > max_shown) out += ", ... (" + std::to_string(labels.size()) + " in all)";
  return out;
}

double us(std::int64_t ns) { return static_cast<double>(ns) * 1e-3; }

nlohmann::json phaseJson(const LatencyHistogram& h) {
  return {{"p50", us(h.percentileNs(0.50))}, {"p99", us(h.percentileNs(0.99))}, {"max", us(h.maxNs())}, {"count", h.count()}};
}

// A child process: /bin/sh -c "<command> <segment>". Returns its pid (or -1).
pid_t spawnConsumer(const std::string& command) {
  const std::string shell_command = command;
  std::vector<char*> argv = {const_cast<char*>("/bin/sh"), const_cast<char*>("-c"), const_cast<char*>(shell_command.c_str()), nullptr};
  pid_t pid = -1;
  if (posix_spawn(&pid, "/bin/sh", nullptr, nullptr, argv.data(), environ) != 0) return -1;
  return pid;
}

// Waits up to timeout for the child; kills it if still running. Returns its exit status (or -1).
int reapConsumer(pid_t pid, std::chrono::milliseconds timeout) {
  const auto end = std::chrono::steady_clock::now() + timeout;
  int status = 0;
  while (std::chrono::steady_clock::now() < end) {
    const pid_t r = waitpid(pid, &status, WNOHANG);
    if (r == pid) return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + (WIFSIGNALED(status) ? WTERMSIG(status) : 0);
    if (r < 0) return -1;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  kill(pid, SIGTERM);
  waitpid(pid, &status, 0);
  return -1;
}

}  // namespace

// Waits until process `pid` maps `file` (its /proc/PID/maps names it), the process ends, or
// `timeout` passes.
static void waitUntilMapped(pid_t pid, const std::string& file, std::chrono::milliseconds timeout) {
  if (pid <= 0) return;
  const auto end = std::chrono::steady_clock::now() + timeout;
  const std::string maps = "/proc/" + std::to_string(pid) + "/maps";
  while (std::chrono::steady_clock::now() < end) {
    std::ifstream in(maps);
    if (!in) return;  // the process is gone
    for (std::string line; std::getline(in, line);) {
      if (line.size() >= file.size() && line.compare(line.size() - file.size(), file.size(), file) == 0) return;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
}

std::size_t stillLeadFrames(const drivers::C3DClip& clip, double threshold_mm) {
  const std::size_t frames = clip.frameCount();
  const int points = clip.pointCount();
  if (frames == 0 || points == 0) return 0;
  const double k = clip.unitsToMm();
  std::vector<float> first(static_cast<std::size_t>(points) * 3, 0.0f);
  std::vector<std::uint8_t> seen(static_cast<std::size_t>(points), 0);
  for (std::size_t f = 0; f < frames; ++f) {
    const float* p = clip.positions(f);
    for (int i = 0; i < points; ++i) {
      if (clip.pointKind(i) != drivers::C3DPointKind::kMarker || !clip.isValid(f, i)) continue;
      const auto u = static_cast<std::size_t>(i);
      if (!seen[u]) {
        seen[u] = 1;
        for (int c = 0; c < 3; ++c) first[u * 3 + static_cast<std::size_t>(c)] = p[u * 3 + static_cast<std::size_t>(c)];
        continue;
      }
      const double dx = p[u * 3] - first[u * 3], dy = p[u * 3 + 1] - first[u * 3 + 1], dz = p[u * 3 + 2] - first[u * 3 + 2];
      if (k * std::sqrt(dx * dx + dy * dy + dz * dz) > threshold_mm) return f;
    }
  }
  return frames;
}

int runLive(const RunOptions& options, RunOutcome* outcome) {
  if (options.iterations < 1) throw std::invalid_argument("--iterations must be at least 1");
  if (!options.final_obj.empty()) {
    const std::filesystem::path inputs[] = {options.rig_path, options.coarse_rig_path};
    rigbuild::checkOutputPath(options.final_obj, rigbuild::OutputKind::kObj, inputs, false);
  }
  // 1. The rig and the live rig (load time: allocation, factorization).
  std::optional<Rig> loaded;
  if (!options.rig) loaded = loadRigFile(options.rig_path);
  const Rig& rig = options.rig ? *options.rig : *loaded;
  LiveRigOptions live_options;
  live_options.occlusion_blend_s = options.occlusion_blend_ms * 1e-3;
  live_options.normals = options.normals;
  const int pose_threads = options.pose_threads > 0 ? options.pose_threads : 1;
  live_options.split_pose_transfer = pose_threads >= 2;
  checkSolverSettings(options.solver);
  live_options.solver = options.solver;
  std::optional<Rig> coarse;
  if (!options.coarse_rig_path.empty()) coarse = loadRigFile(options.coarse_rig_path);
  LiveRig live(rig, live_options, coarse ? &*coarse : nullptr);

  if (live.volumeNotKept())
    std::fprintf(stderr, "tetrig run: note: the rig's fine mesh is not closed, so its volume is not kept (the volume constraint needs "
                         "a watertight surface)\n");

  // 2. The source, its labels, the binding.
  devices::SourceOpenOptions open;
  open.pacing = options.as_fast_as_possible ? drivers::Pacing::kLockstep : drivers::Pacing::kRealTime;
  open.speed = options.speed;
  open.loop = options.loop;
  open.rate_hz = options.rate_hz;
  open.c3d_keep_zero_points = options.keep_zero_markers;
  if (options.source.rfind("synthetic", 0) == 0) {
    // The synthetic source sways the rig's own markers about their rest positions (device mm).
    open.synthetic_rest_mm = markerRestPositionsMm(rig);
    for (const RigMarker& m : rig.markers) open.synthetic_labels.push_back(m.label);
  }
  std::unique_ptr<drivers::MarkerSource> source = devices::openMarkerSource(options.source, open);
  // Where a clip run is (frame k of n) for the header and the status line.
  std::optional<ClipPosition> clip_position;
  if (options.source.rfind("c3d:", 0) == 0) {
    drivers::C3DReadOptions read;
    read.keep_zero_points = options.keep_zero_markers;
    const drivers::C3DClip clip = drivers::C3DClip::load(options.source.substr(4), read);
    const double rate = options.rate_hz > 0 ? options.rate_hz : clip.frameRate();
    clip_position = ClipPosition{clip.frameCount(), rate, rate > 0 ? static_cast<double>(stillLeadFrames(clip)) / rate : 0.0};
  }
  auto mailbox = std::make_unique<FrameMailbox>();
  // Sources that know their labels before they start (playback, synthetic, the Hydra) start only
  // once the solver waits, so that no frame waits for the set-up; a device names its markers
  // after it opens, so it starts first.
  std::vector<std::string> labels;
  const bool start_late = source->waitForLabels(std::chrono::milliseconds(0), labels);
  if (!start_late && !source->start(*mailbox))
    throw std::runtime_error("source " + options.source + " did not start: " + source->lastError());
  if (!start_late && !source->waitForLabels(std::chrono::milliseconds(static_cast<std::int64_t>(options.label_timeout_ms)), labels)) {
    source->stop();
    throw std::runtime_error("source " + options.source + " named no markers within " +
                             std::to_string(static_cast<int>(options.label_timeout_ms)) +
                             " ms (a marker-stream device must send its descriptor; see docs/protocol.md)");
  }
  const MarkerBindingReport binding = live.bindLabels(labels);
  if (binding.matched == 0 && binding.sensors_matched == 0) {
    source->stop();
    std::vector<std::string> rig_labels;
    for (const RigMarker& m : rig.markers) rig_labels.push_back(m.label);
    std::vector<std::string> named;
    for (const std::string& l : labels)
      if (!l.empty()) named.push_back(l);
    throw std::runtime_error("the source's markers share no label with the rig (rig: " + joinLabels(rig_labels) +
                             "; source: " + (named.empty() ? std::string("none") : joinLabels(named)) +
                             "): build the rig from a clip of the same marker set");
  }
  // 3. The segment.
  ShmPublisherOptions shm_options;
  shm_options.name = options.publish.empty() || options.publish.front() == '/' ? options.publish : "/" + options.publish;
  shm_options.normals = options.normals;
  shm_options.permissions = options.shm_permissions;
  std::vector<std::string> rig_labels;
  for (const RigMarker& m : rig.markers) rig_labels.push_back(m.label);
  ShmStaticData static_data;
  static_data.triangles = live.fineTriangles();
  static_data.rest_positions = live.restPositions();
  static_data.rig_name = rig.name;
  static_data.marker_labels = rig_labels;
  std::unique_ptr<ShmPublisher> publisher;
  try {
    publisher = std::make_unique<ShmPublisher>(shm_options, live.fineVertexCount(), static_data);
  } catch (...) {
    source->stop();
    throw;
  }
  // 3b. DDS (--dds; docs/dds.md): a thread of its own follows the segment and writes each frame to DDS.
  std::unique_ptr<RunDds> dds;
  try {
    dds = std::make_unique<RunDds>(options, *publisher);
  } catch (...) {
    source->stop();
    throw;
  }

  // The banner once the segment exists (a refused segment is one error line, nothing before it).
  if (!options.quiet) {
    std::printf("tetrig run: %s\n", printableText(source->describe()).c_str());
    std::printf("  rig: %s: %d tet vertices, %d tets, %d fine vertices, %zu markers; %d bound by label\n", printableText(rig.name, 256).c_str(),
                rig.tet_mesh.vertexCount(), rig.tet_mesh.tetCount(), live.fineVertexCount(), rig.markers.size(), binding.matched);
    if (clip_position && clip_position->rate_hz > 0) {
      std::printf("  clip: %zu frames, %.1f s at %g Hz", clip_position->frames, static_cast<double>(clip_position->frames) / clip_position->rate_hz,
                  clip_position->rate_hz);
      if (clip_position->still_s >= 0.5) std::printf("; it starts with %.1f s of a still pose", clip_position->still_s);
      std::printf("\n");
    }
    if (live.coarseLevel() != nullptr)
      std::printf("  coarse level: %d tets, %d iterations per frame\n", live.coarseLevel()->deformer().tetCount(),
                  live.coarseLevel()->options().iterations);
    const SolverSettings& solver = options.solver;
    if (solver.rotation_extrapolation > 0.0) std::printf("  temporal prediction of each frame's start: on\n");
    if (solver.volume_constraint && !live.volumeNotKept())
      std::printf("  fine-mesh volume kept at rest: on (its linearization runs after each publish)\n");
    if (solver.after_publish_iterations > 0)
      std::printf("  %d iterations after each publish (on that frame's targets, within its budget)\n", solver.after_publish_iterations);
    std::printf("  over-relaxation of the rotation update: omega %.3g\n", solver.rotation_relaxation);
    if (solver.inversion_guard > 0.0 && solver.inversion_guard_solves > 0)
      std::printf("  inversion guard: body tets squashed below %.3g of their volume up to %.3g times stiffer, implicit (%d "
                  "conjugate-gradient steps per iteration)\n",
                  solver.inversion_guard_threshold, 1.0 + solver.inversion_guard, solver.inversion_guard_solves);
    else if (solver.inversion_guard > 0.0)
      std::printf("  inversion guard: body tets squashed below %.3g of their volume up to %.3g times stiffer\n",
                  solver.inversion_guard_threshold, 1.0 + solver.inversion_guard);
    if (!binding.missing.empty())
      std::printf("  note: %zu rig markers the source never names are treated as occluded: %s\n", binding.missing.size(),
                  joinLabels(binding.missing).c_str());
    if (!rig.pose_sensors.empty())
      std::printf("  pose sensors: %d of %zu bound%s%s\n", binding.sensors_matched, rig.pose_sensors.size(),
                  binding.missing_sensors.empty() ? "" : "; never named by the source (their regions stay put): ",
                  joinLabels(binding.missing_sensors).c_str());
    if (!binding.unknown.empty())
      std::printf("  note: %zu source markers the rig does not know are ignored: %s\n", binding.unknown.size(),
                  joinLabels(binding.unknown).c_str());
  }

  // 4. The solver thread.
  const double rate = source->nominalRateHz();
  FrameLoopOptions loop_options;
  loop_options.max_iterations = options.iterations;
  const double budget_ms = options.budget_ms > 0 ? options.budget_ms : rate > 0 ? 0.9 * 1000.0 / rate : 8.0;
  loop_options.budget_ns = static_cast<std::int64_t>(budget_ms * 1e6);
  loop_options.stale_after_ns = static_cast<std::int64_t>(options.stale_ms * 1e6);
  loop_options.max_frames = options.frames;
  loop_options.cpu = options.cpu;
  loop_options.realtime_fifo = options.fifo;
  loop_options.lock_memory = options.lock_memory;
  loop_options.frame_log_capacity = options.frame_log_capacity;
  loop_options.frame_log_markers = options.frame_log_markers;
  const StopSignalScope signals;
  FrameLoop loop(*mailbox, live, *publisher, loop_options);
  loop.start();
  // A consumer (tetrig demo's) starts before the frames do, so that it sees the first one: the
  // source waits (at most 2 s) until the consumer has mapped the segment.
  pid_t consumer = -1;
  if (!options.consumer_command.empty()) {
    consumer = spawnConsumer(options.consumer_command + " " + options.publish);
    waitUntilMapped(consumer, "/dev/shm" + shm_options.name, std::chrono::seconds(2));
  }
  if (start_late && !source->start(*mailbox)) {
    loop.requestStop();
    loop.join();
    throw std::runtime_error("source " + options.source + " did not start: " + source->lastError());
  }
  if (!options.quiet)
    std::printf("  publishing to shared memory '%s' (%s); budget %.2f ms, %d iterations per frame, pose transfer on %d thread%s\n",
                options.publish.c_str(), options.normals ? "positions and normals" : "positions", budget_ms, options.iterations,
                pose_threads, pose_threads > 1 ? "s" : "");
  if (!options.quiet) dds->printBanner();
  std::fflush(stdout);

  // 5. Wait for the end: source finished and drained, --frames reached, or a signal.
  const bool tty = options.status_line && !options.quiet && isatty(STDERR_FILENO);
  std::uint64_t last_frames = 0;
  int idle_polls = 0;
  auto last_status = std::chrono::steady_clock::now();
  std::uint64_t status_frames = 0;
  const std::int64_t start_ns = monotonicNowNs();
  std::string end_reason = "source ended";
  while (true) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    const FrameLoopSnapshot s = loop.snapshot();
    if (const int stop = StopSignalScope::pending(); stop != 0) {
      end_reason = StopSignalScope::describe(stop);
      break;
    }
    if (loop.finished()) {
      end_reason = "frame limit reached";
      break;
    }
    if (source->finished() && !mailbox->hasPending()) {
      idle_polls = s.counters.frames == last_frames ? idle_polls + 1 : 0;
      if (idle_polls >= 2) break;
    }
    last_frames = s.counters.frames;
    const auto now = std::chrono::steady_clock::now();
    if (tty && now - last_status >= std::chrono::milliseconds(250)) {
      const double dt = std::chrono::duration<double>(now - last_status).count();
      std::string where;
      if (clip_position && clip_position->frames > 0 && clip_position->rate_hz > 0) {
        const std::uint64_t k = source->stats().frames_published % clip_position->frames;
        char buf[96];
        std::snprintf(buf, sizeof buf, "clip %llu / %zu (%.1f / %.1f s) | ", static_cast<unsigned long long>(k), clip_position->frames,
                      static_cast<double>(k) / clip_position->rate_hz, static_cast<double>(clip_position->frames) / clip_position->rate_hz);
        where = buf;
      }
      std::fprintf(stderr,
                   "\r\033[2K%s%8llu frames | %6.1f Hz | latency p50 %.3f ms p99 %.3f ms | %.2f it | occluded %llu | unknown %llu | "
                   "dropped %llu | misses %llu%s",
                   where.c_str(), static_cast<unsigned long long>(s.counters.frames), static_cast<double>(s.counters.frames - status_frames) / dt,
                   static_cast<double>(s.recent_p50_ns) * 1e-6, static_cast<double>(s.recent_p99_ns) * 1e-6,
                   s.counters.frames ? static_cast<double>(s.counters.iterations) / static_cast<double>(s.counters.frames) : 0.0,
                   static_cast<unsigned long long>(s.counters.occluded_marker_frames),
                   static_cast<unsigned long long>(s.counters.unknown_marker_frames),
                   static_cast<unsigned long long>(s.counters.mailbox_dropped),
                   static_cast<unsigned long long>(s.counters.budget_misses),
                   !source->finished() && !source->stats().connected ? " | DEVICE NOT CONNECTED" : s.stale ? " | STALE" : "");
      last_status = now;
      status_frames = s.counters.frames;
    }
  }
  if (tty) std::fprintf(stderr, "\r\033[2K");
  loop.requestStop();
  loop.join();
  source->stop();
  const double seconds = static_cast<double>(monotonicNowNs() - start_ns) * 1e-9;
  const FrameLoopCounters c = loop.counters();
  const FrameLoopLatency& l = loop.latency();
  const drivers::MarkerSourceStats source_stats = source->stats();
  dds->stop();  // before the segment goes: the bridge reads it
  publisher.reset();  // state stopped, name unlinked: consumers see a clean end
  int consumer_status = 0;
  if (consumer > 0) consumer_status = reapConsumer(consumer, std::chrono::seconds(5));

  if (!options.quiet) {
    std::printf("tetrig run: %s after %.1f s: %llu frames solved (%.1f Hz), %.2f iterations per frame\n", end_reason.c_str(), seconds,
                static_cast<unsigned long long>(c.frames), seconds > 0 ? static_cast<double>(c.frames) / seconds : 0.0,
                c.frames ? static_cast<double>(c.iterations) / static_cast<double>(c.frames) : 0.0);
    std::printf("  latency (us)            p50      p99      max\n");
    const std::pair<const char*, const LatencyHistogram*> rows[] = {
        {"receive -> taken", &l.receive_to_taken}, {"step", &l.step}, {"pose transfer", &l.pose_transfer},
        {"receive -> published", &l.receive_to_published}, {"overhead", &l.overhead}, {"after publishing", &l.prepare_next}};
    for (const auto& [name, h] : rows)
      if (h->count() > 0 || h != &l.prepare_next)
        std::printf("  %-20s %8.1f %8.1f %8.1f\n", name, us(h->percentileNs(0.5)), us(h->percentileNs(0.99)), us(h->maxNs()));
    std::printf("  budget misses %llu, deadline hits %llu, frames dropped in the mailbox %llu, held poses %llu, stale periods %llu, "
                "frames received before the solver started %llu (not in the latencies)\n",
                static_cast<unsigned long long>(c.budget_misses), static_cast<unsigned long long>(c.deadline_hits),
                static_cast<unsigned long long>(c.mailbox_dropped), static_cast<unsigned long long>(c.held_frames),
                static_cast<unsigned long long>(c.stale_periods), static_cast<unsigned long long>(c.frames_before_start));
    if (c.rejected_target_frames != 0 || c.rejected_poses != 0)
      std::printf("  frames with rejected marker targets %llu, rejected solved poses %llu (last pose republished; see docs/live.md)\n",
                  static_cast<unsigned long long>(c.rejected_target_frames), static_cast<unsigned long long>(c.rejected_poses));
    if (c.rejected_marker_samples != 0)
      std::printf("  marker samples rejected as implausible %llu (predicted instead; see docs/live.md)\n",
                  static_cast<unsigned long long>(c.rejected_marker_samples));
    std::printf("  occluded marker-frames %llu, unknown marker-frames %llu; source: %llu frames, %llu lost, %llu decode errors\n",
                static_cast<unsigned long long>(c.occluded_marker_frames), static_cast<unsigned long long>(c.unknown_marker_frames),
                static_cast<unsigned long long>(source_stats.frames_published), static_cast<unsigned long long>(source_stats.frames_lost),
                static_cast<unsigned long long>(source_stats.decode_errors));
    std::printf("  solver thread: %s\n", loop.hygiene().c_str());
    dds->printSummary();
  }
  if (!options.final_obj.empty()) {
    std::vector<float> last(static_cast<std::size_t>(live.fineVertexCount()) * 3);
    live.writeLastPose(last.data(), nullptr);
    std::string text = "# tetrig: last published pose of " + printableText(rig.name, 256) + "\n";  // one comment line, whatever the name holds
    char line[96];
    for (std::size_t i = 0; i < last.size(); i += 3) {
      std::snprintf(line, sizeof line, "v %.9g %.9g %.9g\n", last[i], last[i + 1], last[i + 2]);
      text += line;
    }
    const auto tris = live.fineTriangles();
    for (std::size_t i = 0; i + 2 < tris.size(); i += 3) {
      std::snprintf(line, sizeof line, "f %d %d %d\n", tris[i] + 1, tris[i + 1] + 1, tris[i + 2] + 1);
      text += line;
    }
    rigbuild::writeFileAtomically(options.final_obj, std::span<const std::uint8_t>(reinterpret_cast<const std::uint8_t*>(text.data()), text.size()));
    if (!options.quiet) std::printf("  wrote %s\n", options.final_obj.c_str());
  }
  if (!options.stats_json.empty() || outcome != nullptr) {
    nlohmann::json j;
    j["frames"] = c.frames;
    j["budget_misses"] = c.budget_misses;
    j["dropped_frames"] = c.mailbox_dropped;
    j["occluded_marker_frames"] = c.occluded_marker_frames;
    j["unknown_marker_frames"] = c.unknown_marker_frames;
    j["held_frames"] = c.held_frames;
    // What each frame ran, so that a stats file says which configuration its latencies belong to.
    nlohmann::json solver = solverJson(options.solver);
    solver["iterations"] = options.iterations;
    solver["coarse_level"] = live.coarseLevel() != nullptr;
    solver["volume_not_kept"] = live.volumeNotKept();
    solver["pose_threads"] = pose_threads;
    j["solver"] = std::move(solver);
    j["rejected_target_frames"] = c.rejected_target_frames;
    j["rejected_poses"] = c.rejected_poses;
    j["rejected_marker_samples"] = c.rejected_marker_samples;
    j["stale_periods"] = c.stale_periods;
    j["frames_before_start"] = c.frames_before_start;
    j["deadline_hits"] = c.deadline_hits;
    j["iterations_per_frame"] = c.frames ? static_cast<double>(c.iterations) / static_cast<double>(c.frames) : 0.0;
    j["seconds"] = seconds;
    j["budget_ms"] = budget_ms;
    j["end"] = end_reason;
    j["source"] = {{"spec", options.source}, {"description", source->describe()}, {"rate_hz", rate},
                   {"frames_published", source_stats.frames_published}, {"frames_lost", source_stats.frames_lost},
                   {"decode_errors", source_stats.decode_errors}, {"late_frames", source_stats.late_frames}};
    j["rig"] = {{"name", rig.name}, {"tet_vertices", rig.tet_mesh.vertexCount()}, {"tets", rig.tet_mesh.tetCount()},
                {"fine_vertices", live.fineVertexCount()}, {"markers", rig.markers.size()}, {"markers_bound", binding.matched}};
    j["solver_thread"] = loop.hygiene();
    dds->addStats(j);
    j["latency_us"] = {{"receive_to_taken", phaseJson(l.receive_to_taken)},
                       {"step", phaseJson(l.step)},
                       {"pose_transfer", phaseJson(l.pose_transfer)},
                       {"receive_to_step_done", phaseJson(l.receive_to_step_done)},
                       {"receive_to_pose_done", phaseJson(l.receive_to_pose_done)},
                       {"receive_to_published", phaseJson(l.receive_to_published)},
                       {"overhead", phaseJson(l.overhead)},
                       {"prepare_next", phaseJson(l.prepare_next)}};
    if (!options.stats_json.empty()) {
      // Text from the rig and the source may hold bytes that are not UTF-8: replaced, not a failed run.
      const std::string text = j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace) + "\n";
      rigbuild::writeFileAtomically(options.stats_json, std::span<const std::uint8_t>(reinterpret_cast<const std::uint8_t*>(text.data()), text.size()));
    }
    if (outcome != nullptr) {
      outcome->stats = std::move(j);
      const auto log = loop.frameLog();
      outcome->frame_log.assign(log.begin(), log.end());
      outcome->frame_log_markers.resize(log.size());
      for (std::size_t i = 0; i < log.size(); ++i) {
        const auto markers = loop.frameLogMarkers(i);
        outcome->frame_log_markers[i].assign(markers.begin(), markers.end());
      }
      outcome->frame_log_dropped = loop.frameLogDropped();
      outcome->alignment = rig.alignment;
      outcome->rig_name = rig.name;
      outcome->budget_ms = budget_ms;
    }
  }
  if (consumer > 0 && consumer_status != 0) {
    std::fprintf(stderr, "tetrig run: error: the consumer exited with status %d\n", consumer_status);
    return 1;
  }
  return 0;
}

}  // namespace tetrig::tools
