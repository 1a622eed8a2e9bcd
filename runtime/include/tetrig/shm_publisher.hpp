// Shared-memory publisher: the writer of the tetrig shared-memory segment (runtime -> engine).
//
// The layout, the reader protocol and the failure cases are in docs/shm.md; the C99 reader is
// runtime/include/tetrig_shm.h (the layout structs live there, one definition for both sides).
// The segment holds a header, static data written once before the segment becomes visible
// (triangles, rest positions, rig name, marker labels) and N >= 3 slots written round-robin, each
// under a seqlock sequence word, with the newest complete frame id in the header. Readers never
// block the writer, the writer never waits, and a reader never returns a torn frame.
//
// Lifetime: the constructor (load time) creates the segment (0600 unless widened) and replaces a
// segment of the same name left by a crashed or stopped producer; it refuses the name while its
// producer is alive and running. The destructor marks the segment stopped and unlinks the name.
//
// Threads: the constructor and destructor run on any one thread (load / shutdown). The frame path
// (beginPositions, beginNormals, commit, heartbeat) belongs to ONE producer thread (the solver
// thread); it does no heap allocation, no lock, no system call (the monotonic clock is a vDSO
// read) and throws nothing. The accessors may be called from any thread.
//
// In-process followers (the DDS bridge, tetrig::dds::SegmentBridge) sleep in waitForCommit()
// instead of polling: commit() bumps an event count and makes the futex wake call only while a
// follower has announced that it sleeps (the pattern of FrameMailbox::commit/waitForFrame), so
// the frame path stays allocation-free and lock-free and pays one atomic add per frame.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>

#include "tetrig/aligned_vector.hpp"

struct TetrigShmHeader;  // tetrig_shm.h

