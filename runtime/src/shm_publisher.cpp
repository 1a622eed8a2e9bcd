// Shared-memory publisher (tetrig/shm_publisher.hpp): the writer side of the tetrig segment,
// layout version 1.1 (runtime/include/tetrig_shm.h, docs/shm.md). Implements a seqlock writer
// (Lamport 1977; the fence form for the C/C++ memory model from Boehm, "Can seqlocks get along
// with programming language memory models?", 2012) over N >= 3 round-robin slots: sequence odd
// (relaxed), release fence, relaxed word stores of the payload, sequence even (release), newest
// frame id (release). Creation is "magic last": everything is written before the magic's release
// store, so a reader that sees the magic sees the whole static data.
#include "tetrig/shm_publisher.hpp"

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/random.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <limits>
#include <thread>

#include "futex.hpp"
#include "tetrig/clock.hpp"
#include "tetrig_shm.h"

namespace tetrig {

static_assert(static_cast<std::uint32_t>(ShmState::running) == TETRIG_SHM_STATE_RUNNING);
static_assert(static_cast<std::uint32_t>(ShmState::stale_source) == TETRIG_SHM_STATE_STALE_SOURCE);
static_assert(static_cast<std::uint32_t>(ShmState::stopped) == TETRIG_SHM_STATE_STOPPED);
static_assert(kShmFrameStaleSource == TETRIG_SHM_FRAME_STALE_SOURCE);
static_assert(kShmFramePoseHeld == TETRIG_SHM_FRAME_POSE_HELD);
static_assert(kShmFrameBudgetMiss == TETRIG_SHM_FRAME_BUDGET_MISS);
static_assert(kShmFrameMarkersPredicted == TETRIG_SHM_FRAME_MARKERS_PREDICTED);
static_assert(kShmFrameInputRejected == TETRIG_SHM_FRAME_INPUT_REJECTED);
static_assert(kShmFramePoseRejected == TETRIG_SHM_FRAME_POSE_REJECTED);
static_assert(kShmMarkerUnknown == TETRIG_SHM_MARKER_UNKNOWN);
static_assert(kShmMarkerMeasured == TETRIG_SHM_MARKER_MEASURED);
static_assert(kShmMarkerPredicted == TETRIG_SHM_MARKER_PREDICTED);
static_assert(kShmMarkerBlended == TETRIG_SHM_MARKER_BLENDED);
static_assert(kShmMarkerRejected == TETRIG_SHM_MARKER_REJECTED);

namespace {

constexpr std::uint64_t kAlign = TETRIG_SHM_ALIGNMENT;
// How long a segment that is still being created (size 0, or no pid yet) may stay so before it
// counts as abandoned by a process that died while creating it.
constexpr auto kCreationGrace = std::chrono::milliseconds(200);

std::uint64_t alignUp(std::uint64_t bytes) { return (bytes + kAlign - 1) / kAlign * kAlign; }

template <class T>
std::atomic_ref<T> atomicAt(T& word) {
  return std::atomic_ref<T>(word);
}

// Relaxed atomic 8-byte stores of `bytes` (a multiple of 8) from private memory into the segment.
void storeWords(unsigned char* dst, const void* src, std::size_t bytes) noexcept {
  auto* d = reinterpret_cast<std::uint64_t*>(dst);
  const auto* s = static_cast<const unsigned char*>(src);
  const std::size_t n = bytes / 8;
  for (std::size_t i = 0; i < n; ++i) {
    std::uint64_t w;
    std::memcpy(&w, s + 8 * i, 8);
    std::atomic_ref<std::uint64_t>(d[i]).store(w, std::memory_order_relaxed);
  }
}

std::string errnoText(int err) { return std::string(std::strerror(err)); }

const char* stateName(std::uint32_t state) {
  switch (state) {
    case TETRIG_SHM_STATE_RUNNING: return "running";
    case TETRIG_SHM_STATE_STALE_SOURCE: return "stale source";
    case TETRIG_SHM_STATE_STOPPED: return "stopped";
    default: return "starting";
  }
}

std::uint64_t randomInstanceId(std::int64_t now_ns) {
  std::uint64_t id = 0;
  if (getrandom(&id, sizeof id, 0) != static_cast<ssize_t>(sizeof id)) {
    // No entropy source: mix the clock and the pid (splitmix64 finaliser).
    id = static_cast<std::uint64_t>(now_ns) ^ (static_cast<std::uint64_t>(getpid()) << 32);
    id ^= id >> 30;
    id *= 0xBF58476D1CE4E5B9ull;
    id ^= id >> 27;
    id *= 0x94D049BB133111EBull;
    id ^= id >> 31;
  }
  return id == 0 ? 1 : id;
}

void validateName(const std::string& name) {
  if (name.size() < 2 || name.front() != '/' || name.find('/', 1) != std::string::npos ||
      name.size() > TETRIG_SHM_NAME_MAX) {
    throw ShmError("shm segment '" + name + "': a name is '/' followed by 1..254 characters without '/'");
  }
  if (name.find('\0') != std::string::npos) throw ShmError("shm segment name contains a NUL byte");
}

// What to do about a segment that already has our name.
enum class Existing { replace, vanished };

// Looks at the segment already under `name`: returns replace when its producer is dead, stopped
// or never finished creating it, vanished when it disappeared meanwhile; throws ShmError when a
// live producer owns it or it is not a tetrig segment.
Existing inspectExisting(const std::string& name) {
  const std::string where = "shm segment '" + name + "'";
  const auto give_up = std::chrono::steady_clock::now() + kCreationGrace;
  for (;;) {
    const int fd = shm_open(name.c_str(), O_RDONLY | O_CLOEXEC, 0);
    if (fd < 0) {
      if (errno == ENOENT) return Existing::vanished;
      throw ShmError(where + " exists but cannot be opened to check its producer: " + errnoText(errno));
    }
    struct stat st{};
    if (fstat(fd, &st) != 0) {
      const int err = errno;
      close(fd);
      throw ShmError(where + ": fstat failed: " + errnoText(err));
    }
    bool incomplete = false;
    if (st.st_size == 0) {
      incomplete = true;  // created, not yet sized: a producer is starting, or died right there
    } else if (st.st_size < static_cast<off_t>(TETRIG_SHM_HEADER_SIZE)) {
      close(fd);
      throw ShmError(where + " exists and is not a tetrig segment (" + std::to_string(st.st_size) +
                     " bytes); remove /dev/shm" + name + " if nothing uses it");
    } else {
      void* map = mmap(nullptr, TETRIG_SHM_HEADER_SIZE, PROT_READ, MAP_SHARED, fd, 0);
      if (map == MAP_FAILED) {
        const int err = errno;
        close(fd);
        throw ShmError(where + ": mmap of the existing header failed: " + errnoText(err));
      }
      const auto* h = static_cast<const TetrigShmHeader*>(map);
      const std::uint64_t magic = __atomic_load_n(&h->magic, __ATOMIC_ACQUIRE);
      const std::int32_t pid = __atomic_load_n(&h->producer_pid, __ATOMIC_RELAXED);
      const std::uint32_t state = __atomic_load_n(&h->state, __ATOMIC_ACQUIRE);
      const std::int64_t heartbeat = __atomic_load_n(&h->heartbeat_ns, __ATOMIC_RELAXED);
      munmap(map, TETRIG_SHM_HEADER_SIZE);
      if (magic != 0 && magic != TETRIG_SHM_MAGIC) {
        close(fd);
        throw ShmError(where + " exists and is not a tetrig segment (bad magic); remove /dev/shm" + name +
                       " if nothing uses it");
      }
      if (pid == 0) {
        incomplete = true;  // sized but the creator has not written its pid yet (or died first)
      } else if (tetrig_shm_pid_alive(pid) != 0) {
        if (magic == 0) {
          close(fd);
          throw ShmError(where + " is being created by another producer (pid " + std::to_string(pid) + ")");
        }
        if (state != TETRIG_SHM_STATE_STOPPED) {
          close(fd);
          const double age_ms = static_cast<double>(monotonicNowNs() - heartbeat) * 1e-6;
          throw ShmError(where + " is in use by a running producer (pid " + std::to_string(pid) + ", state " +
                         stateName(state) + ", heartbeat " + std::to_string(static_cast<long long>(age_ms)) +
                         " ms ago); stop it or choose another name");
        }
      }
    }
    close(fd);
    if (!incomplete || std::chrono::steady_clock::now() >= give_up) return Existing::replace;
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
}

// Unmaps and unlinks a half-made segment when the constructor fails.
struct CreationGuard {
  std::string name;
  void* map = MAP_FAILED;
  std::size_t size = 0;
  int fd = -1;
  bool armed = false;  // set once the name is ours
  ~CreationGuard() {
    if (!armed) return;
    if (map != MAP_FAILED) munmap(map, size);
    if (fd >= 0) close(fd);
    shm_unlink(name.c_str());
  }
};

}  // namespace

ShmPublisher::ShmPublisher(const ShmPublisherOptions& options, std::int32_t vertex_count, const ShmStaticData& data)
    : name_(options.name), vertex_count_(vertex_count), slot_count_(options.slot_count), normals_(options.normals),
      marker_count_(static_cast<std::int32_t>(std::min<std::size_t>(data.marker_labels.size(), 0x10000u))),
      markers_(options.marker_positions && !data.marker_labels.empty()) {
  validateName(name_);
  const std::string where = "shm segment '" + name_ + "'";
  if (vertex_count <= 0) throw ShmError(where + ": vertex count must be positive (got " + std::to_string(vertex_count) + ")");
  if (options.slot_count < static_cast<int>(TETRIG_SHM_MIN_SLOTS) || options.slot_count > static_cast<int>(TETRIG_SHM_MAX_SLOTS)) {
    throw ShmError(where + ": slot count must be 3..64 (got " + std::to_string(options.slot_count) + ")");
  }
  if ((options.permissions & ~0666u) != 0 || (options.permissions & 0600u) != 0600u) {
    throw ShmError(where + ": permissions must include owner read/write and have no bits beyond 0666");
  }
  if ((options.permissions & 0022u) != 0) {  // readers refuse such a segment (tetrig_shm.h: TETRIG_SHM_E_MODE)
    throw ShmError(where + ": permissions must not let group or others write (any such user could rewrite or truncate the "
                           "segment under its readers); use 0600, 0640 or 0644");
  }
  const auto v = static_cast<std::uint64_t>(vertex_count);
  if (data.rest_positions.size() != v * 3) {
    throw ShmError(where + ": rest positions hold " + std::to_string(data.rest_positions.size()) + " floats, expected " +
                   std::to_string(v * 3) + " (vertex count x 3)");
  }
  if (data.triangles.size() % 3 != 0 || data.triangles.size() / 3 > std::numeric_limits<std::uint32_t>::max()) {
    throw ShmError(where + ": triangle index count " + std::to_string(data.triangles.size()) + " is not a multiple of 3");
  }
  for (std::size_t i = 0; i < data.triangles.size(); ++i) {
    if (data.triangles[i] < 0 || static_cast<std::uint64_t>(data.triangles[i]) >= v) {
      throw ShmError(where + ": triangle " + std::to_string(i / 3) + " uses vertex " + std::to_string(data.triangles[i]) +
                     " outside [0, " + std::to_string(v) + ")");
    }
  }
  if (data.rig_name.find('\0') != std::string_view::npos || data.rig_name.size() > 0xFFFFu) {
    throw ShmError(where + ": rig name contains a NUL byte or is longer than 65535 bytes");
  }
  std::uint64_t label_bytes = 0;
  for (const std::string& label : data.marker_labels) {
    if (label.find('\0') != std::string::npos) throw ShmError(where + ": marker label contains a NUL byte");
    label_bytes += label.size() + 1;
  }
  if (data.marker_labels.size() > 0xFFFFu) throw ShmError(where + ": more than 65535 marker labels");

  // ---- layout (offsets from the segment start; every array on a 64-byte boundary) ----
  const std::uint64_t triangle_count = data.triangles.size() / 3;
  std::uint64_t offset = TETRIG_SHM_HEADER_SIZE;
  const std::uint64_t triangles_offset = offset;
  offset += alignUp(triangle_count * 12);
  const std::uint64_t rest_offset = offset;
  offset += alignUp(v * 12);
  const std::uint64_t rig_name_offset = offset;
  offset += alignUp(data.rig_name.size() + 1);
  const std::uint64_t labels_offset = offset;
  offset += alignUp(label_bytes);
  const std::uint64_t slots_offset = offset;
  const std::uint64_t array_region = alignUp(v * 12);
  slot_positions_offset_ = TETRIG_SHM_SLOT_HEADER_SIZE;
  slot_normals_offset_ = normals_ ? TETRIG_SHM_SLOT_HEADER_SIZE + array_region : 0;
  slot_stride_ = TETRIG_SHM_SLOT_HEADER_SIZE + array_region * (normals_ ? 2 : 1);
  // 1.1: the marker block after the arrays (a 1.0 reader follows the offsets and never sees it).
  const auto m = static_cast<std::uint64_t>(data.marker_labels.size());
  if (markers_) {
    slot_marker_positions_offset_ = slot_stride_;
    slot_stride_ += alignUp(m * 12);
    slot_marker_states_offset_ = slot_stride_;
    slot_stride_ += alignUp(m);
    marker_position_bytes_ = (m * 12 + 7) / 8 * 8;
    marker_state_bytes_ = (m + 7) / 8 * 8;
  }
  const std::uint64_t total = slots_offset + slot_stride_ * static_cast<std::uint64_t>(slot_count_);
  if (total > static_cast<std::uint64_t>(std::numeric_limits<off_t>::max())) throw ShmError(where + ": segment too large");
  size_ = total;
  array_bytes_ = (v * 12 + 7) / 8 * 8;

  // Private staging buffers: positions start as the rest pose, normals as zero.
  staging_positions_.assign(array_bytes_ / sizeof(float), 0.0f);
  std::copy(data.rest_positions.begin(), data.rest_positions.end(), staging_positions_.begin());
  if (normals_) staging_normals_.assign(array_bytes_ / sizeof(float), 0.0f);
  if (markers_) {
    staging_marker_positions_.assign(marker_position_bytes_ / sizeof(float), 0.0f);
    staging_marker_states_.assign(marker_state_bytes_, std::uint8_t{TETRIG_SHM_MARKER_UNKNOWN});
  }

  // ---- create (O_EXCL), replacing a dead or stopped producer's segment ----
  CreationGuard guard{name_};
  int fd = -1;
  for (int attempt = 0; attempt < 8 && fd < 0; ++attempt) {
    fd = shm_open(name_.c_str(), O_RDWR | O_CREAT | O_EXCL | O_CLOEXEC, 0600);
    if (fd >= 0) break;
    if (errno != EEXIST) {
      throw ShmError(where + ": shm_open failed: " + errnoText(errno));
    }
    if (inspectExisting(name_) == Existing::replace) shm_unlink(name_.c_str());
  }
  if (fd < 0) throw ShmError(where + ": another process keeps creating this name; giving up");
  guard.armed = true;
  guard.fd = fd;
  // shm_open's mode is filtered by the umask: set the requested mode exactly.
  if (fchmod(fd, static_cast<mode_t>(options.permissions)) != 0) throw ShmError(where + ": fchmod failed: " + errnoText(errno));
  if (ftruncate(fd, static_cast<off_t>(total)) != 0) {
    throw ShmError(where + ": cannot size the segment to " + std::to_string(total) + " bytes: " + errnoText(errno));
  }
  void* map = mmap(nullptr, size_, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
  if (map == MAP_FAILED) throw ShmError(where + ": mmap of " + std::to_string(total) + " bytes failed: " + errnoText(errno));
  guard.map = map;
  guard.size = size_;
  struct stat st{};
  if (fstat(fd, &st) != 0) throw ShmError(where + ": fstat failed: " + errnoText(errno));
  file_device_ = static_cast<std::uint64_t>(st.st_dev);
  file_inode_ = static_cast<std::uint64_t>(st.st_ino);
  close(fd);
  guard.fd = -1;

  base_ = static_cast<unsigned char*>(map);
  header_ = static_cast<TetrigShmHeader*>(map);
  slots_ = base_ + slots_offset;
  // Our pid first: from here on a producer starting under the same name sees who is creating.
  atomicAt(header_->producer_pid).store(static_cast<std::int32_t>(getpid()), std::memory_order_relaxed);
  // Touch every page now (tmpfs allocates on first write), so commit() never page-faults.
  std::memset(base_ + TETRIG_SHM_HEADER_SIZE, 0, size_ - TETRIG_SHM_HEADER_SIZE);

  const std::int64_t now_ns = monotonicNowNs();
  instance_id_ = randomInstanceId(now_ns);
  TetrigShmHeader& h = *header_;
  h.version_major = TETRIG_SHM_VERSION_MAJOR;
  h.version_minor = TETRIG_SHM_VERSION_MINOR;
  h.header_size = TETRIG_SHM_HEADER_SIZE;
  h.total_size = total;
  h.instance_id = instance_id_;
  h.start_unix_ns = static_cast<std::int64_t>(
      std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch()).count());
  h.start_monotonic_ns = now_ns;
  h.flags = (normals_ ? TETRIG_SHM_HAS_NORMALS : 0u) | (markers_ ? TETRIG_SHM_HAS_MARKER_POSITIONS : 0u);
  h.vertex_count = static_cast<std::uint32_t>(vertex_count);
  h.triangle_count = static_cast<std::uint32_t>(triangle_count);
  h.slot_count = static_cast<std::uint32_t>(slot_count_);
  h.marker_count = static_cast<std::uint32_t>(data.marker_labels.size());
  h.rig_name_length = static_cast<std::uint32_t>(data.rig_name.size());
  h.triangles_offset = triangles_offset;
  h.rest_positions_offset = rest_offset;
  h.rig_name_offset = rig_name_offset;
  h.marker_labels_offset = labels_offset;
  h.marker_labels_size = label_bytes;
  h.slots_offset = slots_offset;
  h.slot_stride = slot_stride_;
  h.slot_positions_offset = slot_positions_offset_;
  h.slot_normals_offset = slot_normals_offset_;
  h.slot_marker_positions_offset = slot_marker_positions_offset_;
  h.slot_marker_states_offset = slot_marker_states_offset_;
  writeStatic(data);
  atomicAt(h.heartbeat_ns).store(now_ns, std::memory_order_relaxed);
  atomicAt(h.state).store(TETRIG_SHM_STATE_RUNNING, std::memory_order_relaxed);
  state_ = TETRIG_SHM_STATE_RUNNING;
  // Last: the magic. A reader that loads it (acquire) sees everything above.
  atomicAt(h.magic).store(TETRIG_SHM_MAGIC, std::memory_order_release);
  guard.armed = false;
}

void ShmPublisher::writeStatic(const ShmStaticData& data) {
  auto* triangles = reinterpret_cast<std::uint32_t*>(base_ + header_->triangles_offset);
  for (std::size_t i = 0; i < data.triangles.size(); ++i) triangles[i] = static_cast<std::uint32_t>(data.triangles[i]);
  std::memcpy(base_ + header_->rest_positions_offset, data.rest_positions.data(), data.rest_positions.size_bytes());
  char* name = reinterpret_cast<char*>(base_ + header_->rig_name_offset);
  if (!data.rig_name.empty()) std::memcpy(name, data.rig_name.data(), data.rig_name.size());  // an empty view may hold nullptr
  name[data.rig_name.size()] = '\0';
  char* label = reinterpret_cast<char*>(base_ + header_->marker_labels_offset);
  for (const std::string& l : data.marker_labels) {
    std::memcpy(label, l.c_str(), l.size() + 1);
    label += l.size() + 1;
  }
}

ShmPublisher::~ShmPublisher() {
  if (base_ == nullptr) return;
  atomicAt(header_->heartbeat_ns).store(monotonicNowNs(), std::memory_order_relaxed);
  atomicAt(header_->state).store(TETRIG_SHM_STATE_STOPPED, std::memory_order_release);
  munmap(base_, size_);
  // Unlink only our own segment: after a replacement the name belongs to the new producer.
  const int fd = shm_open(name_.c_str(), O_RDONLY | O_CLOEXEC, 0);
  if (fd >= 0) {
    struct stat st{};
    const bool ours = fstat(fd, &st) == 0 && static_cast<std::uint64_t>(st.st_dev) == file_device_ &&
                      static_cast<std::uint64_t>(st.st_ino) == file_inode_;
    close(fd);
    if (ours) shm_unlink(name_.c_str());
  }
}

std::uint64_t ShmPublisher::commit(const ShmFrameInfo& info) noexcept {
  const std::uint64_t frame_id = next_frame_id_;
  unsigned char* slot = slots_ + ((frame_id - 1) % static_cast<std::uint64_t>(slot_count_)) * slot_stride_;
  std::atomic_ref<std::uint64_t> sequence(*reinterpret_cast<std::uint64_t*>(slot + TETRIG_SHM_SLOT_SEQUENCE_OFFSET));
  const std::uint64_t s = sequence.load(std::memory_order_relaxed);  // only this thread writes it
  sequence.store(s + 1, std::memory_order_relaxed);                  // odd: being written
  std::atomic_thread_fence(std::memory_order_release);              // orders the odd value before the payload
  storeWords(slot + slot_positions_offset_, staging_positions_.data(), array_bytes_);
  if (normals_) storeWords(slot + slot_normals_offset_, staging_normals_.data(), array_bytes_);
  if (markers_) {
    storeWords(slot + slot_marker_positions_offset_, staging_marker_positions_.data(), marker_position_bytes_);
    storeWords(slot + slot_marker_states_offset_, staging_marker_states_.data(), marker_state_bytes_);
  }
  TetrigShmFrameInfo out{};
  out.frame_id = frame_id;
  out.source_frame = info.source_frame;
  out.iterations = info.iterations;
  out.flags = info.flags;
  out.occluded_markers = info.occluded_markers;
  out.device_ns = info.device_ns;
  out.receive_ns = info.receive_ns;
  out.taken_ns = info.taken_ns;
  out.step_done_ns = info.step_done_ns;
  out.pose_done_ns = info.pose_done_ns;
  out.publish_ns = monotonicNowNs();
  storeWords(slot + TETRIG_SHM_SLOT_INFO_OFFSET, &out, sizeof out);
  sequence.store(s + 2, std::memory_order_release);  // even: complete
  atomicAt(header_->heartbeat_ns).store(out.publish_ns, std::memory_order_relaxed);
  if (state_ != TETRIG_SHM_STATE_RUNNING) {
    atomicAt(header_->state).store(TETRIG_SHM_STATE_RUNNING, std::memory_order_release);
    state_ = TETRIG_SHM_STATE_RUNNING;
  }
  atomicAt(header_->latest_frame_id).store(frame_id, std::memory_order_release);
  next_frame_id_ = frame_id + 1;
  // In-process followers: one atomic add; the wake system call only while one sleeps.
  commit_word_.fetch_add(1, std::memory_order_seq_cst);
  if (commit_sleepers_.load(std::memory_order_seq_cst) != 0u) detail::futexWakeAll(commit_word_);
  return frame_id;
}

std::uint64_t ShmPublisher::latestFrameId() const noexcept {
  return atomicAt(header_->latest_frame_id).load(std::memory_order_acquire);
}

bool ShmPublisher::waitForCommit(std::uint64_t after_frame_id, std::int64_t timeout_ns) const noexcept {
  if (latestFrameId() > after_frame_id) return true;
  if (timeout_ns <= 0) return false;
  // Read the word, announce the sleep, re-check: a commit after the re-check changes the word, so
  // the futex wait returns at once instead of sleeping through it.
  const std::uint32_t word = commit_word_.load(std::memory_order_seq_cst);
  commit_sleepers_.fetch_add(1, std::memory_order_seq_cst);
  if (latestFrameId() <= after_frame_id) detail::futexWait(commit_word_, word, timeout_ns);
  commit_sleepers_.fetch_sub(1, std::memory_order_seq_cst);
  return latestFrameId() > after_frame_id;
}

void ShmPublisher::wakeCommitWaiters() const noexcept {
  commit_word_.fetch_add(1, std::memory_order_seq_cst);
  detail::futexWakeAll(commit_word_);
}

void ShmPublisher::heartbeat(ShmState state) noexcept {
  atomicAt(header_->heartbeat_ns).store(monotonicNowNs(), std::memory_order_release);
  const auto value = static_cast<std::uint32_t>(state);
  if (value < TETRIG_SHM_STATE_RUNNING || value > TETRIG_SHM_STATE_STOPPED) return;  // not a state
  if (value != state_) {
    atomicAt(header_->state).store(value, std::memory_order_release);
    state_ = value;
  }
}

}  // namespace tetrig
