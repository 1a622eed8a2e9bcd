// The solver thread of the live path (DESIGN.md 6a):
//
//   driver thread --publish--> FrameMailbox --waitForFrame/tryAcquireLatest--> solver thread:
//       LiveRig::processFrame (marker targets -> Deformer::step(budget) -> pose transfer straight
//       into the shared-memory slot) -> ShmPublisher::commit -> engine(s)
//
// The solver sleeps until a frame arrives (futex), except for the last stretch before the next frame
// is due (spin_before_frame_ns; due = the last frame's receive time + the frames' recent period):
// there it reads the frame's working set once (LiveRig::frameWorkingSet: the factor, the tet blocks,
// the pose transfer; a shared host evicts them in the 8 ms between frames) and then polls the
// mailbox, so the frame is taken at once and meets warm caches. It always takes the NEWEST frame
// (older unread ones are counted as dropped by the mailbox), and stamps every phase with the
// runtime's clock (tetrig/clock.hpp): receive (by the driver) -> taken -> step done -> pose
// transfer done -> published. The budget of a frame is a deadline at receive + budget_ns; the
// step's own deadline is that minus the pose transfer's recent cost, so the frame as a whole
// meets it; a frame handed to the segment (ShmPublisher::commit) after its deadline is a budget
// miss (frameBudgetMissed: the segment's flag, the counter and the frame log use that one test). When no frame has come for
// stale_after_ns the segment's state says "stale" (the last pose stays published) until frames
// come again.
//
// Real-time hygiene, applied on the solver thread where the system permits and reported
// (FrameLoop::hygiene()) where it does not: flush-to-zero and denormals-are-zero (always), memory locked
// (mlockall), optional CPU pinning and SCHED_FIFO.
//
// The frame log (optional, FrameLoopOptions::frame_log_capacity): one FrameLogEntry per solved
// frame, in order, with every phase's timestamp and, if asked (frame_log_markers), the frame's
// markers as received. Its storage is allocated by the constructor; the solver thread fills it
// with plain stores (no allocation, lock or I/O; frames past the capacity are counted, not kept)
// and it is read after join() (the demo report's latency plot and marker dots: tools/demo_report.hpp).
//
// Threads: construct, start(), requestStop(), join() and the accessors from one control thread;
// snapshot() from any thread. The loop owns nothing: the mailbox, live rig and publisher must
// outlive it, and while it runs only the solver thread touches the live rig and the publisher.
#pragma once

#include "tetrig/frame_mailbox.hpp"
#include "tetrig/latency_histogram.hpp"

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <thread>
#include <vector>