namespace tetrig {

// Producer state in the header (TETRIG_SHM_STATE_* in tetrig_shm.h).
enum class ShmState : std::uint32_t {
  running = 1,       // frames arrive from the source
  stale_source = 2,  // alive, but the source sends nothing: the pose is held
  stopped = 3,       // clean shutdown (the destructor sets it)
};

// ShmFrameInfo::flags bits (TETRIG_SHM_FRAME_* in tetrig_shm.h).
inline constexpr std::uint32_t kShmFrameStaleSource = 0x1u;       // reserved (a silent source publishes no frame)
inline constexpr std::uint32_t kShmFramePoseHeld = 0x2u;          // every marker occluded: pose held
inline constexpr std::uint32_t kShmFrameBudgetMiss = 0x4u;        // iteration deadline hit
inline constexpr std::uint32_t kShmFrameMarkersPredicted = 0x8u;  // some targets predicted
inline constexpr std::uint32_t kShmFrameInputRejected = 0x10u;    // non-finite/absurd input rejected
inline constexpr std::uint32_t kShmFramePoseRejected = 0x20u;     // solved pose implausible: last pose republished

// Marker state bytes of the marker block (TETRIG_SHM_MARKER_* in tetrig_shm.h; layout 1.1).
inline constexpr std::uint8_t kShmMarkerUnknown = 0;    // no (finite) target
inline constexpr std::uint8_t kShmMarkerMeasured = 1;   // the measurement itself
inline constexpr std::uint8_t kShmMarkerPredicted = 2;  // no measurement: predicted (occluded)
inline constexpr std::uint8_t kShmMarkerBlended = 3;    // measured again, blending back from the prediction
inline constexpr std::uint8_t kShmMarkerRejected = 4;   // its sample was rejected as implausible: predicted instead

struct ShmPublisherOptions {
  std::string name;              // "/name": a leading '/', no other '/', at most 255 bytes
  int slot_count = 4;            // 3..64 dynamic slots (more slots: a slow reader is lapped later)
  bool normals = false;          // publish per-vertex normals beside the positions
  bool marker_positions = true;  // layout 1.1: per slot, each labelled marker's target and state
                                 // (12 + 1 bytes per marker; no block when there are no labels)
  unsigned permissions = 0600;   // mode of the segment (set exactly, umask ignored): owner read/write, plus
                                 // read for group/others at most (0640, 0644); write bits for them are
                                 // refused (readers refuse such segments: docs/shm.md)
};

// Static data, copied into the segment once by the constructor (the spans need not outlive it).
struct ShmStaticData {
  std::span<const std::int32_t> triangles;   // #F x 3 vertex indices in [0, vertex_count)
  std::span<const float> rest_positions;     // vertex_count x 3, rig units
  std::string_view rig_name;                 // UTF-8, no NUL inside
  std::span<const std::string> marker_labels;  // optional; no NUL inside a label
};

// What the caller knows about a frame; commit() adds the frame id and publish_ns. Times are
// CLOCK_MONOTONIC nanoseconds (tetrig::monotonicNowNs) except device_ns (device clock); 0 = unknown.
struct ShmFrameInfo {
  std::uint64_t source_frame = 0;       // the source's frame counter
  std::int32_t iterations = 0;          // solver iterations run
  std::uint32_t flags = 0;              // kShmFrame* bits
  std::uint16_t occluded_markers = 0;   // markers without a measurement
  std::int64_t device_ns = 0;           // capture time on the device's clock
  std::int64_t receive_ns = 0;          // received by the driver thread
  std::int64_t taken_ns = 0;            // taken from the mailbox by the solver
  std::int64_t step_done_ns = 0;        // deformation step done
  std::int64_t pose_done_ns = 0;        // pose transfer done
};

// Thrown by the constructor only, with one line naming the segment and the cause.
class ShmError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

class ShmPublisher {
 public:
  // Load time: validates the options and data, creates the segment `options.name` holding
  // `vertex_count` vertices (> 0), writes the static data, pre-faults every page, and only then
  // stores the magic (release) so no reader maps half-written data. An existing segment of that
  // name is replaced when its producer is dead (pid gone or a zombie) or stopped, or when it was
  // left half-created by a dead process; it is refused (ShmError naming the pid) while its
  // producer is alive and not stopped, and refused when it is not a tetrig segment.
  // Allocates (staging buffers of vertex_count x 3 floats) and throws ShmError.
  ShmPublisher(const ShmPublisherOptions& options, std::int32_t vertex_count, const ShmStaticData& data);
  // Marks the segment stopped, unmaps it and unlinks the name (only if the name still refers to
  // this segment). Never throws.
  ~ShmPublisher();
  ShmPublisher(const ShmPublisher&) = delete;
  ShmPublisher& operator=(const ShmPublisher&) = delete;

  // ---- frame path: the producer thread only; no allocation, lock, system call or exception ----

  // The producer's private buffer for the next frame's positions: vertex_count x 3 floats,
  // 64-byte aligned, holding the previous frame's values until overwritten. commit() copies it
  // into the next slot (the slot itself is written only inside commit, so the window in which a
  // reader can find it odd is the copy, a few microseconds).
  [[nodiscard]] float* beginPositions() noexcept { return staging_positions_.data(); }
  // The same for normals (vertex_count x 3 floats); nullptr when options.normals was false.
  [[nodiscard]] float* beginNormals() noexcept { return normals_ ? staging_normals_.data() : nullptr; }
  // The same for the marker block (layout 1.1): markerCount() x 3 floats (rig units, label order)
  // and markerCount() state bytes (TETRIG_SHM_MARKER_*: 0 unknown, 1 measured, 2 predicted,
  // 3 blended); nullptr without the block (no labels, or options.marker_positions false). They
  // start as zeros (state unknown) and keep their values until overwritten.
  [[nodiscard]] float* beginMarkerPositions() noexcept { return markers_ ? staging_marker_positions_.data() : nullptr; }
  [[nodiscard]] std::uint8_t* beginMarkerStates() noexcept { return markers_ ? staging_marker_states_.data() : nullptr; }
  // Publishes the staged positions (and normals) with `info` into the next slot round-robin
  // (sequence odd, relaxed word stores, sequence even with release), stamps publish_ns and the
  // heartbeat, sets the state to running and makes the frame the newest (release). Returns its
  // frame id (1, 2, 3, ...). Cost: one copy of the staged arrays.
  std::uint64_t commit(const ShmFrameInfo& info) noexcept;
  // Refreshes the heartbeat and sets `state` while no frame is committed (e.g. every 100 ms with
  // ShmState::stale_source when the source is silent). Readers call a producer whose heartbeat
  // is older than their limit (about 1 s) stale.
  void heartbeat(ShmState state) noexcept;

