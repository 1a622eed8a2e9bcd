// The solver thread: mailbox -> live rig -> shared-memory slot (tetrig/frame_loop.hpp).
#include "tetrig/frame_loop.hpp"

#include "tetrig/clock.hpp"
#include "tetrig/live_rig.hpp"
#include "tetrig/rig_file.hpp"
#include "tetrig/shm_publisher.hpp"

#include <algorithm>
#include <array>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <stdexcept>
#include <thread>

#if defined(__linux__)
#include <pthread.h>
#include <sched.h>
#include <sys/mman.h>
#endif
#if defined(__x86_64__) || defined(__i386__)
#include <xmmintrin.h>
#endif

namespace tetrig {

namespace {

constexpr std::int64_t kHeartbeatNs = 100'000'000;  // heartbeat while idle
constexpr std::int64_t kMaxSleepNs = 50'000'000;    // re-check stop/stale at least this often
constexpr std::int64_t kSpinGraceNs = 1'000'000;    // polling goes on this long past a frame's due time
constexpr std::size_t kWarmChunkBytes = 64 * 1024;  // the working set is read in chunks, yielding and checking the mailbox between

constexpr int kRecentWindow = 128;                  // frames behind the status line's p50/p99

// Flush denormals to zero on this thread (near-identity covariances make them; DESIGN.md 8).
bool flushDenormals() noexcept {
#if defined(__x86_64__) || defined(__i386__)
  _mm_setcsr(_mm_getcsr() | 0x8040u);  // FTZ (bit 15) | DAZ (bit 6)
  return true;
#elif defined(__aarch64__)
  std::uint64_t fpcr = 0;
  __asm__ volatile("mrs %0, fpcr" : "=r"(fpcr));
  fpcr |= (1ull << 24);  // FZ
  __asm__ volatile("msr fpcr, %0" : : "r"(fpcr));
  return true;
#else
  return false;
#endif
}

// The segment's marker block (layout 1.1): each rig marker's target of this frame (rig units,
// rig.markers order = the segment's label order) and its state. A non-finite target (the live rig
// never steps with one) is published as 0 with the state unknown. No allocation.
void stageMarkers(const LiveRig& live, float* positions, std::uint8_t* states, std::size_t count) noexcept {
  const std::span<const Eigen::Vector3d> targets = live.markerTargets();
  for (std::size_t k = 0; k < count; ++k) {
    const Eigen::Vector3d& t = targets[k];
    float* p = positions + 3 * k;
    if (!t.allFinite()) {
      p[0] = p[1] = p[2] = 0.0f;
      states[k] = kShmMarkerUnknown;
      continue;
    }
    p[0] = static_cast<float>(t.x());
    p[1] = static_cast<float>(t.y());
    p[2] = static_cast<float>(t.z());
    if (live.markerRejected()[k] != 0) {
      states[k] = kShmMarkerRejected;
      continue;
    }
    switch (live.markerState(static_cast<std::int32_t>(k))) {
      case MarkerTrackState::kMeasured: states[k] = kShmMarkerMeasured; break;
      case MarkerTrackState::kReturning: states[k] = kShmMarkerBlended; break;
      case MarkerTrackState::kPredicted: states[k] = kShmMarkerPredicted; break;
      default: states[k] = kShmMarkerUnknown; break;
    }
  }
}

std::chrono::steady_clock::time_point steadyAt(std::int64_t ns) {
  return std::chrono::steady_clock::time_point(std::chrono::duration_cast<std::chrono::steady_clock::duration>(std::chrono::nanoseconds(ns)));
}

}  // namespace

FrameLoop::FrameLoop(FrameMailbox& mailbox, LiveRig& live_rig, ShmPublisher& publisher, const FrameLoopOptions& options)
    : mailbox_(mailbox), live_(live_rig), publisher_(publisher), options_(options) {
  if (publisher_.hasMarkerPositions() && static_cast<std::size_t>(publisher_.markerCount()) != live_.rig().markers.size()) {
    throw std::invalid_argument("frame loop: the segment '" + publisher_.name() + "' has " + std::to_string(publisher_.markerCount()) +
                                " marker labels but the rig has " + std::to_string(live_.rig().markers.size()) +
                                " markers: publish the rig's own labels (rig.markers order)");
  }
  options_.frame_log_markers = std::clamp(options_.frame_log_markers, 0, kMaxMarkers);
  // value-initialised: every page is touched here, not on the solver thread
  frame_log_.resize(options_.frame_log_capacity);
  frame_log_markers_.resize(options_.frame_log_capacity * static_cast<std::size_t>(options_.frame_log_markers));
}

std::span<const FrameLogMarker> FrameLoop::frameLogMarkers(std::size_t index) const noexcept {
  if (index >= frame_log_count_) return {};
  const std::size_t stride = static_cast<std::size_t>(options_.frame_log_markers);
  return {frame_log_markers_.data() + index * stride, frame_log_[index].marker_count};
}

FrameLoop::~FrameLoop() {
  requestStop();
  join();
}

void FrameLoop::start() {
  if (started_.exchange(true)) return;
  mailbox_dropped_at_start_ = mailbox_.dropped();
  thread_ = std::thread([this] { run(); });
  // Return once the solver waits for frames (its real-time set-up, mlockall above all, takes
  // milliseconds: frames received meanwhile are counted as received before the start).
  while (!hygiene_ready_.load(std::memory_order_acquire) && !done_.load(std::memory_order_acquire)) std::this_thread::yield();
}

void FrameLoop::requestStop() noexcept {
  stop_.store(true, std::memory_order_release);
  mailbox_.wake();
}

void FrameLoop::join() {
  if (thread_.joinable()) thread_.join();
}

void FrameLoop::applyHygiene() {
  std::string report;
  auto add = [&report](const std::string& part) { report += (report.empty() ? "" : "; ") + part; };
  add(flushDenormals() ? "flush-to-zero on" : "flush-to-zero not available on this CPU");
#if defined(__linux__)
  if (options_.lock_memory) {
    // MCL_CURRENT only: everything the frame path touches is allocated at load, and MCL_FUTURE would
    // make later allocations elsewhere in the process fail once RLIMIT_MEMLOCK is reached.
    if (mlockall(MCL_CURRENT) == 0) {
      add("memory locked");
    } else {
      add(std::string("memory lock refused: ") + std::strerror(errno));
    }
  }
  if (options_.cpu >= 0) {
    cpu_set_t set;
    CPU_ZERO(&set);
    CPU_SET(static_cast<unsigned>(options_.cpu), &set);
    const int rc = pthread_setaffinity_np(pthread_self(), sizeof(set), &set);
    add(rc == 0 ? "pinned to CPU " + std::to_string(options_.cpu)
                : "pinning to CPU " + std::to_string(options_.cpu) + " refused: " + std::strerror(rc));
  }
  if (options_.realtime_fifo) {
    sched_param param{};
    param.sched_priority = kFrameLoopFifoPriority;
    const int rc = pthread_setschedparam(pthread_self(), SCHED_FIFO, &param);
    add(rc == 0 ? "SCHED_FIFO priority " + std::to_string(kFrameLoopFifoPriority)
                : std::string("SCHED_FIFO refused: ") + std::strerror(rc));
  }
#else
  if (options_.lock_memory || options_.cpu >= 0 || options_.realtime_fifo)
    add("memory locking, pinning and SCHED_FIFO are Linux-only here: not applied");
#endif
  hygiene_ = report.empty() ? "none requested" : report;
  start_ns_ = monotonicNowNs();
  hygiene_ready_.store(true, std::memory_order_release);
}

std::string FrameLoop::hygiene() const {
  return hygiene_ready_.load(std::memory_order_acquire) ? hygiene_ : std::string("(solver thread not started)");
}

bool FrameLoop::spinForFrame(std::int64_t until) noexcept {
  // Read the working set once, a byte per cache line (the sum is kept so the reads are not dropped),
  // then poll.
  std::array<std::span<const std::byte>, 64> working_set{};
  const std::size_t ranges = std::min(live_.frameWorkingSet(working_set), working_set.size());
  std::uint64_t sum = 0;
  for (std::size_t r = 0; r < ranges; ++r) {
    const std::span<const std::byte> range = working_set[r];
    for (std::size_t chunk = 0; chunk < range.size(); chunk += kWarmChunkBytes) {
      // A yield between chunks and in the polling below: the producer (the driver thread) may share this
      // core, and polling with a pause instead starved it (frames came after the polling ended).
      sched_yield();
      if (mailbox_.hasPending() || stop_.load(std::memory_order_relaxed)) {
        working_set_sum_ += sum;
        return mailbox_.hasPending();
      }
      const std::size_t end = std::min(range.size(), chunk + kWarmChunkBytes);
      for (std::size_t i = chunk; i < end; i += 64) sum += static_cast<std::uint64_t>(range[i]);
    }
  }
  working_set_sum_ += sum;
  while (!mailbox_.hasPending() && !stop_.load(std::memory_order_relaxed) && monotonicNowNs() < until) sched_yield();
  return mailbox_.hasPending();
}

void FrameLoop::run() noexcept {
  try {
    applyHygiene();
  } catch (...) {
    // Only the report string can throw (allocation); the loop runs without it.
    start_ns_ = monotonicNowNs();
    hygiene_ready_.store(true, std::memory_order_release);
  }
  std::array<std::int64_t, kRecentWindow> recent{};
  std::array<std::int64_t, kRecentWindow> sorted{};
  int recent_count = 0;
  std::int64_t pose_estimate_ns = 0;  // recent pose-transfer cost, reserved out of the step's deadline
  std::int64_t last_frame_ns = monotonicNowNs();
  std::int64_t last_heartbeat_ns = last_frame_ns;
  // When the next frame is due: the last frame's receive time plus the frames' recent period (an
  // exponential average over about 8 intervals, each under kMaxSleepNs); 0 until two frames have come.
  std::int64_t last_receive_ns = 0, period_ns = 0;
  bool spun = false;  // the solver was polling when the pending frame came

  while (!stop_.load(std::memory_order_acquire)) {
    const MarkerFrame* frame = mailbox_.tryAcquireLatest();
    if (frame == nullptr) {
      const std::int64_t now = monotonicNowNs();
      if (!stale_.load(std::memory_order_relaxed) && now - last_frame_ns > options_.stale_after_ns) {
        stale_.store(true, std::memory_order_relaxed);
        stale_periods_.fetch_add(1, std::memory_order_relaxed);
        publisher_.heartbeat(ShmState::stale_source);
        last_heartbeat_ns = now;
      } else if (now - last_heartbeat_ns > kHeartbeatNs) {
        publisher_.heartbeat(stale_.load(std::memory_order_relaxed) ? ShmState::stale_source : ShmState::running);
        last_heartbeat_ns = now;
      }
      std::int64_t sleep_ns = std::min(kMaxSleepNs, kHeartbeatNs - (now - last_heartbeat_ns));
      if (!stale_.load(std::memory_order_relaxed))
        sleep_ns = std::min(sleep_ns, options_.stale_after_ns - (now - last_frame_ns) + 1);
      sleep_ns = std::max<std::int64_t>(sleep_ns, 1'000'000);
      // Not under SCHED_FIFO: a real-time thread polling would keep the driver thread off a shared core.
      const std::int64_t spin_ns = options_.realtime_fifo ? 0 : options_.spin_before_frame_ns;
      if (spin_ns > 0 && period_ns > 0) {
        // A frame that is later than due by more than kSpinGraceNs is waited for asleep.
        const std::int64_t due = last_receive_ns + period_ns;
        if (now >= due - spin_ns && now < due + kSpinGraceNs) {
          spun = spinForFrame(due + kSpinGraceNs);
          continue;
        }
        if (now < due - spin_ns) sleep_ns = std::min(sleep_ns, due - spin_ns - now);
      }
      mailbox_.waitForFrame(sleep_ns);
      continue;
    }
    const std::int64_t taken_ns = monotonicNowNs();
    last_frame_ns = taken_ns;
    if (spun) frames_spun_for_.fetch_add(1, std::memory_order_relaxed);
    spun = false;
    if (stale_.exchange(false, std::memory_order_relaxed)) publisher_.heartbeat(ShmState::running);
    const std::int64_t receive_ns = frame->receive_timestamp_ns != 0 ? frame->receive_timestamp_ns : taken_ns;
    if (last_receive_ns != 0 && receive_ns > last_receive_ns && receive_ns - last_receive_ns < kMaxSleepNs) {
      const std::int64_t d = receive_ns - last_receive_ns;
      period_ns = period_ns == 0 ? d : (7 * period_ns + d) / 8;
    }
    last_receive_ns = receive_ns;

    StepBudget budget;
    budget.max_iterations = options_.max_iterations;
    const std::int64_t frame_deadline = options_.budget_ns > 0 ? receive_ns + options_.budget_ns : 0;
    if (frame_deadline != 0) budget.deadline = steadyAt(frame_deadline - pose_estimate_ns);

    const LiveFrameStats stats = live_.processFrame(*frame, budget, publisher_.beginPositions(), publisher_.beginNormals());
    const std::int64_t pose_done_ns = monotonicNowNs();
    const std::int64_t step_done_ns = pose_done_ns - stats.pose_transfer_ns;
    if (float* marker_positions = publisher_.beginMarkerPositions())
      stageMarkers(live_, marker_positions, publisher_.beginMarkerStates(), static_cast<std::size_t>(publisher_.markerCount()));

    ShmFrameInfo info;
    info.source_frame = frame->frame_counter;
    info.iterations = stats.step.iterations;
    info.occluded_markers = stats.occluded_markers;
    info.device_ns = frame->device_timestamp_ns;
    info.receive_ns = receive_ns;
    info.taken_ns = taken_ns;
    info.step_done_ns = step_done_ns;
    info.pose_done_ns = pose_done_ns;
    info.flags = 0;
    if (stats.flags & kLivePoseHeld) info.flags |= kShmFramePoseHeld;
    if (stats.occluded_markers != 0) info.flags |= kShmFrameMarkersPredicted;
    if (stats.flags & kLiveTargetsRejected) info.flags |= kShmFrameInputRejected;
    if (stats.flags & kLivePoseRejected) info.flags |= kShmFramePoseRejected;
    // The budget is judged once, as the frame is handed to the segment: its flag, the counter and
    // the frame log all take this one answer.
    const bool miss = frameBudgetMissed(frame_deadline, monotonicNowNs());
    if (miss) info.flags |= kShmFrameBudgetMiss;
    publisher_.commit(info);
    const std::int64_t published_ns = monotonicNowNs();
    // What the next frame needs from this one (the volume constraint's linearization, iterations
    // after publishing), now that the consumers have the pose: off the receive -> published path.
    // The iterations stop at this frame's deadline, before the next frame is due.
    const std::int64_t prepare_ns =
        live_.prepareNextFrame(frame_deadline != 0 ? steadyAt(frame_deadline) : std::chrono::steady_clock::time_point::max());

    // Counters (solver thread only; no allocation).
    pose_estimate_ns = pose_estimate_ns == 0 ? stats.pose_transfer_ns
                                             : std::max(stats.pose_transfer_ns, (7 * pose_estimate_ns + stats.pose_transfer_ns) / 8);
    if (stats.flags & kLiveDeadlineHit) deadline_hits_.fetch_add(1, std::memory_order_relaxed);
    if (stats.flags & kLivePoseHeld) held_frames_.fetch_add(1, std::memory_order_relaxed);
    if (stats.flags & kLiveTargetsRejected) rejected_target_frames_.fetch_add(1, std::memory_order_relaxed);
    if (stats.flags & kLivePoseRejected) rejected_poses_.fetch_add(1, std::memory_order_relaxed);
    occluded_marker_frames_.fetch_add(stats.occluded_markers, std::memory_order_relaxed);
    rejected_marker_samples_.fetch_add(stats.rejected_marker_samples, std::memory_order_relaxed);
    unknown_marker_frames_.fetch_add(stats.unknown_markers, std::memory_order_relaxed);
    iterations_.fetch_add(static_cast<std::uint64_t>(std::max(0, stats.step.iterations)), std::memory_order_relaxed);
    const std::uint64_t done = frames_.fetch_add(1, std::memory_order_relaxed) + 1;
    // Latencies and budget misses. A frame received before start() waited for the set-up (rig,
    // binding, segment), not for the live path: it is counted apart.
    if (receive_ns < start_ns_) {
      frames_before_start_.fetch_add(1, std::memory_order_relaxed);
    } else {
      const std::int64_t total = published_ns - receive_ns;
      const std::int64_t step_ns = stats.flags & kLivePoseHeld ? 0 : stats.step.total_ns;
      latency_.receive_to_taken.record(taken_ns - receive_ns);
      latency_.step.record(step_ns);
      latency_.pose_transfer.record(stats.pose_transfer_ns);
      latency_.receive_to_step_done.record(step_done_ns - receive_ns);
      latency_.receive_to_pose_done.record(pose_done_ns - receive_ns);
      latency_.receive_to_published.record(total);
      latency_.overhead.record(total - step_ns - stats.pose_transfer_ns);
      if (prepare_ns > 0) latency_.prepare_next.record(prepare_ns);
      if (miss) budget_misses_.fetch_add(1, std::memory_order_relaxed);
      last_latency_ns_.store(total, std::memory_order_relaxed);
      recent[static_cast<std::size_t>(recent_count % kRecentWindow)] = total;
      ++recent_count;
      if (recent_count % 16 == 0) {
        const int n = std::min(recent_count, kRecentWindow);
        std::copy_n(recent.begin(), n, sorted.begin());
        std::sort(sorted.begin(), sorted.begin() + n);
        recent_p50_ns_.store(sorted[static_cast<std::size_t>((n - 1) / 2)], std::memory_order_relaxed);
        recent_p99_ns_.store(sorted[static_cast<std::size_t>(((n - 1) * 99) / 100)], std::memory_order_relaxed);
      }
    }
    // The frame log: plain stores into storage sized at construction.
    if (frame_log_count_ < frame_log_.size()) {
      FrameLogEntry& e = frame_log_[frame_log_count_];
      e.frame_id = done;
      e.source_frame = frame->frame_counter;
      e.device_ns = frame->device_timestamp_ns;
      e.receive_ns = receive_ns;
      e.taken_ns = taken_ns;
      e.step_done_ns = step_done_ns;
      e.pose_done_ns = pose_done_ns;
      e.published_ns = published_ns;
      e.step_ns = stats.flags & kLivePoseHeld ? 0 : stats.step.total_ns;
      e.pose_transfer_ns = stats.pose_transfer_ns;
      e.iterations = stats.step.iterations;
      e.occluded_markers = stats.occluded_markers;
      e.flags = static_cast<std::uint16_t>((receive_ns < start_ns_ ? kFrameLogBeforeStart : 0) |
                                           (miss ? kFrameLogBudgetMiss : 0) |
                                           (stats.flags & kLivePoseHeld ? kFrameLogPoseHeld : 0));
      const int kept = std::min(static_cast<int>(frame->marker_count), options_.frame_log_markers);
      FrameLogMarker* out = frame_log_markers_.data() + frame_log_count_ * static_cast<std::size_t>(options_.frame_log_markers);
      for (int m = 0; m < kept; ++m) {
        const Marker& in = frame->markers[static_cast<std::size_t>(m)];
        out[m].position_mm[0] = in.position_mm[0];
        out[m].position_mm[1] = in.position_mm[1];
        out[m].position_mm[2] = in.position_mm[2];
        out[m].id = in.id;
        out[m].valid = in.valid;
      }
      e.marker_count = static_cast<std::uint32_t>(kept);
      e.positions_crc = 0;
      if (options_.frame_log_positions_crc) {
        const auto* bytes = reinterpret_cast<const std::uint8_t*>(publisher_.beginPositions());
        e.positions_crc = rigCrc32c({bytes, static_cast<std::size_t>(publisher_.vertexCount()) * 3 * sizeof(float)});
      }
      ++frame_log_count_;
    } else {
      ++frame_log_dropped_;
    }
    if (options_.max_frames != 0 && done >= options_.max_frames) break;
  }
  done_.store(true, std::memory_order_release);
}

FrameLoopCounters FrameLoop::counters() const noexcept {
  FrameLoopCounters c;
  c.frames = frames_.load(std::memory_order_relaxed);
  c.budget_misses = budget_misses_.load(std::memory_order_relaxed);
  c.deadline_hits = deadline_hits_.load(std::memory_order_relaxed);
  c.held_frames = held_frames_.load(std::memory_order_relaxed);
  c.rejected_target_frames = rejected_target_frames_.load(std::memory_order_relaxed);
  c.rejected_poses = rejected_poses_.load(std::memory_order_relaxed);
  c.occluded_marker_frames = occluded_marker_frames_.load(std::memory_order_relaxed);
  c.rejected_marker_samples = rejected_marker_samples_.load(std::memory_order_relaxed);
  c.unknown_marker_frames = unknown_marker_frames_.load(std::memory_order_relaxed);
  c.stale_periods = stale_periods_.load(std::memory_order_relaxed);
  c.iterations = iterations_.load(std::memory_order_relaxed);
  c.mailbox_dropped = mailbox_.dropped() - mailbox_dropped_at_start_;
  c.frames_spun_for = frames_spun_for_.load(std::memory_order_relaxed);
  c.frames_before_start = frames_before_start_.load(std::memory_order_relaxed);
  return c;
}

FrameLoopSnapshot FrameLoop::snapshot() const noexcept {
  FrameLoopSnapshot s;
  s.counters = counters();
  s.last_receive_to_published_ns = last_latency_ns_.load(std::memory_order_relaxed);
  s.recent_p50_ns = recent_p50_ns_.load(std::memory_order_relaxed);
  s.recent_p99_ns = recent_p99_ns_.load(std::memory_order_relaxed);
  s.stale = stale_.load(std::memory_order_relaxed);
  s.running = started_.load(std::memory_order_relaxed) && !done_.load(std::memory_order_acquire);
  return s;
}

}  // namespace tetrig