namespace tetrig {

class LiveRig;
class ShmPublisher;

// The solver thread's SCHED_FIFO priority (FrameLoopOptions::realtime_fifo).
inline constexpr int kFrameLoopFifoPriority = 50;

// A frame's budget miss: it was handed to the segment (publish_ns, the runtime's clock) after its
// deadline (receive + budget; 0: no deadline). The one definition: the segment's
// TETRIG_SHM_FRAME_BUDGET_MISS flag, FrameLoopCounters::budget_misses and kFrameLogBudgetMiss.
constexpr bool frameBudgetMissed(std::int64_t deadline_ns, std::int64_t publish_ns) noexcept {
  return deadline_ns != 0 && publish_ns > deadline_ns;
}

struct FrameLoopOptions {
  int max_iterations = 3;                        // per frame (the deadline may stop earlier)
  std::int64_t budget_ns = 4'000'000;            // receive -> published deadline; <= 0: none
  std::int64_t stale_after_ns = 250'000'000;     // no frame for this long: the segment says stale
  std::uint64_t max_frames = 0;                  // stop after this many frames (0: until requestStop)
  bool lock_memory = true;                       // mlockall(MCL_CURRENT | MCL_FUTURE)
  int cpu = -1;                                  // pin the solver thread to this CPU (-1: no)
  bool realtime_fifo = false;                    // SCHED_FIFO (priority kFrameLoopFifoPriority) for the solver thread
  std::size_t frame_log_capacity = 0;            // frames the frame log keeps (0: no log); allocated by the constructor
  int frame_log_markers = 0;                     // markers kept per logged frame (0..kMaxMarkers; the first ones of the frame)
  std::int64_t spin_before_frame_ns = 500'000;   // read the working set and poll for this long before a frame is
                                                 // due (see above; at 120 Hz 6 % of a core, yielding to other threads);
                                                 // 0: sleep until it comes. Off under realtime_fifo
  bool frame_log_positions_crc = false;          // the log also keeps each frame's CRC-32C of its published positions
                                                 // (tests: frames compared across runs; costs a pass over the positions
                                                 // per frame, after publishing)
};

// One solved frame of the frame log. Times are the runtime's clock (tetrig/clock.hpp), ns.
struct FrameLogEntry {
  std::uint64_t frame_id = 0;       // 1, 2, ...: the frame's id in the segment (the n-th frame published)
  std::uint64_t source_frame = 0;   // the source's frame counter
  std::int64_t device_ns = 0;       // the source's device timestamp (0 if unknown)
  std::int64_t receive_ns = 0, taken_ns = 0, step_done_ns = 0, pose_done_ns = 0, published_ns = 0;
  std::int64_t step_ns = 0;         // Deformer::step's own time (0 when the pose was held)
  std::int64_t pose_transfer_ns = 0;
  std::int32_t iterations = 0;
  std::uint16_t occluded_markers = 0;
  std::uint16_t flags = 0;          // FrameLogFlags
  std::uint32_t marker_count = 0;   // markers kept for this frame (<= frame_log_markers)
  std::uint32_t positions_crc = 0;  // CRC-32C of the published positions (FrameLoopOptions::frame_log_positions_crc; else 0)
};                                  // 96 bytes

enum FrameLogFlags : std::uint16_t {
  kFrameLogBeforeStart = 1u << 0,   // received before the solver was ready: not in the latency histograms
  kFrameLogBudgetMiss = 1u << 1,    // a budget miss (frameBudgetMissed)
  kFrameLogPoseHeld = 1u << 2,      // no rig marker measured: the pose was held
};

// A marker of a logged frame, as the source gave it (device mm, the source's axes).
struct FrameLogMarker {
  float position_mm[3] = {0.0f, 0.0f, 0.0f};
  std::uint16_t id = 0;   // label index in the source's label table
  std::uint8_t valid = 0; // 1: measured this frame
  std::uint8_t pad = 0;
};

// Latency of each phase, per frame (ns).
struct FrameLoopLatency {
  LatencyHistogram receive_to_taken;      // driver receive -> solver took the frame (wake-up + queueing)
  LatencyHistogram step;                  // Deformer::step (targets, iterations)
  LatencyHistogram pose_transfer;         // x_fine = B x_tet (+ normals) into the slot
  LatencyHistogram receive_to_step_done;
  LatencyHistogram receive_to_pose_done;
  LatencyHistogram receive_to_published;  // the whole live path on this machine
  LatencyHistogram overhead;              // receive_to_published - step - pose_transfer
  LatencyHistogram prepare_next;          // after publishing: LiveRig::prepareNextFrame (the volume constraint's
                                          // linearization, iterations after publishing; only frames that had any)
};

struct FrameLoopCounters {
  std::uint64_t frames = 0;                 // frames processed and published
  std::uint64_t budget_misses = 0;          // budget misses (frameBudgetMissed) of frames received after start
  std::uint64_t deadline_hits = 0;          // steps stopped by their deadline before max_iterations
  std::uint64_t held_frames = 0;            // frames with no measured rig marker (pose held)
  std::uint64_t rejected_target_frames = 0; // frames whose marker targets the deformer rejected (kept the last ones)
  std::uint64_t rejected_poses = 0;         // frames whose solved pose was non-finite or implausible (last pose
                                            // republished, deformer reset; should never happen)
  std::uint64_t occluded_marker_frames = 0; // sum over frames of the rig markers driven by prediction
  std::uint64_t rejected_marker_samples = 0; // sum over frames of the marker samples rejected as non-finite, absurd or
                                             // implausible (LiveFrameStats::rejected_marker_samples; predicted instead)
  std::uint64_t unknown_marker_frames = 0;  // sum over frames of markers whose id the rig does not know
  std::uint64_t stale_periods = 0;          // times the source went stale
  std::uint64_t iterations = 0;             // sum of iterations run
  std::uint64_t mailbox_dropped = 0;        // frames overwritten in the mailbox before the solver took them
  std::uint64_t frames_spun_for = 0;        // frames the solver was polling for when they came (spin_before_frame_ns)
  std::uint64_t frames_before_start = 0;    // frames received before the solver was ready (rig, segment, mlockall
                                            // up): solved and published, but kept out of the latency histograms
                                            // and budget misses (their wait is start-up, not the live path)
};

// What the status line shows (any thread; relaxed, not one consistent snapshot).
struct FrameLoopSnapshot {
  FrameLoopCounters counters;
  std::int64_t last_receive_to_published_ns = 0;
  std::int64_t recent_p50_ns = 0, recent_p99_ns = 0;  // receive -> published over the last ~second of frames
  bool stale = false;
  bool running = false;
};

class FrameLoop {
 public:
  // Throws std::invalid_argument when the segment carries a marker block (layout 1.1) whose
  // label count is not the rig's marker count (the block is filled in rig.markers order).
  FrameLoop(FrameMailbox& mailbox, LiveRig& live_rig, ShmPublisher& publisher, const FrameLoopOptions& options);
  ~FrameLoop();  // requestStop() + join()
  FrameLoop(const FrameLoop&) = delete;
  FrameLoop& operator=(const FrameLoop&) = delete;