  // ---- any thread ----
  [[nodiscard]] const std::string& name() const noexcept { return name_; }
  [[nodiscard]] std::uint64_t instanceId() const noexcept { return instance_id_; }
  [[nodiscard]] std::int32_t vertexCount() const noexcept { return vertex_count_; }
  [[nodiscard]] int slotCount() const noexcept { return slot_count_; }
  [[nodiscard]] bool hasNormals() const noexcept { return normals_; }
  [[nodiscard]] std::int32_t markerCount() const noexcept { return marker_count_; }  // labels
  [[nodiscard]] bool hasMarkerPositions() const noexcept { return markers_; }
  // Frames committed so far (= the newest frame id). Producer thread, or after it has stopped.
  [[nodiscard]] std::uint64_t framesPublished() const noexcept { return next_frame_id_ - 1; }
  // The producer's own mapping (read-write) and its size in bytes, e.g. for tetrig_shm_attach()
  // in tests and in-process readers. Valid until destruction.
  [[nodiscard]] const void* segmentData() const noexcept { return base_; }
  [[nodiscard]] std::size_t segmentSize() const noexcept { return size_; }
  // The newest committed frame id (0 = none yet), read from the segment's header (acquire).
  [[nodiscard]] std::uint64_t latestFrameId() const noexcept;
  // Sleeps until a frame newer than `after_frame_id` is committed, wakeCommitWaiters() is called,
  // or `timeout_ns` passes (no busy wait; spurious returns are possible). Returns whether a newer
  // frame exists. Any number of threads other than the producer may wait at once.
  bool waitForCommit(std::uint64_t after_frame_id, std::int64_t timeout_ns) const noexcept;
  // Wakes every thread sleeping in waitForCommit() (e.g. so that it sees a stop request).
  void wakeCommitWaiters() const noexcept;

 private:
  void writeStatic(const ShmStaticData& data);

  std::string name_;
  std::int32_t vertex_count_ = 0;
  int slot_count_ = 0;
  bool normals_ = false;
  std::uint64_t instance_id_ = 0;
  unsigned char* base_ = nullptr;  // the mapping (size_ bytes)
  std::size_t size_ = 0;
  TetrigShmHeader* header_ = nullptr;
  unsigned char* slots_ = nullptr;
  std::size_t slot_stride_ = 0;
  std::size_t slot_positions_offset_ = 0;
  std::size_t slot_normals_offset_ = 0;
  std::size_t array_bytes_ = 0;  // vertex_count x 12, rounded up to 8 (the copy's word count)
  std::int32_t marker_count_ = 0;
  bool markers_ = false;  // the slots carry the marker block
  std::size_t slot_marker_positions_offset_ = 0;
  std::size_t slot_marker_states_offset_ = 0;
  std::size_t marker_position_bytes_ = 0;  // marker_count x 12, rounded up to 8
  std::size_t marker_state_bytes_ = 0;     // marker_count, rounded up to 8
  std::uint64_t file_device_ = 0;
  std::uint64_t file_inode_ = 0;
  std::uint64_t next_frame_id_ = 1;
  std::uint32_t state_ = 0;  // last state stored (producer thread)
  AlignedVector<float> staging_positions_;
  AlignedVector<float> staging_normals_;
  AlignedVector<float> staging_marker_positions_;
  AlignedVector<std::uint8_t> staging_marker_states_;
  // Event count for waitForCommit(): bumped by commit(); commit_sleepers_ counts announced sleepers.
  mutable std::atomic<std::uint32_t> commit_word_{0};
  mutable std::atomic<std::uint32_t> commit_sleepers_{0};
};

}  // namespace tetrig
