// `tetrig run` (tools/run.hpp): source -> mailbox -> solver thread -> shared memory.
#include "run.hpp"
#include "run_dds.hpp"
#include "signal_scope.hpp"
#include "solver_flags.hpp"

#include "tetrig/coarse_level.hpp"
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
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include <sched.h>
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

namespace {

// One performer while the run lives. Members are destroyed in reverse order: the solver thread
// (loop) first, then the segment, the live rig and the mailbox it uses.
struct Performer {
  PerformerSpec spec;
  std::optional<Rig> loaded;
  const Rig* rig = nullptr;
  std::optional<Rig> coarse;
  std::unique_ptr<LiveRig> live;
  std::size_t source = 0;  // index into the run's sources
  MarkerBindingReport binding;
  std::unique_ptr<FrameMailbox> mailbox;
  ShmPublisherOptions shm_options;
  std::unique_ptr<ShmPublisher> publisher;
  std::unique_ptr<RunDds> dds;  // --dds: the bridge following the segment (docs/dds.md)
  double budget_ms = 0;
  int cpu = -1;
  std::unique_ptr<FrameLoop> loop;
  // The end: why, and the figures taken when it stopped.
  bool ended = false;
  std::string end_reason;
  int idle_polls = 0;
  std::uint64_t last_frames = 0;
  std::uint64_t status_frames = 0;
};

// A source and the performers it feeds (their mailboxes chained in this order).
struct SharedSource {
  std::string spec;
  std::unique_ptr<drivers::MarkerSource> source;
  std::vector<std::string> labels;
  bool start_late = false;  // knows its labels before it starts: started once every solver waits
  std::optional<ClipPosition> clip;
  std::vector<std::size_t> performers;
};

// Stops every source (and so every driver thread) when the run leaves by an exception.
struct SourceStopper {
  std::vector<SharedSource>& sources;
  ~SourceStopper() {
    for (SharedSource& s : sources)
      if (s.source) s.source->stop();
  }
};

std::vector<PerformerSpec> stageOf(const RunOptions& options) {
  if (!options.performers.empty()) return options.performers;
  PerformerSpec one;
  one.rig_path = options.rig ? std::string() : options.rig_path;
  one.coarse_rig_path = options.coarse_rig_path;
  one.source = options.source;
  one.publish = options.publish;
  one.cpu = options.cpu;
  one.name = options.publish;
  return {one};
}

// 1. The rig and the live rig (load time: allocation, factorization).
void loadPerformer(const RunOptions& options, Performer& p) {
  if (options.rig && options.performers.empty()) {
    p.rig = &*options.rig;
  } else {
    p.loaded = loadRigFile(p.spec.rig_path);
    p.rig = &*p.loaded;
  }
  LiveRigOptions live_options;
  live_options.occlusion_blend_s = options.occlusion_blend_ms * 1e-3;
  live_options.normals = options.normals;
  live_options.split_pose_transfer = options.pose_threads >= 2;
  live_options.solver = options.solver;
  if (!p.spec.coarse_rig_path.empty()) p.coarse = loadRigFile(p.spec.coarse_rig_path);
  p.live = std::make_unique<LiveRig>(*p.rig, live_options, p.coarse ? &*p.coarse : nullptr);
  p.mailbox = std::make_unique<FrameMailbox>();
}

// 2. A source (opened once for every performer naming it), its labels, and where a clip run is.
void openSource(const RunOptions& options, const Rig& first_rig, SharedSource& s) {
  devices::SourceOpenOptions open;
  open.pacing = options.as_fast_as_possible ? drivers::Pacing::kLockstep : drivers::Pacing::kRealTime;
  open.speed = options.speed;
  open.loop = options.loop;
  open.rate_hz = options.rate_hz;
  open.c3d_keep_zero_points = options.keep_zero_markers;
  if (s.spec.rfind("synthetic", 0) == 0) {
    // The synthetic source sways the (first) rig's own markers about their rest positions (device mm).
    open.synthetic_rest_mm = markerRestPositionsMm(first_rig);
    for (const RigMarker& m : first_rig.markers) open.synthetic_labels.push_back(m.label);
  }
  s.source = devices::openMarkerSource(s.spec, open);
  if (s.spec.rfind("c3d:", 0) == 0) {
    drivers::C3DReadOptions read;
    read.keep_zero_points = options.keep_zero_markers;
    const drivers::C3DClip clip = drivers::C3DClip::load(s.spec.substr(4), read);
    const double rate = options.rate_hz > 0 ? options.rate_hz : clip.frameRate();
    s.clip = ClipPosition{clip.frameCount(), rate, rate > 0 ? static_cast<double>(stillLeadFrames(clip)) / rate : 0.0};
  }
}

// Sources that know their labels before they start (playback, synthetic, the Hydra) start only
// once the solvers wait, so that no frame waits for the set-up; a device names its markers after
// it opens, so it starts first (into the first performer's mailbox: the chain is already built).
void learnLabels(const RunOptions& options, SharedSource& s, FrameMailbox& head) {
  s.start_late = s.source->waitForLabels(std::chrono::milliseconds(0), s.labels);
  if (s.start_late) return;
  if (!s.source->start(head)) throw std::runtime_error("source " + s.spec + " did not start: " + s.source->lastError());
  if (!s.source->waitForLabels(std::chrono::milliseconds(static_cast<std::int64_t>(options.label_timeout_ms)), s.labels))
    throw std::runtime_error("source " + s.spec + " named no markers within " + std::to_string(static_cast<int>(options.label_timeout_ms)) +
                             " ms (a marker-stream device must send its descriptor; see docs/protocol.md)");
}

std::vector<std::string> rigLabels(const Rig& rig) {
  std::vector<std::string> labels;
  for (const RigMarker& m : rig.markers) labels.push_back(m.label);
  return labels;
}

std::string performerPrefix(const Performer& p, bool several) {
  return several ? "performer " + printableText(p.spec.name, 64) + ": " : std::string();
}

// The binding of one performer to its source's labels (its subject's only, when it names one).
void bindPerformer(Performer& p, const SharedSource& s, bool several) {
  const std::vector<std::string> subjects = labelSubjects(s.labels);
  if (p.spec.subject.empty() && subjects.size() >= 2)
    throw std::runtime_error(performerPrefix(p, several) + "the source " + s.spec + " carries several performers (subjects " + joinLabels(subjects) +
                             "): name one with subject=NAME (tetrig run --performer ...,subject=NAME; docs/live.md, \"Several performers\")");
  if (!p.spec.subject.empty() && std::find(subjects.begin(), subjects.end(), p.spec.subject) == subjects.end())
    throw std::runtime_error(performerPrefix(p, several) + "the source " + s.spec + " has no subject '" + printableText(p.spec.subject, 64) +
                             "' (its subjects: " + (subjects.empty() ? std::string("none, its labels have no SUBJECT: prefix") : joinLabels(subjects)) + ")");
  p.binding = p.live->bindLabels(s.labels, p.spec.subject);
  if (p.binding.matched == 0 && p.binding.sensors_matched == 0) {
    std::vector<std::string> named;
    for (const std::string& l : s.labels)
      if (!l.empty()) named.push_back(l);
    throw std::runtime_error(performerPrefix(p, several) + "the source's markers share no label with the rig (rig: " + joinLabels(rigLabels(*p.rig)) +
                             "; source: " + (named.empty() ? std::string("none") : joinLabels(named)) +
                             "): build the rig from a clip of the same marker set");
  }
}

// 3. The performer's segment.
void createSegment(const RunOptions& options, Performer& p) {
  p.shm_options.name = p.spec.publish.empty() || p.spec.publish.front() == '/' ? p.spec.publish : "/" + p.spec.publish;
  p.shm_options.normals = options.normals;
  p.shm_options.permissions = options.shm_permissions;
  const std::vector<std::string> labels = rigLabels(*p.rig);  // the static data refers to it until the segment is written
  ShmStaticData static_data;
  static_data.triangles = p.live->fineTriangles();
  static_data.rest_positions = p.live->restPositions();
  static_data.rig_name = p.rig->name;
  static_data.marker_labels = labels;
  p.publisher = std::make_unique<ShmPublisher>(p.shm_options, p.live->fineVertexCount(), static_data);
  // DDS (--dds; docs/dds.md): a thread of its own follows the segment and writes each frame to DDS.
  p.dds = std::make_unique<RunDds>(options, *p.publisher);
}

void printBanner(const RunOptions& options, const Performer& p, const SharedSource& s, bool several) {
  const Rig& rig = *p.rig;
  const LiveRig& live = *p.live;
  if (several) {
    std::printf("performer %s: segment '%s'%s%s\n", printableText(p.spec.name, 64).c_str(), p.spec.publish.c_str(),
                p.spec.subject.empty() ? "" : ", subject ", printableText(p.spec.subject, 64).c_str());
    std::printf("  source: %s\n", printableText(s.source->describe()).c_str());
  } else {
    std::printf("tetrig run: %s\n", printableText(s.source->describe()).c_str());
  }
  std::printf("  rig: %s: %d tet vertices, %d tets, %d fine vertices, %zu markers; %d bound by label\n", printableText(rig.name, 256).c_str(),
              rig.tet_mesh.vertexCount(), rig.tet_mesh.tetCount(), live.fineVertexCount(), rig.markers.size(), p.binding.matched);
  if (s.clip && s.clip->rate_hz > 0) {
    std::printf("  clip: %zu frames, %.1f s at %g Hz", s.clip->frames, static_cast<double>(s.clip->frames) / s.clip->rate_hz, s.clip->rate_hz);
    if (s.clip->still_s >= 0.5) std::printf("; it starts with %.1f s of a still pose", s.clip->still_s);
    std::printf("\n");
  }
  if (live.coarseLevel() != nullptr)
    std::printf("  coarse level: %d tets, %d iterations per frame\n", live.coarseLevel()->deformer().tetCount(), live.coarseLevel()->options().iterations);
  const SolverSettings& solver = options.solver;
  if (solver.rotation_extrapolation > 0.0) std::printf("  temporal prediction of each frame's start: on\n");
  if (solver.volume_constraint && !live.volumeNotKept()) std::printf("  fine-mesh volume kept at rest: on (its linearization runs after each publish)\n");
  if (solver.after_publish_iterations > 0)
    std::printf("  %d iterations after each publish (on that frame's targets, within its budget)\n", solver.after_publish_iterations);
  std::printf("  over-relaxation of the rotation update: omega %.3g\n", solver.rotation_relaxation);
  if (solver.inversion_guard > 0.0 && solver.inversion_guard_solves > 0)
    std::printf("  inversion guard: body tets squashed below %.3g of their volume up to %.3g times stiffer, implicit (%d "
                "conjugate-gradient steps per iteration)\n",
                solver.inversion_guard_threshold, 1.0 + solver.inversion_guard, solver.inversion_guard_solves);
  else if (solver.inversion_guard > 0.0)
    std::printf("  inversion guard: body tets squashed below %.3g of their volume up to %.3g times stiffer\n", solver.inversion_guard_threshold,
                1.0 + solver.inversion_guard);
  const MarkerBindingReport& binding = p.binding;
  if (!binding.missing.empty())
    std::printf("  note: %zu rig markers the source never names are treated as occluded: %s\n", binding.missing.size(),
                joinLabels(binding.missing).c_str());
  if (!rig.pose_sensors.empty())
    std::printf("  pose sensors: %d of %zu bound%s%s\n", binding.sensors_matched, rig.pose_sensors.size(),
                binding.missing_sensors.empty() ? "" : "; never named by the source (their regions stay put): ",
                joinLabels(binding.missing_sensors).c_str());
  if (!binding.unknown.empty())
    std::printf("  note: %zu source markers the rig does not know are ignored: %s\n", binding.unknown.size(), joinLabels(binding.unknown).c_str());
  if (binding.other_subjects > 0) std::printf("  %d source markers of other subjects left to their performers\n", binding.other_subjects);
}

// The solver threads' CPUs: a performer's own (cpu=K), else, with several performers, one CPU
// each from the process's allowed set when there are enough; otherwise not pinned (and said).
void assignCpus(std::vector<Performer>& performers, bool quiet) {
  for (Performer& p : performers) p.cpu = p.spec.cpu;
  if (performers.size() < 2) return;
  std::vector<int> allowed;
  cpu_set_t set;
  CPU_ZERO(&set);
  if (sched_getaffinity(0, sizeof set, &set) == 0)
    for (int c = 0; c < CPU_SETSIZE; ++c)
      if (CPU_ISSET(c, &set)) allowed.push_back(c);
  std::vector<int> free_cpus;
  for (const int c : allowed)
    if (std::none_of(performers.begin(), performers.end(), [c](const Performer& p) { return p.spec.cpu == c; })) free_cpus.push_back(c);
  const auto unpinned = static_cast<std::size_t>(std::count_if(performers.begin(), performers.end(), [](const Performer& p) { return p.cpu < 0; }));
  if (unpinned == 0) return;
  if (free_cpus.size() >= unpinned) {
    std::size_t next = 0;
    for (Performer& p : performers)
      if (p.cpu < 0) p.cpu = free_cpus[next++];
  } else if (!quiet) {
    std::printf("note: %zu performers share %zu CPUs: their solver threads are not pinned and compete for time (budget misses are "
                "likely; docs/live.md, \"Several performers\")\n",
                performers.size(), allowed.size());
  }
}

void printSummary(const Performer& p, const SharedSource& s, double seconds, bool several) {
  const FrameLoop& loop = *p.loop;
  const FrameLoopCounters c = loop.counters();
  const FrameLoopLatency& l = loop.latency();
  const drivers::MarkerSourceStats source_stats = s.source->stats();
  if (several)
    std::printf("performer %s: %s after %.1f s: %llu frames solved (%.1f Hz), %.2f iterations per frame\n", printableText(p.spec.name, 64).c_str(),
                p.end_reason.c_str(), seconds, static_cast<unsigned long long>(c.frames), seconds > 0 ? static_cast<double>(c.frames) / seconds : 0.0,
                c.frames ? static_cast<double>(c.iterations) / static_cast<double>(c.frames) : 0.0);
  else
    std::printf("tetrig run: %s after %.1f s: %llu frames solved (%.1f Hz), %.2f iterations per frame\n", p.end_reason.c_str(), seconds,
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
  if (c.frames > 0)
    std::printf("  frames the solver was polling for when they came (--spin-before-frame-us): %llu of %llu\n",
                static_cast<unsigned long long>(c.frames_spun_for), static_cast<unsigned long long>(c.frames));
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
  p.dds->printSummary();
}

// The --stats-json object of one performer (docs/live.md, "Statistics").
nlohmann::json performerJson(const RunOptions& options, const Performer& p, const SharedSource& s, double seconds, bool several) {
  const FrameLoop& loop = *p.loop;
  const FrameLoopCounters c = loop.counters();
  const FrameLoopLatency& l = loop.latency();
  const drivers::MarkerSourceStats source_stats = s.source->stats();
  const Rig& rig = *p.rig;
  nlohmann::json j;
  if (several) {
    j["name"] = p.spec.name;
    j["segment"] = p.spec.publish;
    j["subject"] = p.spec.subject;
    j["cpu"] = p.cpu;
  }
  j["frames"] = c.frames;
  j["budget_misses"] = c.budget_misses;
  j["dropped_frames"] = c.mailbox_dropped;
  j["occluded_marker_frames"] = c.occluded_marker_frames;
  j["unknown_marker_frames"] = c.unknown_marker_frames;
  j["held_frames"] = c.held_frames;
  // What each frame ran, so that a stats file says which configuration its latencies belong to.
  nlohmann::json solver = solverJson(options.solver);
  solver["iterations"] = options.iterations;
  solver["coarse_level"] = p.live->coarseLevel() != nullptr;
  solver["volume_not_kept"] = p.live->volumeNotKept();
  solver["pose_threads"] = options.pose_threads > 0 ? options.pose_threads : 1;
  j["solver"] = std::move(solver);
  j["rejected_target_frames"] = c.rejected_target_frames;
  j["rejected_poses"] = c.rejected_poses;
  j["rejected_marker_samples"] = c.rejected_marker_samples;
  j["stale_periods"] = c.stale_periods;
  j["frames_before_start"] = c.frames_before_start;
  j["frames_spun_for"] = c.frames_spun_for;
  j["spin_before_frame_us"] = options.spin_before_frame_us;
  j["deadline_hits"] = c.deadline_hits;
  j["iterations_per_frame"] = c.frames ? static_cast<double>(c.iterations) / static_cast<double>(c.frames) : 0.0;
  j["seconds"] = seconds;
  j["budget_ms"] = p.budget_ms;
  j["end"] = p.end_reason;
  j["source"] = {{"spec", s.spec}, {"description", s.source->describe()}, {"rate_hz", s.source->nominalRateHz()},
                 {"frames_published", source_stats.frames_published}, {"frames_lost", source_stats.frames_lost},
                 {"decode_errors", source_stats.decode_errors}, {"late_frames", source_stats.late_frames}};
  j["rig"] = {{"name", rig.name}, {"tet_vertices", rig.tet_mesh.vertexCount()}, {"tets", rig.tet_mesh.tetCount()},
              {"fine_vertices", p.live->fineVertexCount()}, {"markers", rig.markers.size()}, {"markers_bound", p.binding.matched}};
  j["solver_thread"] = loop.hygiene();
  p.dds->addStats(j);
  j["latency_us"] = {{"receive_to_taken", phaseJson(l.receive_to_taken)},
                     {"step", phaseJson(l.step)},
                     {"pose_transfer", phaseJson(l.pose_transfer)},
                     {"receive_to_step_done", phaseJson(l.receive_to_step_done)},
                     {"receive_to_pose_done", phaseJson(l.receive_to_pose_done)},
                     {"receive_to_published", phaseJson(l.receive_to_published)},
                     {"overhead", phaseJson(l.overhead)},
                     {"prepare_next", phaseJson(l.prepare_next)}};
  return j;
}

// The stage's totals: the counters summed over performers, the worst latency percentiles.
nlohmann::json totalsJson(const std::vector<nlohmann::json>& each) {
  nlohmann::json t;
  for (const char* key : {"frames", "budget_misses", "dropped_frames", "occluded_marker_frames", "unknown_marker_frames", "held_frames",
                          "rejected_target_frames", "rejected_poses", "rejected_marker_samples", "stale_periods", "deadline_hits"}) {
    std::uint64_t sum = 0;
    for (const nlohmann::json& j : each) sum += j[key].get<std::uint64_t>();
    t[key] = sum;
  }
  double p99 = 0, max = 0;
  for (const nlohmann::json& j : each) {
    p99 = std::max(p99, j["latency_us"]["receive_to_published"]["p99"].get<double>());
    max = std::max(max, j["latency_us"]["receive_to_published"]["max"].get<double>());
  }
  t["worst_receive_to_published_us"] = {{"p99", p99}, {"max", max}};
  t["performers"] = each.size();
  return t;
}

void writeFinalObj(const RunOptions& options, const Performer& p) {
  std::vector<float> last(static_cast<std::size_t>(p.live->fineVertexCount()) * 3);
  p.live->writeLastPose(last.data(), nullptr);
  std::string text = "# tetrig: last published pose of " + printableText(p.rig->name, 256) + "\n";  // one comment line, whatever the name holds
  char line[96];
  for (std::size_t i = 0; i < last.size(); i += 3) {
    std::snprintf(line, sizeof line, "v %.9g %.9g %.9g\n", last[i], last[i + 1], last[i + 2]);
    text += line;
  }
  const auto tris = p.live->fineTriangles();
  for (std::size_t i = 0; i + 2 < tris.size(); i += 3) {
    std::snprintf(line, sizeof line, "f %d %d %d\n", tris[i] + 1, tris[i + 1] + 1, tris[i + 2] + 1);
    text += line;
  }
  rigbuild::writeFileAtomically(options.final_obj, std::span<const std::uint8_t>(reinterpret_cast<const std::uint8_t*>(text.data()), text.size()));
  if (!options.quiet) std::printf("  wrote %s\n", options.final_obj.c_str());
}

void writeJson(const std::string& path, const nlohmann::json& j) {
  // Text from the rig and the source may hold bytes that are not UTF-8: replaced, not a failed run.
  const std::string text = j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace) + "\n";
  rigbuild::writeFileAtomically(path, std::span<const std::uint8_t>(reinterpret_cast<const std::uint8_t*>(text.data()), text.size()));
}

void fillOutcome(const Performer& p, nlohmann::json stats, RunOutcome& out) {
  out.stats = std::move(stats);
  const FrameLoop& loop = *p.loop;
  const auto log = loop.frameLog();
  out.frame_log.assign(log.begin(), log.end());
  out.frame_log_markers.resize(log.size());
  for (std::size_t i = 0; i < log.size(); ++i) {
    const auto markers = loop.frameLogMarkers(i);
    out.frame_log_markers[i].assign(markers.begin(), markers.end());
  }
  out.frame_log_dropped = loop.frameLogDropped();
  out.alignment = p.rig->alignment;
  out.rig_name = p.rig->name;
  out.budget_ms = p.budget_ms;
}

// The live status line (a terminal only): one part per performer.
void printStatus(std::vector<Performer>& performers, const std::vector<SharedSource>& sources, double dt) {
  std::string line = "\r\033[2K";
  const bool several = performers.size() > 1;
  for (Performer& p : performers) {
    const FrameLoopSnapshot s = p.loop->snapshot();
    const SharedSource& src = sources[p.source];
    char buf[512];
    if (several) {
      std::snprintf(buf, sizeof buf, "%s%s %llu fr %.0f Hz p99 %.2f ms miss %llu%s", &p == &performers.front() ? "" : " | ",
                    printableText(p.spec.name, 16).c_str(), static_cast<unsigned long long>(s.counters.frames),
                    static_cast<double>(s.counters.frames - p.status_frames) / dt, static_cast<double>(s.recent_p99_ns) * 1e-6,
                    static_cast<unsigned long long>(s.counters.budget_misses),
                    !src.source->finished() && !src.source->stats().connected ? " NOT CONNECTED" : s.stale ? " STALE" : "");
    } else {
      std::string where;
      if (src.clip && src.clip->frames > 0 && src.clip->rate_hz > 0) {
        const std::uint64_t k = src.source->stats().frames_published % src.clip->frames;
        char w[96];
        std::snprintf(w, sizeof w, "clip %llu / %zu (%.1f / %.1f s) | ", static_cast<unsigned long long>(k), src.clip->frames,
                      static_cast<double>(k) / src.clip->rate_hz, static_cast<double>(src.clip->frames) / src.clip->rate_hz);
        where = w;
      }
      std::snprintf(buf, sizeof buf,
                    "%s%8llu frames | %6.1f Hz | latency p50 %.3f ms p99 %.3f ms | %.2f it | occluded %llu | unknown %llu | "
                    "dropped %llu | misses %llu%s",
                    where.c_str(), static_cast<unsigned long long>(s.counters.frames), static_cast<double>(s.counters.frames - p.status_frames) / dt,
                    static_cast<double>(s.recent_p50_ns) * 1e-6, static_cast<double>(s.recent_p99_ns) * 1e-6,
                    s.counters.frames ? static_cast<double>(s.counters.iterations) / static_cast<double>(s.counters.frames) : 0.0,
                    static_cast<unsigned long long>(s.counters.occluded_marker_frames),
                    static_cast<unsigned long long>(s.counters.unknown_marker_frames),
                    static_cast<unsigned long long>(s.counters.mailbox_dropped), static_cast<unsigned long long>(s.counters.budget_misses),
                    !src.source->finished() && !src.source->stats().connected ? " | DEVICE NOT CONNECTED" : s.stale ? " | STALE" : "");
    }
    line += buf;
    p.status_frames = s.counters.frames;
  }
  std::fputs(line.c_str(), stderr);
}

// The options' checks across performers, before anything is opened. Returns the performers' specs.
std::vector<PerformerSpec> checkedStage(const RunOptions& options) {
  if (options.iterations < 1) throw std::invalid_argument("--iterations must be at least 1");
  checkSolverSettings(options.solver);
  std::vector<PerformerSpec> specs = stageOf(options);
  if (!options.performers.empty()) checkStage(specs);
  const bool several = specs.size() > 1;
  if (several && !options.final_obj.empty()) throw std::invalid_argument("--final-obj writes one performer's pose: not with several performers");
  if (several && !options.consumer_command.empty()) throw std::invalid_argument("a consumer command follows one performer: not with several performers");
  // The outputs replace no input and no file tetrig did not write (unless --force; an input never).
  std::vector<std::filesystem::path> inputs;
  for (const PerformerSpec& p : specs) {
    inputs.push_back(p.rig_path);
    if (!p.coarse_rig_path.empty()) inputs.push_back(p.coarse_rig_path);
    for (const char* file_source : {"c3d:", "replay:"})
      if (p.source.rfind(file_source, 0) == 0) inputs.push_back(p.source.substr(std::strlen(file_source)));
  }
  if (!options.final_obj.empty()) rigbuild::checkOutputPath(options.final_obj, rigbuild::OutputKind::kObj, inputs, options.force, "--out");
  if (!options.stats_json.empty())
    rigbuild::checkOutputPath(options.stats_json, rigbuild::OutputKind::kJson, inputs, options.force, "--stats-json");
  return specs;
}

// Each source spec once, with the performers it feeds, in order of first use.
std::vector<SharedSource> groupSources(std::vector<Performer>& performers) {
  std::vector<SharedSource> sources;
  for (std::size_t i = 0; i < performers.size(); ++i) {
    auto it = std::find_if(sources.begin(), sources.end(), [&](const SharedSource& s) { return s.spec == performers[i].spec.source; });
    if (it == sources.end()) {
      sources.emplace_back();
      sources.back().spec = performers[i].spec.source;
      it = sources.end() - 1;
    }
    it->performers.push_back(i);
    performers[i].source = static_cast<std::size_t>(it - sources.begin());
  }
  return sources;
}

// A performer's solver thread: its budget from the source's rate (or --budget-ms), started.
void startSolver(const RunOptions& options, Performer& p, double source_rate_hz) {
  FrameLoopOptions loop_options;
  loop_options.max_iterations = options.iterations;
  p.budget_ms = options.budget_ms > 0 ? options.budget_ms : source_rate_hz > 0 ? 0.9 * 1000.0 / source_rate_hz : 8.0;
  loop_options.budget_ns = static_cast<std::int64_t>(p.budget_ms * 1e6);
  loop_options.stale_after_ns = static_cast<std::int64_t>(options.stale_ms * 1e6);
  loop_options.max_frames = options.frames;
  loop_options.cpu = p.cpu;
  loop_options.realtime_fifo = options.fifo;
  loop_options.spin_before_frame_ns = static_cast<std::int64_t>(options.spin_before_frame_us * 1e3);
  loop_options.lock_memory = options.lock_memory;
  loop_options.frame_log_capacity = options.frame_log_capacity;
  loop_options.frame_log_markers = options.frame_log_markers;
  loop_options.frame_log_positions_crc = options.frame_log_positions_crc;
  p.loop = std::make_unique<FrameLoop>(*p.mailbox, *p.live, *p.publisher, loop_options);
  p.loop->start();
}

// One line per performer: where it publishes, its budget and threads.
void printPublishing(const RunOptions& options, const std::vector<Performer>& performers, bool several) {
  const int pose_threads = options.pose_threads > 0 ? options.pose_threads : 1;
  for (const Performer& p : performers)
    std::printf("  %spublishing to shared memory '%s' (%s); budget %.2f ms, %d iterations per frame, pose transfer on %d thread%s%s\n",
                several ? (printableText(p.spec.name, 64) + ": ").c_str() : "", p.spec.publish.c_str(),
                options.normals ? "positions and normals" : "positions", p.budget_ms, options.iterations, pose_threads, pose_threads > 1 ? "s" : "",
                several && p.cpu >= 0 ? (", solver on CPU " + std::to_string(p.cpu)).c_str() : "");
  for (const Performer& p : performers) p.dds->printBanner();
}

// Polls until every performer has ended: its source finished and drained, --frames reached, or a
// signal (which ends them all); the status line meanwhile on a terminal.
void waitForTheEnd(const RunOptions& options, std::vector<Performer>& performers, const std::vector<SharedSource>& sources) {
  const bool tty = options.status_line && !options.quiet && isatty(STDERR_FILENO);
  auto last_status = std::chrono::steady_clock::now();
  while (true) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    if (const int stop = StopSignalScope::pending(); stop != 0) {
      for (Performer& p : performers)
        if (!p.ended) {
          p.ended = true;
          p.end_reason = StopSignalScope::describe(stop);
        }
      break;
    }
    bool all_ended = true;
    for (Performer& p : performers) {
      if (p.ended) continue;
      const FrameLoopSnapshot s = p.loop->snapshot();
      const SharedSource& src = sources[p.source];
      if (p.loop->finished()) {
        p.ended = true;
        p.end_reason = "frame limit reached";
      } else if (src.source->finished() && !p.mailbox->hasPending()) {
        p.idle_polls = s.counters.frames == p.last_frames ? p.idle_polls + 1 : 0;
        if (p.idle_polls >= 2) {
          p.ended = true;
          p.end_reason = "source ended";
        }
      }
      p.last_frames = s.counters.frames;
      all_ended = all_ended && p.ended;
    }
    if (all_ended) break;
    const auto now = std::chrono::steady_clock::now();
    if (tty && now - last_status >= std::chrono::milliseconds(250)) {
      printStatus(performers, sources, std::chrono::duration<double>(now - last_status).count());
      last_status = now;
    }
  }
  if (tty) std::fprintf(stderr, "\r\033[2K");
}