  void start();           // spawns the solver thread and returns when it is ready for frames; allocates
  void requestStop() noexcept;
  void join();
  [[nodiscard]] bool finished() const noexcept { return done_.load(std::memory_order_acquire); }

  [[nodiscard]] FrameLoopSnapshot snapshot() const noexcept;
  // After join(): the per-phase histograms and counters of the whole run.
  [[nodiscard]] const FrameLoopLatency& latency() const noexcept { return latency_; }
  [[nodiscard]] FrameLoopCounters counters() const noexcept;
  // After the solver thread started: what the real-time hygiene managed ("flush-to-zero on; memory
  // locked; pinned to CPU 1; SCHED_FIFO refused: Operation not permitted").
  [[nodiscard]] std::string hygiene() const;
  // After join(): the frame log, one entry per solved frame in order (at most frame_log_capacity;
  // the frames that did not fit are frameLogDropped()), and the markers kept for entry `index`.
  [[nodiscard]] std::span<const FrameLogEntry> frameLog() const noexcept { return {frame_log_.data(), frame_log_count_}; }
  [[nodiscard]] std::span<const FrameLogMarker> frameLogMarkers(std::size_t index) const noexcept;
  [[nodiscard]] std::uint64_t frameLogDropped() const noexcept { return frame_log_dropped_; }

 private:
  void run() noexcept;
  void applyHygiene();
  // The last stretch before a frame is due: reads the live rig's working set (stopping as soon as a
  // frame is pending), then polls the mailbox until a frame is pending, `until` or a stop request.
  // Returns true when a frame is pending.
  bool spinForFrame(std::int64_t until) noexcept;

  FrameMailbox& mailbox_;
  LiveRig& live_;
  ShmPublisher& publisher_;
  FrameLoopOptions options_;
  FrameLoopLatency latency_;
  std::thread thread_;
  std::atomic<bool> stop_{false}, done_{false}, started_{false}, stale_{false};
  std::atomic<bool> hygiene_ready_{false};
  std::string hygiene_;  // written by the solver thread before hygiene_ready_
  // Live counters (solver thread writes, others read relaxed).
  std::atomic<std::uint64_t> frames_{0}, budget_misses_{0}, deadline_hits_{0}, held_frames_{0},
      rejected_target_frames_{0}, rejected_poses_{0}, occluded_marker_frames_{0}, rejected_marker_samples_{0}, unknown_marker_frames_{0},
      stale_periods_{0}, iterations_{0}, frames_spun_for_{0}, frames_before_start_{0};
  std::uint64_t working_set_sum_ = 0;  // what spinForFrame's reading summed (kept, so the reads stay)
  std::atomic<std::int64_t> last_latency_ns_{0}, recent_p50_ns_{0}, recent_p99_ns_{0};
  std::uint64_t mailbox_dropped_at_start_ = 0;
  std::int64_t start_ns_ = 0;  // when the solver thread was ready (written before hygiene_ready_)
  // The frame log (sized by the constructor; the solver thread writes, read after join()).
  std::vector<FrameLogEntry> frame_log_;
  std::vector<FrameLogMarker> frame_log_markers_;  // frame_log_capacity * frame_log_markers
  std::size_t frame_log_count_ = 0;
  std::uint64_t frame_log_dropped_ = 0;
};

}  // namespace tetrig