// The stats (--stats-json, and the outcome for tests and tetrig demo): one performer's object, or
// {performers, totals, seconds}.
void writeStats(const RunOptions& options, const std::vector<Performer>& performers, const std::vector<SharedSource>& sources,
                double seconds, bool several, RunOutcome* outcome) {
  std::vector<nlohmann::json> each;
  for (const Performer& p : performers) each.push_back(performerJson(options, p, sources[p.source], seconds, several));
  nlohmann::json j;
  if (several) {
    j["performers"] = each;
    j["totals"] = totalsJson(each);
    j["seconds"] = seconds;
  } else {
    j = each[0];
  }
  if (!options.stats_json.empty()) {
    nlohmann::json file = j;
    file["generator"] = "tetrig run";  // tetrig's mark: a later run may replace this file
    writeJson(options.stats_json, file);
  }
  if (outcome != nullptr) {
    fillOutcome(performers[0], j, *outcome);  // several performers: the first one's, with the whole stats
    if (several) {
      outcome->performers.resize(performers.size());
      for (std::size_t i = 0; i < performers.size(); ++i) fillOutcome(performers[i], each[i], outcome->performers[i]);
    }
  }
}

}  // namespace

int runLive(const RunOptions& options, RunOutcome* outcome) {
  const std::vector<PerformerSpec> specs = checkedStage(options);
  const bool several = specs.size() > 1;

  // 1. Each performer's rig and live rig.
  std::vector<Performer> performers(specs.size());
  for (std::size_t i = 0; i < specs.size(); ++i) {
    performers[i].spec = specs[i];
    loadPerformer(options, performers[i]);
    if (performers[i].live->volumeNotKept())
      std::fprintf(stderr, "tetrig run: note: %sthe rig's fine mesh is not closed, so its volume is not kept (the volume constraint needs "
                           "a watertight surface)\n", performerPrefix(performers[i], several).c_str());
  }

  // 2. The sources (each opened once), the fan-out of their frames, the bindings.
  std::vector<SharedSource> sources = groupSources(performers);
  const SourceStopper stopper{sources};
  for (SharedSource& s : sources) {
    for (std::size_t k = 0; k + 1 < s.performers.size(); ++k)
      performers[s.performers[k]].mailbox->forwardTo(performers[s.performers[k + 1]].mailbox.get());
    openSource(options, *performers[s.performers.front()].rig, s);
    learnLabels(options, s, *performers[s.performers.front()].mailbox);
    for (const std::size_t i : s.performers) bindPerformer(performers[i], s, several);
  }

  // 3. The segments (a refused segment is one error line, nothing printed before it).
  for (Performer& p : performers) createSegment(options, p);
  if (!options.quiet)
    for (const Performer& p : performers) printBanner(options, p, sources[p.source], several);
  assignCpus(performers, options.quiet);

  // 4. The solver threads, then the sources that start late.
  const StopSignalScope signals;
  for (Performer& p : performers) startSolver(options, p, sources[p.source].source->nominalRateHz());
  // A consumer (tetrig demo's) starts before the frames do, so that it sees the first one: the
  // source waits (at most 2 s) until the consumer has mapped the segment.
  pid_t consumer = -1;
  if (!options.consumer_command.empty()) {
    consumer = spawnConsumer(options.consumer_command + " " + performers[0].spec.publish);
    waitUntilMapped(consumer, "/dev/shm" + performers[0].shm_options.name, std::chrono::seconds(2));
  }
  for (SharedSource& s : sources)
    if (s.start_late && !s.source->start(*performers[s.performers.front()].mailbox))
      throw std::runtime_error("source " + s.spec + " did not start: " + s.source->lastError());
  if (!options.quiet) printPublishing(options, performers, several);
  std::fflush(stdout);

  // 5. Wait for the end of every performer, then stop the solvers, the sources, the bridges and
  //    the segments, in that order.
  const std::int64_t start_ns = monotonicNowNs();
  waitForTheEnd(options, performers, sources);
  for (Performer& p : performers) p.loop->requestStop();
  for (Performer& p : performers) p.loop->join();
  for (SharedSource& s : sources) s.source->stop();
  const double seconds = static_cast<double>(monotonicNowNs() - start_ns) * 1e-9;
  for (Performer& p : performers) {
    p.dds->stop();        // before the segment goes: the bridge reads it
    p.publisher.reset();  // state stopped, name unlinked: consumers see a clean end
  }
  int consumer_status = 0;
  if (consumer > 0) consumer_status = reapConsumer(consumer, std::chrono::seconds(5));

  // 6. The summary, the final pose and the stats.
  if (!options.quiet)
    for (const Performer& p : performers) printSummary(p, sources[p.source], seconds, several);
  if (!options.final_obj.empty()) writeFinalObj(options, performers[0]);
  if (!options.stats_json.empty() || outcome != nullptr) writeStats(options, performers, sources, seconds, several, outcome);
  if (consumer > 0 && consumer_status != 0) {
    std::fprintf(stderr, "tetrig run: error: the consumer exited with status %d\n", consumer_status);
    return 1;
  }
  return 0;
}

}  // namespace tetrig::tools
