// Tests for the shared-memory segment: the C++ writer (runtime/src/shm_publisher.cpp), the C99
// reader header (runtime/include/tetrig_shm.h, used here as C++) and the C consumer
// tools/tetrig_shm_cat.c. Round trip, refusal of bad segments, the seqlock under concurrent
// readers (no torn frame, ids never go backwards, the retry path exercised), processes (killed
// reader, killed writer seen dead, replacement by a new producer, live producer refused),
// permissions, no allocation on the frame path, and the consumer's output and --dump. Layout
// 1.1: the marker block round trip, left out, a 1.0 segment read as "no markers", and the marker
// block inside the seqlock under the concurrent readers.
// Also built with -fsanitize=thread (test_shm_tsan, fewer stress frames).
#include "tetrig/shm_publisher.hpp"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include "shm_dump.hpp"
#include "temp_dir.hpp"

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <limits>
#include <memory>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "counting_allocator.hpp"
#include "tetrig/clock.hpp"

// The reader's test hook (tetrig_shm.h): runs in every read attempt between the frame info copy
// and the positions copy.
namespace shm_test_hook {
void readWindow(const void* reader);
}
#define TETRIG_SHM_READ_WINDOW_HOOK(reader) ::shm_test_hook::readWindow(reader)
#include "tetrig_shm.h"

namespace shm_test_hook {
// 0: off; n: every n-th read attempt of this thread waits inside its window until the writer has
// published slot_count more frames, i.e. has certainly rewritten the slot being read.
thread_local std::uint64_t lap_every = 0;
thread_local std::uint64_t attempts = 0;
thread_local std::uint64_t forced_laps = 0;  // attempts that were certainly overlapped by a write
void readWindow(const void* reader) {
  if (lap_every == 0 || ++attempts % lap_every != 0) return;
  const auto* r = static_cast<const TetrigShmReader*>(reader);
  const std::uint64_t start = tetrig_shm_latest_frame_id(r);
  const auto give_up = std::chrono::steady_clock::now() + std::chrono::milliseconds(20);
  while (tetrig_shm_latest_frame_id(r) < start + tetrig_shm_slot_count(r)) {
    if (std::chrono::steady_clock::now() > give_up) return;  // the writer has finished
    std::this_thread::sleep_for(std::chrono::microseconds(20));
  }
  ++forced_laps;
}
}  // namespace shm_test_hook

extern char** environ;

namespace {

using tetrig::ShmError;
using tetrig::ShmFrameInfo;
using tetrig::ShmPublisher;
using tetrig::ShmPublisherOptions;
using tetrig::ShmStaticData;
using tetrig::ShmState;

#ifndef TETRIG_SHM_STRESS_FRAMES
#define TETRIG_SHM_STRESS_FRAMES 2000000
#endif

// ---------------------------------------------------------------------------------------------
// Helpers

std::string uniqueName(const std::string& tag) {
  static std::atomic<int> counter{0};
  return "/tetrig_test_" + std::to_string(getpid()) + "_" + std::to_string(counter.fetch_add(1)) + "_" + tag;
}

// Unlinks the name at scope exit (a failed test must not leave segments behind).
struct NameGuard {
  std::string name;
  ~NameGuard() { shm_unlink(name.c_str()); }
};

// Every published float is a function of (frame id, index): a torn copy mixes frames and fails.
// 4099 is odd, so two frame ids closer than 2^24 give different values at every index. Cheap, so
// the stress writer runs at copy speed.
float positionValue(std::uint64_t frame_id, std::size_t i) {
  return static_cast<float>((frame_id * 4099u + static_cast<std::uint64_t>(i) * 7u) & 0xFFFFFFu);  // exact in float
}
float normalValue(std::uint64_t frame_id, std::size_t i) { return -positionValue(frame_id, i) - 0.5f; }
float markerValue(std::uint64_t frame_id, std::size_t i) { return 0.25f * positionValue(frame_id, i + 100003u); }
std::uint8_t markerStateValue(std::uint64_t frame_id, std::size_t k) { return static_cast<std::uint8_t>((frame_id + k) % 4u); }

ShmFrameInfo infoFor(std::uint64_t frame_id) {
  ShmFrameInfo info;
  info.source_frame = frame_id * 3 + 1;
  info.iterations = static_cast<std::int32_t>(frame_id % 17);
  info.flags = static_cast<std::uint32_t>(frame_id & 0x1Fu);
  info.occluded_markers = static_cast<std::uint16_t>(frame_id & 0xFFFFu);
  info.device_ns = static_cast<std::int64_t>(frame_id * 11);
  info.receive_ns = static_cast<std::int64_t>(frame_id * 13);
  info.taken_ns = static_cast<std::int64_t>(frame_id * 17);
  info.step_done_ns = static_cast<std::int64_t>(frame_id * 19);
  info.pose_done_ns = static_cast<std::int64_t>(frame_id * 23);
  return info;
}

// Stages the pattern of the publisher's next frame and commits it; returns the frame id.
std::uint64_t publishPattern(ShmPublisher& pub) {
  const std::uint64_t id = pub.framesPublished() + 1;
  const std::size_t n = static_cast<std::size_t>(pub.vertexCount()) * 3;
  float* p = pub.beginPositions();
  for (std::size_t i = 0; i < n; ++i) p[i] = positionValue(id, i);
  if (float* q = pub.beginNormals()) {
    for (std::size_t i = 0; i < n; ++i) q[i] = normalValue(id, i);
  }
  if (float* m = pub.beginMarkerPositions()) {
    const auto markers = static_cast<std::size_t>(pub.markerCount());
    for (std::size_t i = 0; i < markers * 3; ++i) m[i] = markerValue(id, i);
    std::uint8_t* states = pub.beginMarkerStates();
    for (std::size_t k = 0; k < markers; ++k) states[k] = markerStateValue(id, k);
  }
  const std::uint64_t got = pub.commit(infoFor(id));
  return got;
}

// True when positions, normals (if given) and info all belong to info.frame_id.
bool consistent(const std::vector<float>& positions, const std::vector<float>* normals, const TetrigShmFrameInfo& info) {
  const std::uint64_t id = info.frame_id;
  const ShmFrameInfo want = infoFor(id);
  if (id == 0 || info.source_frame != want.source_frame || info.iterations != want.iterations ||
      info.flags != want.flags || info.occluded_markers != want.occluded_markers || info.device_ns != want.device_ns ||
      info.receive_ns != want.receive_ns || info.taken_ns != want.taken_ns || info.step_done_ns != want.step_done_ns ||
      info.pose_done_ns != want.pose_done_ns || info.publish_ns <= 0) {
    return false;
  }
  for (std::size_t i = 0; i < positions.size(); ++i) {
    if (positions[i] != positionValue(id, i)) return false;
  }
  if (normals != nullptr) {
    for (std::size_t i = 0; i < normals->size(); ++i) {
      if ((*normals)[i] != normalValue(id, i)) return false;
    }
  }
  return true;
}

// True when the marker block belongs to frame `id`.
bool markersConsistent(std::uint64_t id, const std::vector<float>& marker_positions, const std::vector<std::uint8_t>& states) {
  for (std::size_t i = 0; i < marker_positions.size(); ++i) {
    if (marker_positions[i] != markerValue(id, i)) return false;
  }
  for (std::size_t k = 0; k < states.size(); ++k) {
    if (states[k] != markerStateValue(id, k)) return false;
  }
  return true;
}

// A small static mesh: a strip of triangles over `v` vertices.
struct Mesh {
  std::vector<std::int32_t> triangles;
  std::vector<float> rest;
  std::vector<std::string> labels{"LFHD", "RFHD", "C7"};
  std::string rig_name = "test rig";
  explicit Mesh(int v) {
    for (int i = 0; i + 2 < v; ++i) {
      triangles.insert(triangles.end(), {i, i + 1, i + 2});
    }
    for (int i = 0; i < v; ++i) {
      rest.insert(rest.end(), {0.5f * static_cast<float>(i), static_cast<float>(i), 1.5f * static_cast<float>(i)});
    }
  }
  [[nodiscard]] ShmStaticData data() const { return ShmStaticData{triangles, rest, rig_name, labels}; }
};

ShmPublisherOptions optionsFor(const std::string& name, int slots = 4, bool normals = false) {
  ShmPublisherOptions o;
  o.name = name;
  o.slot_count = slots;
  o.normals = normals;
  return o;
}

bool waitUntil(const std::function<bool()>& done, std::chrono::milliseconds timeout) {
  const auto end = std::chrono::steady_clock::now() + timeout;
  while (!done()) {
    if (std::chrono::steady_clock::now() > end) return false;
    std::this_thread::sleep_for(std::chrono::microseconds(200));
  }
  return true;
}

// Maps an existing segment read-write, for tests that corrupt or inspect it.
struct RawMapping {
  void* base = MAP_FAILED;
  std::size_t size = 0;
  explicit RawMapping(const std::string& name) {
    const int fd = shm_open(name.c_str(), O_RDWR, 0);
    if (fd < 0) return;
    struct stat st{};
    fstat(fd, &st);
    size = static_cast<std::size_t>(st.st_size);
    base = mmap(nullptr, size, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
    close(fd);
  }
  ~RawMapping() {
    if (base != MAP_FAILED) munmap(base, size);
  }
  [[nodiscard]] bool ok() const { return base != MAP_FAILED; }
  TetrigShmHeader& header() { return *static_cast<TetrigShmHeader*>(base); }
  unsigned char* bytes() { return static_cast<unsigned char*>(base); }
};

// Creates a raw shared-memory object (not made by the publisher) of `size` bytes.
bool makeRawSegment(const std::string& name, std::size_t size, const std::function<void(unsigned char*)>& fill) {
  const int fd = shm_open(name.c_str(), O_RDWR | O_CREAT | O_EXCL, 0600);
  if (fd < 0) return false;
  bool ok = ftruncate(fd, static_cast<off_t>(size)) == 0;
  if (ok && size > 0) {
    void* m = mmap(nullptr, size, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
    ok = m != MAP_FAILED;
    if (ok) {
      fill(static_cast<unsigned char*>(m));
      munmap(m, size);
    }
  }
  close(fd);
  return ok;
}

// The pid of a process that has exited and been reaped.
pid_t deadPid() {
  const pid_t pid = fork();
  if (pid == 0) _exit(0);
  int status = 0;
  waitpid(pid, &status, 0);
  return pid;
}

// Reads one byte from `fd` within `timeout_ms`; -1 on timeout or EOF.
int readByte(int fd, int timeout_ms) {
  pollfd p{fd, POLLIN, 0};
  if (poll(&p, 1, timeout_ms) <= 0) return -1;
  unsigned char c = 0;
  return read(fd, &c, 1) == 1 ? c : -1;
}

// A producer in a child process: creates the segment, reports through `ready_fd` ('r' + its
// 8-byte instance id, or 'e' on failure), then publishes `frames` frames (0 = forever) every
// `period_us`, heartbeating while idle, until killed. Never returns.
[[noreturn]] void runChildWriter(const std::string& name, int vertices, int ready_fd, std::uint64_t frames, int period_us) {
  try {
    const Mesh mesh(vertices);
    ShmPublisher pub(optionsFor(name), vertices, mesh.data());
    const std::uint64_t id = pub.instanceId();
    unsigned char msg[9];
    msg[0] = 'r';
    std::memcpy(msg + 1, &id, 8);
    if (write(ready_fd, msg, sizeof msg) != static_cast<ssize_t>(sizeof msg)) _exit(3);
    for (;;) {
      if (frames == 0 || pub.framesPublished() < frames) {
        publishPattern(pub);
      } else {
        pub.heartbeat(ShmState::stale_source);
      }
      usleep(static_cast<useconds_t>(period_us));
    }
  } catch (...) {
    const unsigned char e = 'e';
    (void)!write(ready_fd, &e, 1);
    _exit(2);
  }
}

struct ChildWriter {
  pid_t pid = -1;
  std::uint64_t instance_id = 0;
  ~ChildWriter() {
    if (pid > 0) {
      kill(pid, SIGKILL);
      waitpid(pid, nullptr, 0);
    }
  }
};

// Forks a child writer and waits until its segment exists.
::testing::AssertionResult startChildWriter(ChildWriter& child, const std::string& name, int vertices,
                                            std::uint64_t frames = 0, int period_us = 200) {
  int fds[2];
  if (pipe2(fds, O_CLOEXEC) != 0) return ::testing::AssertionFailure() << "pipe2 failed";
  const pid_t pid = fork();
  if (pid < 0) return ::testing::AssertionFailure() << "fork failed";
  if (pid == 0) {
    close(fds[0]);
    runChildWriter(name, vertices, fds[1], frames, period_us);
  }
  close(fds[1]);
  child.pid = pid;
  unsigned char msg[9];
  std::size_t got = 0;
  pollfd p{fds[0], POLLIN, 0};
  while (got < sizeof msg && poll(&p, 1, 10000) > 0) {
    const ssize_t n = read(fds[0], msg + got, sizeof msg - got);
    if (n <= 0) break;
    got += static_cast<std::size_t>(n);
    if (msg[0] != 'r') break;
  }
  close(fds[0]);
  if (got != sizeof msg || msg[0] != 'r') return ::testing::AssertionFailure() << "child writer did not start";
  std::memcpy(&child.instance_id, msg + 1, 8);
  return ::testing::AssertionSuccess();
}

// ---------------------------------------------------------------------------------------------
// Round trip

TEST(Shm, RoundTripOfStaticDataAndFrames) {
  const std::string name = uniqueName("roundtrip");
  NameGuard guard{name};
  const int v = 5;
  const Mesh mesh(v);
  ShmPublisher pub(optionsFor(name, 4, true), v, mesh.data());
  EXPECT_EQ(pub.name(), name);
  EXPECT_NE(pub.instanceId(), 0u);

  TetrigShmReader r;
  ASSERT_EQ(tetrig_shm_open(&r, name.c_str()), TETRIG_SHM_OK);
  EXPECT_EQ(tetrig_shm_vertex_count(&r), 5u);
  EXPECT_EQ(tetrig_shm_triangle_count(&r), 3u);
  EXPECT_EQ(tetrig_shm_slot_count(&r), 4u);
  EXPECT_TRUE(tetrig_shm_has_normals(&r));
  EXPECT_EQ(r.instance_id, pub.instanceId());
  EXPECT_EQ(r.producer_pid, getpid());
  EXPECT_EQ(tetrig_shm_state(&r), TETRIG_SHM_STATE_RUNNING);
  EXPECT_EQ(r.header->version_major, TETRIG_SHM_VERSION_MAJOR);
  EXPECT_EQ(r.header->total_size, pub.segmentSize());
  for (std::size_t i = 0; i < mesh.triangles.size(); ++i) {
    EXPECT_EQ(tetrig_shm_triangles(&r)[i], static_cast<std::uint32_t>(mesh.triangles[i]));
  }
  EXPECT_EQ(std::memcmp(tetrig_shm_rest_positions(&r), mesh.rest.data(), mesh.rest.size() * sizeof(float)), 0);
  EXPECT_STREQ(tetrig_shm_rig_name(&r), "test rig");
  ASSERT_EQ(tetrig_shm_marker_count(&r), 3u);
  EXPECT_STREQ(tetrig_shm_marker_label(&r, 0), "LFHD");
  EXPECT_STREQ(tetrig_shm_marker_label(&r, 1), "RFHD");
  EXPECT_STREQ(tetrig_shm_marker_label(&r, 2), "C7");
  EXPECT_EQ(tetrig_shm_marker_label(&r, 3), nullptr);
  // every array on a 64-byte boundary
  EXPECT_EQ(r.header->triangles_offset % 64, 0u);
  EXPECT_EQ(r.header->rest_positions_offset % 64, 0u);
  EXPECT_EQ(r.header->slots_offset % 64, 0u);
  EXPECT_EQ(r.header->slot_stride % 64, 0u);
  EXPECT_EQ(r.header->slot_normals_offset % 64, 0u);

  std::vector<float> pos(15), nrm(15);
  TetrigShmFrameInfo info{};
  EXPECT_EQ(tetrig_shm_read_latest(&r, pos.data(), pos.size(), nrm.data(), nrm.size(), &info), TETRIG_SHM_NO_FRAME);
  EXPECT_EQ(tetrig_shm_latest_frame_id(&r), 0u);

  for (std::uint64_t k = 1; k <= 10; ++k) {  // more frames than slots: every slot reused
    const std::int64_t before = tetrig::monotonicNowNs();
    ASSERT_EQ(publishPattern(pub), k);
    const std::int64_t after = tetrig::monotonicNowNs();
    ASSERT_EQ(tetrig_shm_read_latest(&r, pos.data(), pos.size(), nrm.data(), nrm.size(), &info), TETRIG_SHM_OK);
    EXPECT_EQ(info.frame_id, k);
    EXPECT_TRUE(consistent(pos, &nrm, info)) << "frame " << k;
    EXPECT_GE(info.publish_ns, before);
    EXPECT_LE(info.publish_ns, after);
    EXPECT_EQ(tetrig_shm_heartbeat_ns(&r), info.publish_ns);
    EXPECT_EQ(r.last_frame_id, k);
  }
  EXPECT_EQ(tetrig_shm_latest_frame_id(&r), 10u);
  EXPECT_EQ(pub.framesPublished(), 10u);
  EXPECT_EQ(r.reads, 10u);

  // attaching to the producer's own mapping reads the same frame
  TetrigShmReader attached;
  ASSERT_EQ(tetrig_shm_attach(&attached, pub.segmentData(), pub.segmentSize()), TETRIG_SHM_OK);
  std::vector<float> pos2(15);
  ASSERT_EQ(tetrig_shm_read_latest(&attached, pos2.data(), pos2.size(), nullptr, 0, &info), TETRIG_SHM_OK);
  EXPECT_EQ(info.frame_id, 10u);
  EXPECT_EQ(pos2, pos);
  tetrig_shm_close(&attached);

  // a buffer too small is refused, untouched
  std::vector<float> small(14, 7.0f);
  EXPECT_EQ(tetrig_shm_read_latest(&r, small.data(), small.size(), nullptr, 0, nullptr), TETRIG_SHM_E_ARGUMENT);
  EXPECT_EQ(small, std::vector<float>(14, 7.0f));
  tetrig_shm_close(&r);
}

TEST(Shm, WithoutNormalsTheNormalsBufferIsLeftAlone) {
  const std::string name = uniqueName("nonormals");
  NameGuard guard{name};
  const Mesh mesh(4);
  ShmPublisher pub(optionsFor(name, 3, false), 4, mesh.data());
  EXPECT_EQ(pub.beginNormals(), nullptr);
  EXPECT_FALSE(pub.hasNormals());
  publishPattern(pub);
  TetrigShmReader r;
  ASSERT_EQ(tetrig_shm_open(&r, name.c_str()), TETRIG_SHM_OK);
  EXPECT_FALSE(tetrig_shm_has_normals(&r));
  EXPECT_EQ(r.header->slot_normals_offset, 0u);
  std::vector<float> pos(12), nrm(12, 42.0f);
  TetrigShmFrameInfo info{};
  ASSERT_EQ(tetrig_shm_read_latest(&r, pos.data(), pos.size(), nrm.data(), nrm.size(), &info), TETRIG_SHM_OK);
  EXPECT_TRUE(consistent(pos, nullptr, info));
  EXPECT_EQ(nrm, std::vector<float>(12, 42.0f));
  tetrig_shm_close(&r);
}

// Layout 1.1: the marker block (positions + state bytes, label order) of the newest frame comes
// with that frame's mesh; 5 markers = 5 state bytes, so the copy ends inside a 4-byte word and
// must not write past the caller's buffer.
TEST(Shm, MarkerPositionsAndStatesRoundTripWithTheirFrame) {
  const std::string name = uniqueName("markers");
  NameGuard guard{name};
  Mesh mesh(6);
  mesh.labels = {"LFHD", "RFHD", "C7", "T10", "STRN"};
  ShmPublisher pub(optionsFor(name, 3, true), 6, mesh.data());
  ASSERT_TRUE(pub.hasMarkerPositions());
  ASSERT_EQ(pub.markerCount(), 5);
  // staged markers start as zeros, state unknown
  for (int i = 0; i < 15; ++i) EXPECT_EQ(pub.beginMarkerPositions()[i], 0.0f);
  for (int k = 0; k < 5; ++k) EXPECT_EQ(pub.beginMarkerStates()[k], TETRIG_SHM_MARKER_UNKNOWN);
  TetrigShmReader r;
  ASSERT_EQ(tetrig_shm_open(&r, name.c_str()), TETRIG_SHM_OK);
  EXPECT_EQ(r.header->version_minor, 1u);
  EXPECT_NE(r.header->flags & TETRIG_SHM_HAS_MARKER_POSITIONS, 0u);
  EXPECT_EQ(tetrig_shm_has_marker_positions(&r), 1);
  EXPECT_EQ(r.header->slot_marker_positions_offset % 64, 0u);
  EXPECT_EQ(r.header->slot_marker_states_offset % 64, 0u);
  std::vector<float> pos(18), nrm(18), markers(16, -7.0f);
  std::vector<std::uint8_t> states(6, 0xEE);
  TetrigShmFrameInfo info{};
  EXPECT_EQ(tetrig_shm_read_latest_markers(&r, pos.data(), 18, nrm.data(), 18, markers.data(), 15, states.data(), 5, &info),
            TETRIG_SHM_NO_FRAME);
  for (std::uint64_t k = 1; k <= 7; ++k) {  // more frames than slots
    ASSERT_EQ(publishPattern(pub), k);
    ASSERT_EQ(tetrig_shm_read_latest_markers(&r, pos.data(), 18, nrm.data(), 18, markers.data(), 15, states.data(), 5, &info),
              TETRIG_SHM_OK);
    EXPECT_EQ(info.frame_id, k);
    EXPECT_TRUE(consistent(pos, &nrm, info)) << "frame " << k;
    EXPECT_TRUE(markersConsistent(k, std::vector<float>(markers.begin(), markers.begin() + 15),
                                  std::vector<std::uint8_t>(states.begin(), states.begin() + 5)))
        << "frame " << k;
    EXPECT_EQ(markers[15], -7.0f) << "wrote past the marker positions";
    EXPECT_EQ(states[5], 0xEE) << "wrote past the marker states";
  }
  // only the markers (mesh buffers NULL) and only the states
  std::vector<float> markers_only(15);
  ASSERT_EQ(tetrig_shm_read_latest_markers(&r, nullptr, 0, nullptr, 0, markers_only.data(), 15, nullptr, 0, &info),
            TETRIG_SHM_OK);
  EXPECT_TRUE(markersConsistent(7, markers_only, {}));
  std::vector<std::uint8_t> states_only(5);
  ASSERT_EQ(tetrig_shm_read_latest_markers(&r, nullptr, 0, nullptr, 0, nullptr, 0, states_only.data(), 5, nullptr),
            TETRIG_SHM_OK);
  EXPECT_TRUE(markersConsistent(7, {}, states_only));
  // the 1.0 call still reads the mesh of a 1.1 segment
  ASSERT_EQ(tetrig_shm_read_latest(&r, pos.data(), 18, nrm.data(), 18, &info), TETRIG_SHM_OK);
  EXPECT_TRUE(consistent(pos, &nrm, info));
  // marker buffers too small: refused, untouched
  std::vector<float> small(14, 3.0f);
  EXPECT_EQ(tetrig_shm_read_latest_markers(&r, nullptr, 0, nullptr, 0, small.data(), 14, nullptr, 0, nullptr),
            TETRIG_SHM_E_ARGUMENT);
  EXPECT_EQ(small, std::vector<float>(14, 3.0f));
  std::vector<std::uint8_t> small_states(4, 9);
  EXPECT_EQ(tetrig_shm_read_latest_markers(&r, nullptr, 0, nullptr, 0, nullptr, 0, small_states.data(), 4, nullptr),
            TETRIG_SHM_E_ARGUMENT);
  EXPECT_EQ(small_states, std::vector<std::uint8_t>(4, 9));
  tetrig_shm_close(&r);
}

// Without labels, or with ShmPublisherOptions::marker_positions off, a 1.1 segment has no marker
// block: smaller slots, and the marker read reports TETRIG_SHM_NO_MARKERS.
TEST(Shm, TheMarkerBlockIsLeftOutWithoutLabelsOrWhenTurnedOff) {
  Mesh mesh(4);
  std::size_t with_size = 0;
  {
    const std::string name = uniqueName("withmarkers");
    NameGuard guard{name};
    ShmPublisher pub(optionsFor(name), 4, mesh.data());
    with_size = pub.segmentSize();
  }
  for (int variant = 0; variant < 2; ++variant) {
    const std::string name = uniqueName("nomarkers");
    NameGuard guard{name};
    ShmPublisherOptions o = optionsFor(name);
    Mesh m(4);
    if (variant == 0) {
      o.marker_positions = false;
    } else {
      m.labels.clear();
    }
    ShmPublisher pub(o, 4, m.data());
    EXPECT_FALSE(pub.hasMarkerPositions()) << variant;
    EXPECT_EQ(pub.beginMarkerPositions(), nullptr) << variant;
    EXPECT_EQ(pub.beginMarkerStates(), nullptr) << variant;
    EXPECT_LT(pub.segmentSize(), with_size) << variant;
    publishPattern(pub);
    TetrigShmReader r;
    ASSERT_EQ(tetrig_shm_open(&r, name.c_str()), TETRIG_SHM_OK);
    EXPECT_EQ(tetrig_shm_marker_count(&r), variant == 0 ? 3u : 0u);
    EXPECT_EQ(tetrig_shm_has_marker_positions(&r), 0);
    EXPECT_EQ(r.header->slot_marker_positions_offset, 0u);
    std::vector<float> pos(12), markers(9, 5.0f);
    EXPECT_EQ(tetrig_shm_read_latest_markers(&r, pos.data(), 12, nullptr, 0, markers.data(), 9, nullptr, 0, nullptr),
              TETRIG_SHM_NO_MARKERS);
    EXPECT_EQ(markers, std::vector<float>(9, 5.0f));
    TetrigShmFrameInfo info{};
    ASSERT_EQ(tetrig_shm_read_latest(&r, pos.data(), 12, nullptr, 0, &info), TETRIG_SHM_OK);
    EXPECT_TRUE(consistent(pos, nullptr, info));
    tetrig_shm_close(&r);
  }
}

// A layout 1.0 segment (minor 0: the marker fields are reserved zeros) is still accepted by a 1.1
// reader, which reports "no marker positions" and reads the mesh as before. A minor-0 header with
// a stray flag bit is not trusted either.
TEST(Shm, ALayout10SegmentIsAcceptedWithNoMarkers) {
  const std::string name = uniqueName("v10");
  NameGuard guard{name};
  const Mesh mesh(5);
  ShmPublisher pub(optionsFor(name, 3, true), 5, mesh.data());
  publishPattern(pub);
  RawMapping raw(name);
  ASSERT_TRUE(raw.ok());
  TetrigShmHeader& h = raw.header();
  // what a 1.0 producer writes: minor 0, flags without the marker bit, the 1.1 fields zero
  h.version_minor = 0;
  h.flags = TETRIG_SHM_HAS_NORMALS;
  h.slot_marker_positions_offset = 0;
  h.slot_marker_states_offset = 0;
  for (int stray = 0; stray < 2; ++stray) {
    if (stray == 1) h.flags |= TETRIG_SHM_HAS_MARKER_POSITIONS;  // ignored in minor 0 (offsets 0 would fail in 1.1)
    TetrigShmReader r;
    ASSERT_EQ(tetrig_shm_open(&r, name.c_str()), TETRIG_SHM_OK) << stray;
    EXPECT_EQ(tetrig_shm_has_marker_positions(&r), 0) << stray;
    EXPECT_EQ(tetrig_shm_marker_count(&r), 3u);
    EXPECT_STREQ(tetrig_shm_marker_label(&r, 2), "C7");
    std::vector<float> pos(15), nrm(15), markers(9, 5.0f);
    std::vector<std::uint8_t> states(3, 0xEE);
    EXPECT_EQ(tetrig_shm_read_latest_markers(&r, pos.data(), 15, nrm.data(), 15, markers.data(), 9, states.data(), 3, nullptr),
              TETRIG_SHM_NO_MARKERS);
    EXPECT_EQ(markers, std::vector<float>(9, 5.0f));
    EXPECT_EQ(states, std::vector<std::uint8_t>(3, 0xEE));
    EXPECT_STRNE(tetrig_shm_status_string(TETRIG_SHM_NO_MARKERS), "unknown status");
    TetrigShmFrameInfo info{};
    ASSERT_EQ(tetrig_shm_read_latest(&r, pos.data(), 15, nrm.data(), 15, &info), TETRIG_SHM_OK);
    EXPECT_TRUE(consistent(pos, &nrm, info));
    tetrig_shm_close(&r);
  }
  // the same header as 1.1 with the flag but no offsets is inconsistent
  h.version_minor = 1;
  TetrigShmReader r;
  EXPECT_EQ(tetrig_shm_open(&r, name.c_str()), TETRIG_SHM_E_SIZE);
}

TEST(Shm, FirstFrameDefaultsToRestPoseAndOddVertexCountsCopyExactly) {
  const std::string name = uniqueName("odd");
  NameGuard guard{name};
  const int v = 7;  // 84 bytes: the copy ends with a 4-byte word
  const Mesh mesh(v);
  ShmPublisher pub(optionsFor(name, 3, true), v, mesh.data());
  // staged positions start as the rest pose
  EXPECT_EQ(std::memcmp(pub.beginPositions(), mesh.rest.data(), mesh.rest.size() * sizeof(float)), 0);
  pub.commit(ShmFrameInfo{});
  TetrigShmReader r;
  ASSERT_EQ(tetrig_shm_open(&r, name.c_str()), TETRIG_SHM_OK);
  std::vector<float> pos(22, -1.0f);  // one sentinel float past the 21 the frame has
  ASSERT_EQ(tetrig_shm_read_latest(&r, pos.data(), 21, nullptr, 0, nullptr), TETRIG_SHM_OK);
  EXPECT_EQ(std::memcmp(pos.data(), mesh.rest.data(), 21 * sizeof(float)), 0);
  EXPECT_EQ(pos[21], -1.0f);
  publishPattern(pub);
  std::vector<float> exact(21), nrm(22, -1.0f);
  TetrigShmFrameInfo info{};
  ASSERT_EQ(tetrig_shm_read_latest(&r, exact.data(), 21, nrm.data(), 21, &info), TETRIG_SHM_OK);
  EXPECT_EQ(nrm[21], -1.0f);
  nrm.resize(21);
  EXPECT_TRUE(consistent(exact, &nrm, info));
  tetrig_shm_close(&r);
}

TEST(Shm, HeartbeatAndStateReachReaders) {
  const std::string name = uniqueName("heartbeat");
  NameGuard guard{name};
  const Mesh mesh(3);
  ShmPublisher pub(optionsFor(name), 3, mesh.data());
  TetrigShmReader r;
  ASSERT_EQ(tetrig_shm_open(&r, name.c_str()), TETRIG_SHM_OK);
  const std::int64_t h0 = tetrig_shm_heartbeat_ns(&r);
  EXPECT_GT(h0, 0);
  EXPECT_EQ(tetrig_shm_producer_status(&r, 1'000'000'000), TETRIG_SHM_PRODUCER_ALIVE);
  std::this_thread::sleep_for(std::chrono::milliseconds(2));
  pub.heartbeat(ShmState::stale_source);
  EXPECT_EQ(tetrig_shm_state(&r), TETRIG_SHM_STATE_STALE_SOURCE);
  EXPECT_GT(tetrig_shm_heartbeat_ns(&r), h0);
  EXPECT_EQ(tetrig_shm_producer_status(&r, 1'000'000'000), TETRIG_SHM_PRODUCER_ALIVE);
  // a heartbeat older than the limit: stale, although the pid lives
  std::this_thread::sleep_for(std::chrono::milliseconds(5));
  EXPECT_EQ(tetrig_shm_producer_status(&r, 1'000'000), TETRIG_SHM_PRODUCER_STALE);
  pub.heartbeat(static_cast<ShmState>(9));  // not a state: heartbeat only
  EXPECT_EQ(tetrig_shm_state(&r), TETRIG_SHM_STATE_STALE_SOURCE);
  publishPattern(pub);  // a frame means running again
  EXPECT_EQ(tetrig_shm_state(&r), TETRIG_SHM_STATE_RUNNING);
  tetrig_shm_close(&r);
}

// ---------------------------------------------------------------------------------------------
// Reader refusals

TEST(Shm, ReaderRefusesBadMagicVersionAndSizes) {
  const std::string name = uniqueName("refuse");
  NameGuard guard{name};
  const Mesh mesh(6);
  ShmPublisher pub(optionsFor(name, 3, true), 6, mesh.data());
  publishPattern(pub);
  RawMapping raw(name);
  ASSERT_TRUE(raw.ok());
  TetrigShmHeader& h = raw.header();
  TetrigShmReader r;
  ASSERT_EQ(tetrig_shm_open(&r, name.c_str()), TETRIG_SHM_OK);
  tetrig_shm_close(&r);

  // Applies `change`, expects `code` from open (and from attach on the same bytes), restores.
  auto expectOpen = [&](const char* what, const std::function<void()>& change, const std::function<void()>& undo, int code) {
    change();
    TetrigShmReader rr;
    EXPECT_EQ(tetrig_shm_open(&rr, name.c_str()), code) << what;
    EXPECT_EQ(rr.header, nullptr) << what;  // nothing stays open on failure
    tetrig_shm_close(&rr);
    undo();
    ASSERT_EQ(tetrig_shm_open(&rr, name.c_str()), TETRIG_SHM_OK) << what << " (restored)";
    tetrig_shm_close(&rr);
  };
  const std::uint64_t magic = h.magic;
  expectOpen("magic", [&] { h.magic = 0x1234; }, [&] { h.magic = magic; }, TETRIG_SHM_E_MAGIC);
  expectOpen("magic 0", [&] { h.magic = 0; }, [&] { h.magic = magic; }, TETRIG_SHM_E_NOT_READY);
  expectOpen("major", [&] { h.version_major = 2; }, [&] { h.version_major = 1; }, TETRIG_SHM_E_VERSION);
  expectOpen("major 0", [&] { h.version_major = 0; }, [&] { h.version_major = 1; }, TETRIG_SHM_E_VERSION);
  expectOpen("total size", [&] { h.total_size += 64; }, [&] { h.total_size -= 64; }, TETRIG_SHM_E_SIZE);
  expectOpen("header size", [&] { h.header_size = 128; }, [&] { h.header_size = 256; }, TETRIG_SHM_E_SIZE);
  expectOpen("slot count 2", [&] { h.slot_count = 2; }, [&] { h.slot_count = 3; }, TETRIG_SHM_E_SIZE);
  expectOpen("slot count 4", [&] { h.slot_count = 4; }, [&] { h.slot_count = 3; }, TETRIG_SHM_E_SIZE);
  expectOpen("vertex count", [&] { h.vertex_count = 1000; }, [&] { h.vertex_count = 6; }, TETRIG_SHM_E_SIZE);
  expectOpen("vertex count 0", [&] { h.vertex_count = 0; }, [&] { h.vertex_count = 6; }, TETRIG_SHM_E_SIZE);
  const std::uint64_t tri_off = h.triangles_offset;
  expectOpen("triangles offset", [&] { h.triangles_offset = h.total_size; }, [&] { h.triangles_offset = tri_off; },
             TETRIG_SHM_E_SIZE);
  expectOpen("triangles misaligned", [&] { h.triangles_offset += 4; }, [&] { h.triangles_offset = tri_off; },
             TETRIG_SHM_E_SIZE);
  auto* tri = reinterpret_cast<std::uint32_t*>(raw.bytes() + tri_off);
  expectOpen("triangle index", [&] { tri[4] = 6; }, [&] { tri[4] = static_cast<std::uint32_t>(mesh.triangles[4]); },
             TETRIG_SHM_E_SIZE);
  unsigned char* name_end = raw.bytes() + h.rig_name_offset + h.rig_name_length;
  expectOpen("rig name terminator", [&] { *name_end = 'x'; }, [&] { *name_end = 0; }, TETRIG_SHM_E_SIZE);
  expectOpen("marker count", [&] { h.marker_count = 4; }, [&] { h.marker_count = 3; }, TETRIG_SHM_E_SIZE);
  const std::uint64_t stride = h.slot_stride;
  expectOpen("slot stride", [&] { h.slot_stride = stride + 8; }, [&] { h.slot_stride = stride; }, TETRIG_SHM_E_SIZE);
  expectOpen("slot stride large", [&] { h.slot_stride = stride * 2; }, [&] { h.slot_stride = stride; }, TETRIG_SHM_E_SIZE);
  const std::uint32_t flags = h.flags;
  expectOpen("normals flag", [&] { h.flags = flags & ~TETRIG_SHM_HAS_NORMALS; }, [&] { h.flags = flags; }, TETRIG_SHM_E_SIZE);
  const std::uint64_t normals_offset = h.slot_normals_offset;
  expectOpen("normals offset", [&] { h.slot_normals_offset = stride; }, [&] { h.slot_normals_offset = normals_offset; },
             TETRIG_SHM_E_SIZE);
  // two slot arrays over the same bytes (each inside the slot on its own)
  const std::uint64_t positions_offset = h.slot_positions_offset;
  expectOpen("positions over the normals", [&] { h.slot_positions_offset = normals_offset; },
             [&] { h.slot_positions_offset = positions_offset; }, TETRIG_SHM_E_SIZE);
  expectOpen("normals over the positions", [&] { h.slot_normals_offset = positions_offset; },
             [&] { h.slot_normals_offset = normals_offset; }, TETRIG_SHM_E_SIZE);
  // file larger than the header says
  const int fd = shm_open(name.c_str(), O_RDWR, 0);
  ASSERT_GE(fd, 0);
  expectOpen("file size", [&] { ASSERT_EQ(ftruncate(fd, static_cast<off_t>(h.total_size + 4096)), 0); },
             [&] { ASSERT_EQ(ftruncate(fd, static_cast<off_t>(h.total_size)), 0); }, TETRIG_SHM_E_SIZE);
  close(fd);
  // a newer minor version is accepted
  h.version_minor = 7;
  ASSERT_EQ(tetrig_shm_open(&r, name.c_str()), TETRIG_SHM_OK);
  tetrig_shm_close(&r);
  h.version_minor = TETRIG_SHM_VERSION_MINOR;
  // 1.1 marker block: offsets checked like the other arrays
  const std::uint64_t mp = h.slot_marker_positions_offset, ms = h.slot_marker_states_offset;
  ASSERT_NE(mp, 0u);
  expectOpen("marker positions misaligned", [&] { h.slot_marker_positions_offset = mp + 4; },
             [&] { h.slot_marker_positions_offset = mp; }, TETRIG_SHM_E_SIZE);
  expectOpen("marker positions past the slot", [&] { h.slot_marker_positions_offset = stride; },
             [&] { h.slot_marker_positions_offset = mp; }, TETRIG_SHM_E_SIZE);
  expectOpen("marker states in the slot header", [&] { h.slot_marker_states_offset = 64; },
             [&] { h.slot_marker_states_offset = ms; }, TETRIG_SHM_E_SIZE);
  expectOpen("marker states past the slot", [&] { h.slot_marker_states_offset = stride; },
             [&] { h.slot_marker_states_offset = ms; }, TETRIG_SHM_E_SIZE);
  expectOpen("marker states over the marker positions", [&] { h.slot_marker_states_offset = mp; },
             [&] { h.slot_marker_states_offset = ms; }, TETRIG_SHM_E_SIZE);
  expectOpen("marker positions over the normals", [&] { h.slot_marker_positions_offset = normals_offset; },
             [&] { h.slot_marker_positions_offset = mp; }, TETRIG_SHM_E_SIZE);

  EXPECT_EQ(tetrig_shm_open(&r, uniqueName("absent").c_str()), TETRIG_SHM_E_NOT_FOUND);
  EXPECT_EQ(tetrig_shm_open(&r, "no_slash"), TETRIG_SHM_E_ARGUMENT);
  EXPECT_EQ(tetrig_shm_open(&r, std::string(300, 'a').insert(0, "/").c_str()), TETRIG_SHM_E_ARGUMENT);
  EXPECT_EQ(tetrig_shm_open(nullptr, name.c_str()), TETRIG_SHM_E_ARGUMENT);
  // an object smaller than the header: still being created
  const std::string tiny = uniqueName("tiny");
  NameGuard tiny_guard{tiny};
  ASSERT_TRUE(makeRawSegment(tiny, 100, [](unsigned char*) {}));
  EXPECT_EQ(tetrig_shm_open(&r, tiny.c_str()), TETRIG_SHM_E_NOT_READY);
}

TEST(Shm, PublisherRejectsBadArgumentsWithOneLine) {
  const Mesh mesh(4);
  const std::string name = uniqueName("bad");
  NameGuard guard{name};
  auto expectError = [&](const ShmPublisherOptions& o, std::int32_t v, const ShmStaticData& d, const char* needle) {
    try {
      ShmPublisher pub(o, v, d);
      ADD_FAILURE() << "no error for " << needle;
    } catch (const ShmError& e) {
      const std::string msg = e.what();
      EXPECT_NE(msg.find(needle), std::string::npos) << msg;
      EXPECT_EQ(msg.find('\n'), std::string::npos) << msg;
    }
    if (o.name == name) {
      TetrigShmReader r;
      EXPECT_EQ(tetrig_shm_open(&r, o.name.c_str()), TETRIG_SHM_E_NOT_FOUND) << "left behind: " << o.name;
    }
  };
  expectError(optionsFor("no_slash"), 4, mesh.data(), "'/'");
  expectError(optionsFor("/a/b"), 4, mesh.data(), "'/'");
  expectError(optionsFor("/"), 4, mesh.data(), "'/'");
  expectError(optionsFor(name, 2), 4, mesh.data(), "slot count");
  expectError(optionsFor(name, 65), 4, mesh.data(), "slot count");
  expectError(optionsFor(name), 0, mesh.data(), "vertex count");
  expectError(optionsFor(name), 5, mesh.data(), "rest positions");
  ShmPublisherOptions perms = optionsFor(name);
  perms.permissions = 0755;
  expectError(perms, 4, mesh.data(), "permissions");
  perms.permissions = 0400;
  expectError(perms, 4, mesh.data(), "permissions");
  Mesh bad = mesh;
  bad.triangles[5] = 4;
  expectError(optionsFor(name), 4, bad.data(), "triangle 1");
  bad.triangles[5] = -1;
  expectError(optionsFor(name), 4, bad.data(), "triangle 1");
  bad = mesh;
  bad.triangles.pop_back();
  expectError(optionsFor(name), 4, bad.data(), "multiple of 3");
  bad = mesh;
  bad.labels[1] = std::string("a\0b", 3);
  expectError(optionsFor(name), 4, bad.data(), "marker label");
  // the name is usable afterwards
  ShmPublisher ok(optionsFor(name), 4, mesh.data());
  EXPECT_EQ(ok.vertexCount(), 4);
}

// ---------------------------------------------------------------------------------------------
// The seqlock

TEST(Shm, AReadOfASlotBeingWrittenRetriesBoundedAndCounts) {
  const std::string name = uniqueName("odd_sequence");
  NameGuard guard{name};
  const Mesh mesh(4);
  ShmPublisher pub(optionsFor(name, 3), 4, mesh.data());
  publishPattern(pub);
  RawMapping raw(name);
  ASSERT_TRUE(raw.ok());
  auto& seq = *reinterpret_cast<std::uint64_t*>(raw.bytes() + raw.header().slots_offset);  // frame 1's slot
  ASSERT_EQ(seq, 2u);  // one complete write: 0 -> 1 -> 2
  TetrigShmReader r;
  ASSERT_EQ(tetrig_shm_open(&r, name.c_str()), TETRIG_SHM_OK);
  r.max_attempts = 5;
  std::vector<float> pos(12);
  seq = 3;  // the writer is (as if) inside this slot
  EXPECT_EQ(tetrig_shm_read_latest(&r, pos.data(), pos.size(), nullptr, 0, nullptr), TETRIG_SHM_BUSY);
  EXPECT_EQ(r.retries, 5u);
  EXPECT_EQ(r.busy, 1u);
  EXPECT_EQ(r.reads, 0u);
  seq = 4;  // complete again: read succeeds
  TetrigShmFrameInfo info{};
  EXPECT_EQ(tetrig_shm_read_latest(&r, pos.data(), pos.size(), nullptr, 0, &info), TETRIG_SHM_OK);
  EXPECT_TRUE(consistent(pos, nullptr, info));
  // a slot whose frame id does not belong to it (corrupt) is never returned
  auto* slot_info = reinterpret_cast<TetrigShmFrameInfo*>(raw.bytes() + raw.header().slots_offset + TETRIG_SHM_SLOT_INFO_OFFSET);
  slot_info->frame_id = 2;
  EXPECT_EQ(tetrig_shm_read_latest(&r, pos.data(), pos.size(), nullptr, 0, &info), TETRIG_SHM_BUSY);
  tetrig_shm_close(&r);
}

// One writer at full speed, four readers (two on the producer's own mapping, so ThreadSanitizer
// sees the same addresses; two on their own mappings by name): every frame a reader gets is
// consistent, ids never go backwards, readers see many distinct frames. Readers 0 and 1 make
// every 8th attempt wait in the middle of its copy until the writer has lapped the slot (the test
// hook above): the copy then holds frame k's info with a later frame's positions, so the torn
// read happens for certain, not only when the scheduler preempts a reader mid-copy; each such
// attempt must be discarded (retries >= forced laps) and no torn frame may come out. The writer publishes at least TETRIG_SHM_STRESS_FRAMES
// frames and goes on (up to 10x, 30 s) until every reader has seen kMinDistinct frames and each
// lapping reader was lapped, so a starved reader thread on a loaded machine does not fail the test.
TEST(Shm, ConcurrentReadersNeverSeeTornFrames) {
  const std::string name = uniqueName("stress");
  NameGuard guard{name};
  const int v = 256;
  Mesh mesh(v);
  mesh.labels.clear();
  for (int k = 0; k < 41; ++k) mesh.labels.push_back(std::to_string(k).insert(0, 1, 'M'));  // 41 markers: 492 + 41 bytes
  ShmPublisher pub(optionsFor(name, 3, true), v, mesh.data());  // 3 slots: lapped as soon as possible
  const std::uint64_t min_frames = TETRIG_SHM_STRESS_FRAMES;
  const std::uint64_t max_frames = 10 * min_frames;
  constexpr int kReaders = 4;
  constexpr std::uint64_t kMinDistinct = 1000;
  struct Stats {
    std::uint64_t reads = 0, torn = 0, backwards = 0, busy = 0, last = 0;
    std::atomic<std::uint64_t> distinct{0}, retries{0}, forced_laps{0};  // read by the writer while running
    bool open_failed = false;
  };
  std::vector<Stats> stats(kReaders);
  std::atomic<bool> done{false};
  std::atomic<int> started{0};
  std::vector<std::thread> readers;
  for (int t = 0; t < kReaders; ++t) {
    readers.emplace_back([&, t] {
      Stats& s = stats[static_cast<std::size_t>(t)];
      TetrigShmReader r;
      const int rc = t % 2 == 0 ? tetrig_shm_attach(&r, pub.segmentData(), pub.segmentSize())
                                : tetrig_shm_open(&r, name.c_str());
      if (rc != TETRIG_SHM_OK) s.open_failed = true;
      started.fetch_add(1);
      if (rc != TETRIG_SHM_OK) return;
      shm_test_hook::lap_every = t < 2 ? 8 : 0;
      std::vector<float> pos(static_cast<std::size_t>(v) * 3), nrm(static_cast<std::size_t>(v) * 3);
      std::vector<float> markers(41 * 3);
      std::vector<std::uint8_t> states(41);
      const bool with_markers = t == 1 || t == 2;  // one lapping and one plain reader read the marker block too
      TetrigShmFrameInfo info{};
      for (;;) {
        const bool finished = done.load(std::memory_order_acquire);
        const std::uint64_t latest = tetrig_shm_latest_frame_id(&r);
        if (latest > s.last) {
          const int got = with_markers ? tetrig_shm_read_latest_markers(&r, pos.data(), pos.size(), nrm.data(), nrm.size(),
                                                                        markers.data(), markers.size(), states.data(),
                                                                        states.size(), &info)
                                       : tetrig_shm_read_latest(&r, pos.data(), pos.size(), nrm.data(), nrm.size(), &info);
          if (got == TETRIG_SHM_OK) {
            ++s.reads;
            if (!consistent(pos, &nrm, info) || (with_markers && !markersConsistent(info.frame_id, markers, states))) ++s.torn;
            if (info.frame_id < s.last) ++s.backwards;
            if (info.frame_id > s.last) s.distinct.fetch_add(1, std::memory_order_relaxed);
            s.last = info.frame_id;
          }
          s.retries.store(r.retries, std::memory_order_relaxed);
          s.forced_laps.store(shm_test_hook::forced_laps, std::memory_order_relaxed);
        } else if (finished) {
          break;
        }
        // else: poll again at once. (No sched_yield: under the EEVDF scheduler a thread that
        // yields in a loop is pushed back behind every other runnable task and starves.)
      }
      s.busy = r.busy;
      s.retries.store(r.retries);
      s.forced_laps.store(shm_test_hook::forced_laps);
      shm_test_hook::lap_every = 0;
      tetrig_shm_close(&r);
    });
  }
  while (started.load() < kReaders) std::this_thread::yield();
  auto enough = [&] {
    for (int t = 0; t < kReaders; ++t) {
      const Stats& s = stats[static_cast<std::size_t>(t)];
      if (s.open_failed) continue;
      if (s.distinct.load(std::memory_order_relaxed) < kMinDistinct) return false;
      if (t < 2 && s.forced_laps.load(std::memory_order_relaxed) == 0) return false;
    }
    return true;
  };
  const auto t0 = std::chrono::steady_clock::now();
  std::uint64_t frames = 0;
  const auto give_up = t0 + std::chrono::seconds(30);
  while (frames < max_frames && (frames < min_frames || (frames % 1024 != 0 || !enough()))) {
    if (frames % 1024 == 0 && std::chrono::steady_clock::now() > give_up) break;
    publishPattern(pub);
    ++frames;
  }
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  done.store(true, std::memory_order_release);
  for (auto& th : readers) th.join();

  std::uint64_t retries = 0, forced = 0, busy = 0;
  for (int t = 0; t < kReaders; ++t) {
    const Stats& s = stats[static_cast<std::size_t>(t)];
    ASSERT_FALSE(s.open_failed) << "reader " << t;
    EXPECT_EQ(s.torn, 0u) << "reader " << t << " got inconsistent frames";
    EXPECT_EQ(s.backwards, 0u) << "reader " << t << " saw frame ids go backwards";
    EXPECT_EQ(s.last, frames) << "reader " << t << " did not end on the last frame";
    EXPECT_GE(s.distinct.load(), kMinDistinct) << "reader " << t;
    if (t < 2) {
      EXPECT_GT(s.forced_laps.load(), 0u) << "reader " << t << " was never lapped";
      EXPECT_GE(s.retries.load(), s.forced_laps.load()) << "reader " << t << " kept a copy the writer overlapped";
    }
    retries += s.retries.load();
    forced += s.forced_laps.load();
    busy += s.busy;
    std::cout << "[ stress   ] reader " << t << (t % 2 == 0 ? " (attached)" : " (by name) ") << ": " << s.reads
              << " reads, " << s.distinct.load() << " distinct frames, " << s.retries.load() << " retries ("
              << s.forced_laps.load() << " forced laps), " << s.busy << " busy\n";
  }
  std::cout << "[ stress   ] writer: " << frames << " frames of " << v << " vertices + normals in " << seconds << " s ("
            << static_cast<double>(frames) / seconds * 1e-6 << " M frames/s); " << retries << " retries ("
            << retries - forced << " unforced), " << busy << " busy in all\n";
  EXPECT_GT(retries, 0u) << "the torn-read path was never exercised";
}

TEST(Shm, CommitAndHeartbeatDoNotAllocate) {
  const std::string name = uniqueName("alloc");
  NameGuard guard{name};
  const Mesh mesh(64);
  ShmPublisher pub(optionsFor(name, 4, true), 64, mesh.data());
  publishPattern(pub);  // warm-up
  const std::uint64_t before = tetrig::test::allocationCount();
  for (int i = 0; i < 1000; ++i) {
    float* p = pub.beginPositions();
    float* n = pub.beginNormals();
    p[i % 192] = static_cast<float>(i);
    n[i % 192] = static_cast<float>(-i);
    pub.commit(infoFor(static_cast<std::uint64_t>(i)));
    pub.heartbeat(i % 2 ? ShmState::stale_source : ShmState::running);
  }
  EXPECT_EQ(tetrig::test::allocationCount(), before);
  EXPECT_EQ(pub.framesPublished(), 1001u);
  // readers do not allocate either
  TetrigShmReader r;
  ASSERT_EQ(tetrig_shm_attach(&r, pub.segmentData(), pub.segmentSize()), TETRIG_SHM_OK);
  std::vector<float> pos(192), nrm(192);
  TetrigShmFrameInfo info{};
  const std::uint64_t before_read = tetrig::test::allocationCount();
  for (int i = 0; i < 100; ++i) {
    ASSERT_EQ(tetrig_shm_read_latest(&r, pos.data(), pos.size(), nrm.data(), nrm.size(), &info), TETRIG_SHM_OK);
  }
  EXPECT_EQ(tetrig::test::allocationCount(), before_read);
  EXPECT_EQ(info.frame_id, 1001u);
}

// waitForCommit (the DDS bridge's wake-up): a sleeping follower wakes on the next commit, not at
// its timeout; with no commit it sleeps the timeout out; wakeCommitWaiters() ends the sleep early
// without a frame. Commits with a follower asleep allocate nothing.
TEST(Shm, WaitForCommitWakesOnTheNextCommit) {
  const std::string name = uniqueName("waitcommit");
  NameGuard guard{name};
  const Mesh mesh(16);
  ShmPublisher pub(optionsFor(name, 3, false), 16, mesh.data());
  using Clock = std::chrono::steady_clock;
  EXPECT_EQ(pub.latestFrameId(), 0u);
  EXPECT_FALSE(pub.waitForCommit(0, 0));
  // No commit: the whole timeout passes.
  auto t0 = Clock::now();
  EXPECT_FALSE(pub.waitForCommit(0, 30'000'000));
  EXPECT_GE(Clock::now() - t0, std::chrono::milliseconds(25));
  // A commit 50 ms into a 10 s wait ends it.
  std::atomic<bool> woke{false};
  std::atomic<std::int64_t> waited_ms{-1};
  std::thread follower([&] {
    const auto start = Clock::now();
    woke = pub.waitForCommit(0, 10'000'000'000);
    waited_ms = std::chrono::duration_cast<std::chrono::milliseconds>(Clock::now() - start).count();
  });
  std::this_thread::sleep_for(std::chrono::milliseconds(50));
  const std::uint64_t before = tetrig::test::allocationCount();
  pub.commit(infoFor(1));
  EXPECT_EQ(tetrig::test::allocationCount(), before);
  follower.join();
  EXPECT_TRUE(woke);
  EXPECT_LT(waited_ms.load(), 5000);
  EXPECT_EQ(pub.latestFrameId(), 1u);
  EXPECT_TRUE(pub.waitForCommit(0, 0));  // frame 1 is newer than 0: no sleep
  // wakeCommitWaiters ends a wait with no new frame.
  std::atomic<bool> done{false};
  std::thread stopped([&] {
    const auto start = Clock::now();
    woke = pub.waitForCommit(1, 10'000'000'000);
    waited_ms = std::chrono::duration_cast<std::chrono::milliseconds>(Clock::now() - start).count();
    done = true;
  });
  // Woken until it returns (a wake before the follower sleeps is not seen by it).
  while (!done) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    pub.wakeCommitWaiters();
  }
  stopped.join();
  EXPECT_FALSE(woke);
  EXPECT_LT(waited_ms.load(), 5000);
}

// ---------------------------------------------------------------------------------------------
// An untrusted segment: whoever can write it may rewrite any byte at any time

// One field of the segment header, rewritten by the tamper tests through their own mapping.
struct HeaderField {
  const char* name;
  std::size_t offset;
  std::size_t size;
  bool live;  // a live word the producer keeps rewriting (state, heartbeat, newest frame id)
};
#define TETRIG_HEADER_FIELD(f, live) \
  HeaderField { #f, offsetof(TetrigShmHeader, f), sizeof(TetrigShmHeader::f), live }

std::vector<HeaderField> everyHeaderField() {
  return {TETRIG_HEADER_FIELD(magic, false),
          TETRIG_HEADER_FIELD(version_major, false),
          TETRIG_HEADER_FIELD(version_minor, false),
          TETRIG_HEADER_FIELD(header_size, false),
          TETRIG_HEADER_FIELD(total_size, false),
          TETRIG_HEADER_FIELD(instance_id, false),
          TETRIG_HEADER_FIELD(start_unix_ns, false),
          TETRIG_HEADER_FIELD(start_monotonic_ns, false),
          TETRIG_HEADER_FIELD(producer_pid, false),
          TETRIG_HEADER_FIELD(flags, false),
          TETRIG_HEADER_FIELD(state, true),
          TETRIG_HEADER_FIELD(heartbeat_ns, true),
          TETRIG_HEADER_FIELD(latest_frame_id, true),
          TETRIG_HEADER_FIELD(vertex_count, false),
          TETRIG_HEADER_FIELD(triangle_count, false),
          TETRIG_HEADER_FIELD(slot_count, false),
          TETRIG_HEADER_FIELD(marker_count, false),
          TETRIG_HEADER_FIELD(rig_name_length, false),
          TETRIG_HEADER_FIELD(triangles_offset, false),
          TETRIG_HEADER_FIELD(rest_positions_offset, false),
          TETRIG_HEADER_FIELD(rig_name_offset, false),
          TETRIG_HEADER_FIELD(marker_labels_offset, false),
          TETRIG_HEADER_FIELD(marker_labels_size, false),
          TETRIG_HEADER_FIELD(slots_offset, false),
          TETRIG_HEADER_FIELD(slot_stride, false),
          TETRIG_HEADER_FIELD(slot_positions_offset, false),
          TETRIG_HEADER_FIELD(slot_normals_offset, false),
          TETRIG_HEADER_FIELD(slot_marker_positions_offset, false),
          TETRIG_HEADER_FIELD(slot_marker_states_offset, false)};
}
#undef TETRIG_HEADER_FIELD

std::uint64_t loadField(const unsigned char* header, const HeaderField& f) {
  switch (f.size) {
    case 2: return __atomic_load_n(reinterpret_cast<const std::uint16_t*>(header + f.offset), __ATOMIC_RELAXED);
    case 4: return __atomic_load_n(reinterpret_cast<const std::uint32_t*>(header + f.offset), __ATOMIC_RELAXED);
    default: return __atomic_load_n(reinterpret_cast<const std::uint64_t*>(header + f.offset), __ATOMIC_RELAXED);
  }
}

// An atomic store (the readers load these words concurrently), truncated to the field's width.
void storeField(unsigned char* header, const HeaderField& f, std::uint64_t value) {
  switch (f.size) {
    case 2:
      __atomic_store_n(reinterpret_cast<std::uint16_t*>(header + f.offset), static_cast<std::uint16_t>(value), __ATOMIC_RELAXED);
      break;
    case 4:
      __atomic_store_n(reinterpret_cast<std::uint32_t*>(header + f.offset), static_cast<std::uint32_t>(value), __ATOMIC_RELAXED);
      break;
    default: __atomic_store_n(reinterpret_cast<std::uint64_t*>(header + f.offset), value, __ATOMIC_RELAXED); break;
  }
}

// Hostile values for a field whose current value is `current` in a segment of `size` bytes: zero,
// one, small counts, the segment's size and beyond, the sign bits, all ones, and near misses of
// the true value (one alignment step either way, double, half).
std::vector<std::uint64_t> hostileValues(std::uint64_t current, std::uint64_t size) {
  return {0u,
          1u,
          2u,
          3u,
          65u,
          size - 64u,
          size,
          size + 4096u,
          std::uint64_t{1} << 31,
          0xFFFFFFFFu,
          std::uint64_t{1} << 63,
          ~std::uint64_t{0},
          current + 1u,
          current + 64u,
          current - 64u,
          current * 2u,
          current / 2u};
}

// Under ThreadSanitizer the tamper test's readers all open the segment by name: a layout opened
// while an offset was rewritten may point the reader's plain reads of static data (rig name,
// labels, triangles) at slot words the writer is storing, which TSan would report on the
// writer's own mapping; the ASan build runs the attached readers.
#if defined(__SANITIZE_THREAD__)
constexpr bool kThreadSanitizer = true;
#elif defined(__has_feature)
#if __has_feature(thread_sanitizer)
constexpr bool kThreadSanitizer = true;
#else
constexpr bool kThreadSanitizer = false;
#endif
#else
constexpr bool kThreadSanitizer = false;
#endif

// Readers in four threads (two on the producer's own mapping, two opening the segment by name,
// each re-opening every few reads) read while a writer publishes and the test rewrites every
// header field in turn through its own mapping, to every hostile value: slot_count 0 and huge,
// slots_offset and every other offset past the segment, slot_stride, vertex_count, the newest
// frame id huge, ... A reader must never crash (a SIGFPE or SIGSEGV kills this test), and each
// call must either return a frame that is exactly the one its info names, or an error code.
TEST(ShmTamper, ReadersSurviveEveryHeaderFieldRewrittenWhileTheyRead) {
  const std::string name = uniqueName("tamper");
  NameGuard guard{name};
  const int v = 64;
  const Mesh mesh(v);
  ShmPublisher pub(optionsFor(name, 4, true), v, mesh.data());
  publishPattern(pub);
  RawMapping raw(name);
  ASSERT_TRUE(raw.ok());
  const std::uint64_t size = pub.segmentSize();
  constexpr int kReaders = 4;
  struct Counts {
    std::atomic<std::uint64_t> loops{0};
    std::uint64_t ok = 0, wrong = 0, busy = 0, no_frame = 0, no_markers = 0, argument = 0, opened = 0, refused = 0;
    std::uint64_t unexpected = 0;
    int last_unexpected = 0;
  };
  std::vector<Counts> counts(kReaders);
  std::atomic<bool> done{false};
  std::atomic<bool> writing{true};
  std::thread writer([&] {
    while (writing.load(std::memory_order_relaxed)) {
      publishPattern(pub);
      std::this_thread::sleep_for(std::chrono::microseconds(100));
    }
  });
  std::vector<std::thread> readers;
  for (int t = 0; t < kReaders; ++t) {
    readers.emplace_back([&, t] {
      Counts& c = counts[static_cast<std::size_t>(t)];
      const std::size_t n = static_cast<std::size_t>(v) * 3;
      std::vector<float> pos(n), nrm(n), markers(mesh.labels.size() * 3);
      std::vector<std::uint8_t> states(mesh.labels.size());
      std::vector<std::uint32_t> triangles;
      TetrigShmReader r{};
      bool open = false;
      char text[64];
      for (std::uint64_t loop = 0; !done.load(std::memory_order_relaxed); ++loop) {
        if (!open || loop % 4 == 0) {  // (re)open: the checks at open run against a header being rewritten
          if (open) tetrig_shm_close(&r);
          const int rc = t % 2 == 0 && !kThreadSanitizer ? tetrig_shm_attach(&r, pub.segmentData(), pub.segmentSize())
                                                         : tetrig_shm_open(&r, name.c_str());
          open = rc == TETRIG_SHM_OK;
          if (open) {
            ++c.opened;
          } else if (rc == TETRIG_SHM_E_NOT_READY || rc == TETRIG_SHM_E_MAGIC || rc == TETRIG_SHM_E_VERSION ||
                     rc == TETRIG_SHM_E_SIZE) {
            ++c.refused;
          } else {
            ++c.unexpected;
            c.last_unexpected = rc;
          }
        }
        if (open) {
          TetrigShmFrameInfo info{};
          const int rc = loop % 2 == 0 ? tetrig_shm_read_latest_markers(&r, pos.data(), n, nrm.data(), n, markers.data(),
                                                                         markers.size(), states.data(), states.size(), &info)
                                       : tetrig_shm_read_latest(&r, pos.data(), n, nrm.data(), n, &info);
          switch (rc) {
            case TETRIG_SHM_OK:
              ++c.ok;
              if (!consistent(pos, &nrm, info) || (loop % 2 == 0 && !markersConsistent(info.frame_id, markers, states))) ++c.wrong;
              break;
            case TETRIG_SHM_BUSY: ++c.busy; break;
            case TETRIG_SHM_NO_FRAME: ++c.no_frame; break;
            case TETRIG_SHM_NO_MARKERS: ++c.no_markers; break;
            case TETRIG_SHM_E_ARGUMENT: ++c.argument; break;  // the header now claims more vertices than the buffers hold
            default:
              ++c.unexpected;
              c.last_unexpected = rc;
          }
          // every other accessor a consumer calls
          (void)tetrig_shm_state(&r);
          (void)tetrig_shm_latest_frame_id(&r);
          (void)tetrig_shm_producer_status(&r, 1'000'000'000);
          (void)tetrig_shm_heartbeat_age_ns(&r, tetrig_shm_now_ns());
          (void)tetrig_shm_heartbeat_age_ns(&r, std::numeric_limits<std::int64_t>::min());
          (void)tetrig_shm_copy_rig_name(&r, text, sizeof text);
          for (std::uint32_t k = 0; k <= tetrig_shm_marker_count(&r); ++k) {
            const char* label = tetrig_shm_marker_label(&r, k);
            if (label != nullptr) (void)std::strlen(label);
            (void)tetrig_shm_copy_marker_label(&r, k, text, sizeof text);
          }
          triangles.resize(std::size_t{tetrig_shm_triangle_count(&r)} * 3);
          if (tetrig_shm_copy_triangles(&r, triangles.data(), triangles.size()) == TETRIG_SHM_OK) {
            for (const std::uint32_t i : triangles) {
              if (i >= tetrig_shm_vertex_count(&r)) ++c.wrong;
            }
          }
          // the last rest coordinate (an atomic load: a layout opened mid-rewrite may place it in a slot)
          const auto* rest = reinterpret_cast<const std::uint32_t*>(tetrig_shm_rest_positions(&r));
          (void)__atomic_load_n(rest + std::size_t{tetrig_shm_vertex_count(&r)} * 3 - 1, __ATOMIC_RELAXED);
        }
        c.loops.fetch_add(1, std::memory_order_release);
      }
      if (open) tetrig_shm_close(&r);
    });
  }
  // Holds each value until every reader has gone round its loop a few times (or 100 ms).
  auto hold = [&](const HeaderField& f, std::uint64_t value) {
    std::uint64_t start[kReaders];
    for (int t = 0; t < kReaders; ++t) start[t] = counts[static_cast<std::size_t>(t)].loops.load(std::memory_order_acquire);
    const auto give_up = std::chrono::steady_clock::now() + std::chrono::milliseconds(100);
    for (;;) {
      storeField(raw.bytes(), f, value);  // again and again: the producer rewrites its live words
      bool all = true;
      for (int t = 0; t < kReaders; ++t) {
        all = all && counts[static_cast<std::size_t>(t)].loops.load(std::memory_order_acquire) >= start[t] + 6;
      }
      if (all || std::chrono::steady_clock::now() > give_up) return;
      std::this_thread::sleep_for(std::chrono::microseconds(50));
    }
  };
  std::size_t rewrites = 0;
  for (const HeaderField& f : everyHeaderField()) {
    const std::uint64_t original = loadField(raw.bytes(), f);
    for (const std::uint64_t value : hostileValues(original, size)) {
      hold(f, value);
      ++rewrites;
      if (!f.live) storeField(raw.bytes(), f, original);
    }
    if (f.offset == offsetof(TetrigShmHeader, state)) storeField(raw.bytes(), f, TETRIG_SHM_STATE_RUNNING);
  }
  done.store(true);
  for (auto& th : readers) th.join();
  writing.store(false);
  writer.join();

  std::uint64_t ok = 0;
  for (int t = 0; t < kReaders; ++t) {
    const Counts& c = counts[static_cast<std::size_t>(t)];
    EXPECT_EQ(c.wrong, 0u) << "reader " << t << " got frames that are not the frame their info names";
    EXPECT_EQ(c.unexpected, 0u) << "reader " << t << " got an unexpected code, last " << c.last_unexpected << " ("
                                << tetrig_shm_status_string(c.last_unexpected) << ")";
    EXPECT_GT(c.opened, 0u) << "reader " << t;
    EXPECT_GT(c.refused, 0u) << "reader " << t << " never saw a header it had to refuse";
    ok += c.ok;
    std::cout << "[ tamper   ] reader " << t << (t % 2 == 0 && !kThreadSanitizer ? " (attached)" : " (by name) ") << ": " << c.loops.load()
              << " loops, " << c.opened << " opens, " << c.refused << " refused, " << c.ok << " frames, " << c.busy << " busy, "
              << c.no_frame << " no frame, " << c.no_markers << " no markers, " << c.argument << " buffer too small\n";
  }
  std::cout << "[ tamper   ] " << rewrites << " header rewrites over " << everyHeaderField().size() << " fields, "
            << pub.framesPublished() << " frames published\n";
  EXPECT_GT(ok, 0u) << "no frame was read at all";
  // restored: a new reader reads the newest frame exactly
  publishPattern(pub);
  TetrigShmReader r;
  ASSERT_EQ(tetrig_shm_open(&r, name.c_str()), TETRIG_SHM_OK);
  std::vector<float> pos(static_cast<std::size_t>(v) * 3), nrm(pos.size());
  TetrigShmFrameInfo info{};
  ASSERT_EQ(tetrig_shm_read_latest(&r, pos.data(), pos.size(), nrm.data(), nrm.size(), &info), TETRIG_SHM_OK);
  EXPECT_EQ(info.frame_id, pub.framesPublished());
  EXPECT_TRUE(consistent(pos, &nrm, info));
  tetrig_shm_close(&r);
}

// A reader that opened the segment uses its own copies of the header's static fields: rewriting
// them afterwards changes nothing it reads (counts, layout, frames), and a heartbeat of any value
// gives an age without overflow.
TEST(ShmTamper, AnOpenReaderKeepsTheHeaderItChecked) {
  const std::string name = uniqueName("copies");
  NameGuard guard{name};
  const Mesh mesh(5);
  ShmPublisher pub(optionsFor(name, 3, true), 5, mesh.data());
  TetrigShmReader r;
  ASSERT_EQ(tetrig_shm_open(&r, name.c_str()), TETRIG_SHM_OK);
  RawMapping raw(name);
  ASSERT_TRUE(raw.ok());
  TetrigShmHeader& h = raw.header();
  h.slot_count = 0;
  h.vertex_count = 0xFFFFFFFFu;
  h.slots_offset = h.total_size + 4096;
  h.slot_stride = 1;
  h.slot_positions_offset = ~std::uint64_t{0};
  h.flags = 0;
  h.marker_count = 1000;
  h.triangle_count = 0xFFFFFFFFu;
  h.version_minor = 0;
  EXPECT_EQ(tetrig_shm_slot_count(&r), 3u);
  EXPECT_EQ(tetrig_shm_vertex_count(&r), 5u);
  EXPECT_EQ(tetrig_shm_triangle_count(&r), 3u);
  EXPECT_EQ(tetrig_shm_marker_count(&r), 3u);
  EXPECT_TRUE(tetrig_shm_has_normals(&r));
  EXPECT_EQ(tetrig_shm_has_marker_positions(&r), 1);
  for (std::uint64_t k = 1; k <= 5; ++k) {
    ASSERT_EQ(publishPattern(pub), k);
    std::vector<float> pos(15), nrm(15), markers(9);
    std::vector<std::uint8_t> states(3);
    TetrigShmFrameInfo info{};
    ASSERT_EQ(tetrig_shm_read_latest_markers(&r, pos.data(), 15, nrm.data(), 15, markers.data(), 9, states.data(), 3, &info),
              TETRIG_SHM_OK);
    EXPECT_EQ(info.frame_id, k);
    EXPECT_TRUE(consistent(pos, &nrm, info));
    EXPECT_TRUE(markersConsistent(k, markers, states));
  }
  // a newest frame id far beyond what was published: no slot holds it, so no frame comes back
  h.latest_frame_id = ~std::uint64_t{0};
  r.max_attempts = 3;
  std::vector<float> pos(15);
  EXPECT_EQ(tetrig_shm_read_latest(&r, pos.data(), 15, nullptr, 0, nullptr), TETRIG_SHM_BUSY);
  h.latest_frame_id = 0;
  EXPECT_EQ(tetrig_shm_read_latest(&r, pos.data(), 15, nullptr, 0, nullptr), TETRIG_SHM_NO_FRAME);
  // heartbeat ages: never beat -> INT64_MAX (stale); in the future -> 0; extreme values do not overflow
  const std::int64_t now = tetrig_shm_now_ns();
  h.heartbeat_ns = 0;
  EXPECT_EQ(tetrig_shm_heartbeat_age_ns(&r, now), std::numeric_limits<std::int64_t>::max());
  EXPECT_EQ(tetrig_shm_producer_status(&r, 1'000'000'000), TETRIG_SHM_PRODUCER_STALE);
  h.heartbeat_ns = std::numeric_limits<std::int64_t>::min();
  EXPECT_EQ(tetrig_shm_heartbeat_age_ns(&r, now), std::numeric_limits<std::int64_t>::max());
  h.heartbeat_ns = std::numeric_limits<std::int64_t>::max();
  EXPECT_EQ(tetrig_shm_heartbeat_age_ns(&r, now), 0);
  EXPECT_EQ(tetrig_shm_heartbeat_age_ns(&r, std::numeric_limits<std::int64_t>::min()), 0);
  h.heartbeat_ns = now - 5;
  EXPECT_EQ(tetrig_shm_heartbeat_age_ns(&r, now), 5);
  tetrig_shm_close(&r);
}

// The static data behind the header (triangles, rig name, labels) is checked at open; when it is
// rewritten later, the copying accessors still never read outside its block, always terminate
// text, and report triangle indices out of range in their copy.
TEST(ShmTamper, StaticDataRewrittenAfterOpenIsCopiedSafely) {
  const std::string name = uniqueName("static_rewrite");
  NameGuard guard{name};
  const Mesh mesh(5);
  ShmPublisher pub(optionsFor(name), 5, mesh.data());
  TetrigShmReader r;
  ASSERT_EQ(tetrig_shm_open(&r, name.c_str()), TETRIG_SHM_OK);
  std::vector<std::uint32_t> tris(9, 0xEEu);
  EXPECT_EQ(tetrig_shm_copy_triangles(&r, tris.data(), 8), TETRIG_SHM_E_ARGUMENT);
  EXPECT_EQ(tris, std::vector<std::uint32_t>(9, 0xEEu));
  ASSERT_EQ(tetrig_shm_copy_triangles(&r, tris.data(), 9), TETRIG_SHM_OK);
  for (std::size_t i = 0; i < 9; ++i) EXPECT_EQ(tris[i], static_cast<std::uint32_t>(mesh.triangles[i]));
  char text[64];
  ASSERT_EQ(tetrig_shm_copy_rig_name(&r, text, sizeof text), TETRIG_SHM_OK);
  EXPECT_STREQ(text, "test rig");
  ASSERT_EQ(tetrig_shm_copy_rig_name(&r, text, 5), TETRIG_SHM_OK);  // truncated, terminated
  EXPECT_STREQ(text, "test");
  ASSERT_EQ(tetrig_shm_copy_marker_label(&r, 1, text, sizeof text), TETRIG_SHM_OK);
  EXPECT_STREQ(text, "RFHD");
  EXPECT_EQ(tetrig_shm_copy_marker_label(&r, 3, text, sizeof text), TETRIG_SHM_E_SIZE);
  EXPECT_STREQ(text, "");

  RawMapping raw(name);
  ASSERT_TRUE(raw.ok());
  const TetrigShmHeader& h = raw.header();
  reinterpret_cast<std::uint32_t*>(raw.bytes() + h.triangles_offset)[4] = 0xFFFFFFFFu;
  EXPECT_EQ(tetrig_shm_copy_triangles(&r, tris.data(), 9), TETRIG_SHM_E_SIZE);
  // the rig name's block and the label block without any NUL
  std::memset(raw.bytes() + h.rig_name_offset, 'x', h.rig_name_length + 1);
  ASSERT_EQ(tetrig_shm_copy_rig_name(&r, text, sizeof text), TETRIG_SHM_OK);
  EXPECT_EQ(std::string(text), std::string(h.rig_name_length, 'x'));  // the name's bytes only, terminated
  std::memset(raw.bytes() + h.marker_labels_offset, 'y', h.marker_labels_size);
  for (std::uint32_t k = 0; k < 3; ++k) {
    EXPECT_EQ(tetrig_shm_marker_label(&r, k), nullptr) << k;
    EXPECT_EQ(tetrig_shm_copy_marker_label(&r, k, text, sizeof text), TETRIG_SHM_E_SIZE) << k;
    EXPECT_STREQ(text, "") << k;
  }
  tetrig_shm_close(&r);
}

// Changes the owner of segment `name` (needs root or CAP_CHOWN); false when not permitted.
bool chownSegment(const std::string& name, uid_t uid) {
  const int fd = shm_open(name.c_str(), O_RDWR, 0);
  if (fd < 0) return false;
  const bool ok = fchown(fd, uid, static_cast<gid_t>(-1)) == 0;
  close(fd);
  return ok;
}

bool chmodSegment(const std::string& name, mode_t mode) {
  const int fd = shm_open(name.c_str(), O_RDWR, 0);
  if (fd < 0) return false;
  const bool ok = fchmod(fd, mode) == 0;
  close(fd);
  return ok;
}

// A segment of another user (a squatter on the name, or another user's producer) is refused by
// default, naming its owner; tetrig_shm_open_as accepts exactly the user it is told.
TEST(ShmOwner, ASegmentOfAnotherUserIsRefusedUnlessThatOwnerIsAccepted) {
  const std::string name = uniqueName("owner");
  NameGuard guard{name};
  const Mesh mesh(4);
  ShmPublisher pub(optionsFor(name), 4, mesh.data());
  publishPattern(pub);
  TetrigShmReader r;
  ASSERT_EQ(tetrig_shm_open(&r, name.c_str()), TETRIG_SHM_OK);
  EXPECT_EQ(r.owner_uid, geteuid());
  EXPECT_EQ(r.mode, 0600u);
  tetrig_shm_close(&r);
  constexpr uid_t kOther = 12345;
  if (geteuid() == kOther) GTEST_SKIP() << "running as uid " << kOther;
  if (!chownSegment(name, kOther)) GTEST_SKIP() << "fchown of the segment not permitted (needs root or CAP_CHOWN)";

  EXPECT_EQ(tetrig_shm_open(&r, name.c_str()), TETRIG_SHM_E_OWNER);
  EXPECT_EQ(r.owner_uid, kOther);
  EXPECT_EQ(r.header, nullptr);  // nothing mapped
  EXPECT_STREQ(tetrig_shm_status_string(TETRIG_SHM_E_OWNER), "segment is owned by another user");
  tetrig_shm_close(&r);
  EXPECT_EQ(tetrig_shm_open_as(&r, name.c_str(), geteuid()), TETRIG_SHM_E_OWNER);
  EXPECT_EQ(tetrig_shm_open_as(&r, name.c_str(), kOther + 1), TETRIG_SHM_E_OWNER);
  ASSERT_EQ(tetrig_shm_open_as(&r, name.c_str(), kOther), TETRIG_SHM_OK);
  EXPECT_EQ(r.owner_uid, kOther);
  std::vector<float> pos(12);
  TetrigShmFrameInfo info{};
  ASSERT_EQ(tetrig_shm_read_latest(&r, pos.data(), pos.size(), nullptr, 0, &info), TETRIG_SHM_OK);
  EXPECT_TRUE(consistent(pos, nullptr, info));
  EXPECT_EQ(tetrig_shm_name_status(&r), TETRIG_SHM_NAME_SAME);
  tetrig_shm_close(&r);
  // a squatter's empty object is refused at once (not "still being created" forever)
  const std::string squat = uniqueName("squat");
  NameGuard squat_guard{squat};
  ASSERT_TRUE(makeRawSegment(squat, 0, [](unsigned char*) {}));
  ASSERT_TRUE(chownSegment(squat, kOther));
  EXPECT_EQ(tetrig_shm_open(&r, squat.c_str()), TETRIG_SHM_E_OWNER);
}

// A segment that group or others may write (anyone of them could rewrite or truncate it under its
// readers) is refused; read bits for them are fine. The publisher refuses to make one.
TEST(ShmOwner, ASegmentWritableByGroupOrOthersIsRefused) {
  const std::string name = uniqueName("mode");
  NameGuard guard{name};
  const Mesh mesh(4);
  ShmPublisher pub(optionsFor(name), 4, mesh.data());
  publishPattern(pub);
  TetrigShmReader r;
  for (const mode_t mode : {0620u, 0602u, 0660u, 0666u, 0622u}) {
    ASSERT_TRUE(chmodSegment(name, mode));
    EXPECT_EQ(tetrig_shm_open(&r, name.c_str()), TETRIG_SHM_E_MODE) << std::oct << mode;
    EXPECT_EQ(r.mode, mode) << std::oct << mode;
    EXPECT_EQ(r.header, nullptr);
    EXPECT_EQ(tetrig_shm_open_as(&r, name.c_str(), geteuid()), TETRIG_SHM_E_MODE) << std::oct << mode;
  }
  EXPECT_STRNE(tetrig_shm_status_string(TETRIG_SHM_E_MODE), "unknown status");
  for (const mode_t mode : {0600u, 0640u, 0644u}) {
    ASSERT_TRUE(chmodSegment(name, mode));
    ASSERT_EQ(tetrig_shm_open(&r, name.c_str()), TETRIG_SHM_OK) << std::oct << mode;
    tetrig_shm_close(&r);
  }
  for (const unsigned mode : {0620u, 0602u, 0660u, 0666u}) {
    const std::string wide = uniqueName("mode_wide");
    NameGuard wide_guard{wide};
    ShmPublisherOptions o = optionsFor(wide);
    o.permissions = mode;
    try {
      ShmPublisher refused(o, 4, mesh.data());
      ADD_FAILURE() << "permissions " << std::oct << mode << " accepted";
    } catch (const ShmError& e) {
      EXPECT_NE(std::string(e.what()).find("must not let group or others write"), std::string::npos) << e.what();
    }
    EXPECT_EQ(tetrig_shm_open(&r, wide.c_str()), TETRIG_SHM_E_NOT_FOUND) << "left behind";
  }
}

// An empty rig name (a string_view that may hold nullptr) is published as "" (UBSan: no null
// pointer reaches memcpy).
TEST(Shm, AnEmptyRigNameIsPublished) {
  const std::string name = uniqueName("noname");
  NameGuard guard{name};
  const Mesh mesh(4);
  ShmStaticData data = mesh.data();
  data.rig_name = std::string_view();
  ShmPublisher pub(optionsFor(name), 4, data);
  TetrigShmReader r;
  ASSERT_EQ(tetrig_shm_open(&r, name.c_str()), TETRIG_SHM_OK);
  EXPECT_STREQ(tetrig_shm_rig_name(&r), "");
  tetrig_shm_close(&r);
}

// ---------------------------------------------------------------------------------------------
// Lifetime, permissions, replacement

TEST(Shm, CleanShutdownMarksStoppedAndUnlinks) {
  const std::string name = uniqueName("shutdown");
  NameGuard guard{name};
  const Mesh mesh(3);
  TetrigShmReader r;
  {
    ShmPublisher pub(optionsFor(name), 3, mesh.data());
    publishPattern(pub);
    ASSERT_EQ(tetrig_shm_open(&r, name.c_str()), TETRIG_SHM_OK);
    EXPECT_EQ(tetrig_shm_name_status(&r), TETRIG_SHM_NAME_SAME);
    EXPECT_EQ(tetrig_shm_producer_status(&r, 1'000'000'000), TETRIG_SHM_PRODUCER_ALIVE);
  }
  EXPECT_EQ(tetrig_shm_state(&r), TETRIG_SHM_STATE_STOPPED);
  EXPECT_EQ(tetrig_shm_producer_status(&r, 1'000'000'000), TETRIG_SHM_PRODUCER_STOPPED);
  EXPECT_EQ(tetrig_shm_name_status(&r), TETRIG_SHM_NAME_GONE);
  TetrigShmReader again;
  EXPECT_EQ(tetrig_shm_open(&again, name.c_str()), TETRIG_SHM_E_NOT_FOUND);
  // the last frame stays readable through the old mapping
  std::vector<float> pos(9);
  TetrigShmFrameInfo info{};
  EXPECT_EQ(tetrig_shm_read_latest(&r, pos.data(), pos.size(), nullptr, 0, &info), TETRIG_SHM_OK);
  EXPECT_TRUE(consistent(pos, nullptr, info));
  tetrig_shm_close(&r);
}

mode_t segmentMode(const std::string& name) {
  const int fd = shm_open(name.c_str(), O_RDONLY, 0);
  if (fd < 0) return 0;
  struct stat st{};
  fstat(fd, &st);
  close(fd);
  return st.st_mode & 0777;
}

TEST(Shm, PermissionsAreOwnerOnlyByDefaultAndWidenedOnlyOnRequest) {
  const Mesh mesh(3);
  const std::string a = uniqueName("perm_default");
  NameGuard ga{a};
  const mode_t old_mask = umask(0);  // a permissive umask must not widen the default
  {
    ShmPublisher pub(optionsFor(a), 3, mesh.data());
    EXPECT_EQ(segmentMode(a), 0600u);
  }
  umask(0077);  // a strict umask must not narrow an explicit request
  const std::string b = uniqueName("perm_wide");
  NameGuard gb{b};
  {
    ShmPublisherOptions o = optionsFor(b);
    o.permissions = 0644;
    ShmPublisher pub(o, 3, mesh.data());
    EXPECT_EQ(segmentMode(b), 0644u);
  }
  umask(old_mask);
}

TEST(Shm, LiveProducerNameIsRefusedWithItsPid) {
  const std::string name = uniqueName("live");
  NameGuard guard{name};
  const Mesh mesh(3);
  ShmPublisher first(optionsFor(name), 3, mesh.data());
  publishPattern(first);
  try {
    ShmPublisher second(optionsFor(name), 3, mesh.data());
    FAIL() << "a running producer's name was taken over";
  } catch (const ShmError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("pid " + std::to_string(getpid())), std::string::npos) << msg;
    EXPECT_NE(msg.find(name), std::string::npos) << msg;
    EXPECT_NE(msg.find("running"), std::string::npos) << msg;
  }
  // the first producer is untouched
  TetrigShmReader r;
  ASSERT_EQ(tetrig_shm_open(&r, name.c_str()), TETRIG_SHM_OK);
  EXPECT_EQ(r.instance_id, first.instanceId());
  publishPattern(first);
  std::vector<float> pos(9);
  TetrigShmFrameInfo info{};
  ASSERT_EQ(tetrig_shm_read_latest(&r, pos.data(), pos.size(), nullptr, 0, &info), TETRIG_SHM_OK);
  EXPECT_EQ(info.frame_id, 2u);
  EXPECT_TRUE(consistent(pos, nullptr, info));
  tetrig_shm_close(&r);
}

TEST(Shm, StoppedSegmentIsReplacedAndTheOldProducerDoesNotUnlinkTheNewOne) {
  const std::string name = uniqueName("stopped");
  NameGuard guard{name};
  const Mesh mesh(3);
  auto old_pub = std::make_unique<ShmPublisher>(optionsFor(name), 3, mesh.data());
  TetrigShmReader old_reader;
  ASSERT_EQ(tetrig_shm_open(&old_reader, name.c_str()), TETRIG_SHM_OK);
  old_pub->heartbeat(ShmState::stopped);  // alive, but says it stopped
  ShmPublisher fresh(optionsFor(name), 3, mesh.data());
  EXPECT_NE(fresh.instanceId(), old_pub->instanceId());
  EXPECT_EQ(tetrig_shm_name_status(&old_reader), TETRIG_SHM_NAME_REPLACED);
  old_pub.reset();  // must leave the new segment's name alone
  TetrigShmReader r;
  ASSERT_EQ(tetrig_shm_open(&r, name.c_str()), TETRIG_SHM_OK);
  EXPECT_EQ(r.instance_id, fresh.instanceId());
  tetrig_shm_close(&r);
  tetrig_shm_close(&old_reader);
}

TEST(Shm, LeftoversOfACrashedCreationAreReplacedButForeignObjectsAreNot) {
  const Mesh mesh(3);
  // sized, magic 0, the pid of a dead process: a creator that crashed mid-way
  const std::string half = uniqueName("half");
  NameGuard gh{half};
  const pid_t dead = deadPid();
  ASSERT_TRUE(makeRawSegment(half, 4096, [&](unsigned char* m) {
    reinterpret_cast<TetrigShmHeader*>(m)->producer_pid = static_cast<std::int32_t>(dead);
  }));
  {
    ShmPublisher pub(optionsFor(half), 3, mesh.data());
    TetrigShmReader r;
    ASSERT_EQ(tetrig_shm_open(&r, half.c_str()), TETRIG_SHM_OK);
    EXPECT_EQ(r.instance_id, pub.instanceId());
    tetrig_shm_close(&r);
  }
  // magic 0 and the pid of a live process: being created, refused
  const std::string busy = uniqueName("creating");
  NameGuard gb{busy};
  ASSERT_TRUE(makeRawSegment(busy, 4096, [&](unsigned char* m) {
    reinterpret_cast<TetrigShmHeader*>(m)->producer_pid = static_cast<std::int32_t>(getpid());
  }));
  try {
    ShmPublisher pub(optionsFor(busy), 3, mesh.data());
    ADD_FAILURE() << "a segment being created was replaced";
  } catch (const ShmError& e) {
    EXPECT_NE(std::string(e.what()).find("being created by another producer (pid " + std::to_string(getpid())),
              std::string::npos)
        << e.what();
  }
  // size 0 (created, never sized) for longer than the grace period: abandoned, replaced
  const std::string empty = uniqueName("empty");
  NameGuard ge{empty};
  ASSERT_TRUE(makeRawSegment(empty, 0, [](unsigned char*) {}));
  { ShmPublisher pub(optionsFor(empty), 3, mesh.data()); }
  // somebody else's object under the name: refused and left in place
  const std::string foreign = uniqueName("foreign");
  NameGuard gf{foreign};
  ASSERT_TRUE(makeRawSegment(foreign, 4096, [](unsigned char* m) { std::memset(m, 0xAB, 4096); }));
  try {
    ShmPublisher pub(optionsFor(foreign), 3, mesh.data());
    ADD_FAILURE() << "a foreign object was replaced";
  } catch (const ShmError& e) {
    EXPECT_NE(std::string(e.what()).find("not a tetrig segment"), std::string::npos) << e.what();
  }
  RawMapping still(foreign);
  ASSERT_TRUE(still.ok());
  EXPECT_EQ(still.bytes()[100], 0xAB);
}

// ---------------------------------------------------------------------------------------------
// Processes

TEST(ShmProcess, KilledWriterIsSeenDeadAndANewProducerReplacesIt) {
  const std::string name = uniqueName("killed_writer");
  NameGuard guard{name};
  ChildWriter child;
  ASSERT_TRUE(startChildWriter(child, name, 10));
  TetrigShmReader r;
  ASSERT_EQ(tetrig_shm_open(&r, name.c_str()), TETRIG_SHM_OK);
  EXPECT_EQ(r.producer_pid, child.pid);
  EXPECT_EQ(r.instance_id, child.instance_id);
  ASSERT_TRUE(waitUntil([&] { return tetrig_shm_latest_frame_id(&r) >= 10; }, std::chrono::seconds(10)));
  std::vector<float> pos(30);
  TetrigShmFrameInfo info{};
  ASSERT_EQ(tetrig_shm_read_latest(&r, pos.data(), pos.size(), nullptr, 0, &info), TETRIG_SHM_OK);
  EXPECT_TRUE(consistent(pos, nullptr, info));
  EXPECT_EQ(tetrig_shm_producer_status(&r, 1'000'000'000), TETRIG_SHM_PRODUCER_ALIVE);

  // a live producer in another process: its name is refused, naming its pid
  const Mesh mesh(10);
  try {
    ShmPublisher intruder(optionsFor(name), 10, mesh.data());
    ADD_FAILURE() << "the live child's name was taken over";
  } catch (const ShmError& e) {
    EXPECT_NE(std::string(e.what()).find("pid " + std::to_string(child.pid)), std::string::npos) << e.what();
  }

  // slow, not dead: a stopped (SIGSTOP) producer is stale, then alive again
  constexpr std::int64_t kStaleNs = 100'000'000;
  ASSERT_EQ(kill(child.pid, SIGSTOP), 0);
  auto t0 = std::chrono::steady_clock::now();
  EXPECT_TRUE(waitUntil([&] { return tetrig_shm_producer_status(&r, kStaleNs) == TETRIG_SHM_PRODUCER_STALE; },
                        std::chrono::seconds(10)));
  const double stale_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_NE(tetrig_shm_producer_status(&r, kStaleNs), TETRIG_SHM_PRODUCER_DEAD);
  ASSERT_EQ(kill(child.pid, SIGCONT), 0);
  EXPECT_TRUE(waitUntil([&] { return tetrig_shm_producer_status(&r, kStaleNs) == TETRIG_SHM_PRODUCER_ALIVE; },
                        std::chrono::seconds(10)));

  // SIGKILL: dead (a zombie until reaped counts as dead)
  const std::uint64_t frames_before = tetrig_shm_latest_frame_id(&r);
  ASSERT_EQ(kill(child.pid, SIGKILL), 0);
  t0 = std::chrono::steady_clock::now();
  EXPECT_TRUE(waitUntil([&] { return tetrig_shm_producer_status(&r, 1'000'000'000) == TETRIG_SHM_PRODUCER_DEAD; },
                        std::chrono::seconds(5)));
  const double dead_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  int status = 0;
  ASSERT_EQ(waitpid(child.pid, &status, 0), child.pid);
  EXPECT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL);
  const pid_t old_pid = child.pid;
  child.pid = -1;
  EXPECT_EQ(tetrig_shm_producer_status(&r, 1'000'000'000), TETRIG_SHM_PRODUCER_DEAD);
  EXPECT_NE(tetrig_shm_state(&r), TETRIG_SHM_STATE_STOPPED);  // it never stopped cleanly
  EXPECT_GE(tetrig_shm_latest_frame_id(&r), frames_before);
  EXPECT_EQ(tetrig_shm_name_status(&r), TETRIG_SHM_NAME_SAME);  // the crashed segment is still there
  std::cout << "[ process  ] SIGSTOP seen stale (100 ms limit) after " << stale_ms << " ms; SIGKILL seen dead after "
            << dead_ms << " ms\n";

  // a new producer replaces the crashed one's segment
  ShmPublisher fresh(optionsFor(name), 10, mesh.data());
  EXPECT_EQ(tetrig_shm_name_status(&r), TETRIG_SHM_NAME_REPLACED);
  TetrigShmReader r2;
  ASSERT_EQ(tetrig_shm_open(&r2, name.c_str()), TETRIG_SHM_OK);
  EXPECT_NE(r2.instance_id, r.instance_id);
  EXPECT_EQ(r2.instance_id, fresh.instanceId());
  EXPECT_EQ(r2.producer_pid, getpid());
  EXPECT_NE(r2.producer_pid, old_pid);
  EXPECT_EQ(tetrig_shm_latest_frame_id(&r2), 0u);  // frame ids restart with the instance
  // the old mapping still holds the crashed producer's last frame, consistent
  ASSERT_EQ(tetrig_shm_read_latest(&r, pos.data(), pos.size(), nullptr, 0, &info), TETRIG_SHM_OK);
  EXPECT_TRUE(consistent(pos, nullptr, info));
  tetrig_shm_close(&r2);
  tetrig_shm_close(&r);
}

TEST(ShmProcess, ReaderKilledMidReadLeavesTheWriterUnaffected) {
  const std::string name = uniqueName("killed_reader");
  NameGuard guard{name};
  const int v = 256;
  const Mesh mesh(v);
  ShmPublisher pub(optionsFor(name, 3, true), v, mesh.data());
  publishPattern(pub);
  int fds[2];
  ASSERT_EQ(pipe2(fds, O_CLOEXEC), 0);
  const pid_t pid = fork();  // no other thread runs at this point
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    close(fds[0]);
    TetrigShmReader r;
    if (tetrig_shm_open(&r, name.c_str()) != TETRIG_SHM_OK) _exit(2);
    std::vector<float> pos(static_cast<std::size_t>(v) * 3), nrm(pos.size());
    TetrigShmFrameInfo info{};
    std::uint64_t good = 0;
    for (;;) {  // reads as fast as it can until killed
      if (tetrig_shm_read_latest(&r, pos.data(), pos.size(), nrm.data(), nrm.size(), &info) == TETRIG_SHM_OK) {
        const unsigned char verdict = consistent(pos, &nrm, info) ? 'k' : 'x';
        if (verdict == 'x' || ++good == 2000) (void)!write(fds[1], &verdict, 1);
      }
    }
  }
  close(fds[1]);
  std::atomic<bool> stop{false};
  std::thread writer([&] {
    while (!stop.load(std::memory_order_relaxed)) publishPattern(pub);
  });
  const int verdict = readByte(fds[0], 20000);
  EXPECT_EQ(verdict, 'k') << "the reader child did not report 2000 consistent reads";
  std::this_thread::sleep_for(std::chrono::milliseconds(20));  // it keeps looping
  ASSERT_EQ(kill(pid, SIGKILL), 0);
  int status = 0;
  ASSERT_EQ(waitpid(pid, &status, 0), pid);
  EXPECT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL);
  close(fds[0]);
  // the writer goes on; its frames stay complete and readable
  TetrigShmReader r;
  ASSERT_EQ(tetrig_shm_attach(&r, pub.segmentData(), pub.segmentSize()), TETRIG_SHM_OK);
  const std::uint64_t at_kill = tetrig_shm_latest_frame_id(&r);
  EXPECT_TRUE(waitUntil([&] { return tetrig_shm_latest_frame_id(&r) > at_kill + 1000; }, std::chrono::seconds(20)));
  stop.store(true);
  writer.join();
  std::vector<float> pos(static_cast<std::size_t>(v) * 3), nrm(pos.size());
  TetrigShmFrameInfo info{};
  ASSERT_EQ(tetrig_shm_read_latest(&r, pos.data(), pos.size(), nrm.data(), nrm.size(), &info), TETRIG_SHM_OK);
  EXPECT_EQ(info.frame_id, pub.framesPublished());
  EXPECT_TRUE(consistent(pos, &nrm, info));
  EXPECT_EQ(tetrig_shm_state(&r), TETRIG_SHM_STATE_RUNNING);
  std::cout << "[ process  ] writer at frame " << at_kill << " when the reader was killed, " << pub.framesPublished()
            << " at the end\n";
  tetrig_shm_close(&r);
}

// ---------------------------------------------------------------------------------------------
// The C consumer (tools/tetrig_shm_cat.c)

#ifdef TETRIG_SHM_CAT_PATH

struct CatRun {
  pid_t pid = -1;
  std::unique_ptr<tetrig::test::TempDir> tmp;  // a fresh private directory (tests/support/temp_dir.hpp), removed last
  std::filesystem::path dir;
  int exit_code = -1;
  ~CatRun() {
    if (pid > 0) {
      kill(pid, SIGKILL);
      waitpid(pid, nullptr, 0);
    }
  }
  [[nodiscard]] std::filesystem::path file(const std::string& f) const { return dir / f; }
  [[nodiscard]] std::string read(const std::string& f) const {
    std::ifstream in(file(f), std::ios::binary);
    std::stringstream ss;
    ss << in.rdbuf();
    return ss.str();
  }
  // Non-blocking: true once the consumer has exited (exit_code set).
  bool exited() {
    if (pid <= 0) return true;
    int status = 0;
    if (waitpid(pid, &status, WNOHANG) != pid) return false;
    exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
    pid = -1;
    return true;
  }
  int frameLines() const {
    std::istringstream in(read("out.txt"));
    std::string line;
    int n = 0;
    while (std::getline(in, line)) n += line.rfind("frame ", 0) == 0 ? 1 : 0;
    return n;
  }
};

::testing::AssertionResult spawnCat(CatRun& run, const std::vector<std::string>& args) {
  run.tmp = std::make_unique<tetrig::test::TempDir>("tetrig-shm-cat");
  run.dir = run.tmp->path();
  std::vector<std::string> all{TETRIG_SHM_CAT_PATH};
  for (const auto& a : args) all.push_back(a == "@dump" ? run.file("dump.bin").string() : a == "@json" ? run.file("out.json").string() : a);
  std::vector<char*> argv;
  for (auto& a : all) argv.push_back(a.data());
  argv.push_back(nullptr);
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  const std::string out = run.file("out.txt").string(), err = run.file("err.txt").string();
  posix_spawn_file_actions_addopen(&actions, 1, out.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0600);
  posix_spawn_file_actions_addopen(&actions, 2, err.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0600);
  const int rc = posix_spawn(&run.pid, all[0].c_str(), &actions, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  if (rc != 0) return ::testing::AssertionFailure() << "posix_spawn " << all[0] << ": " << std::strerror(rc);
  return ::testing::AssertionSuccess();
}

using tetrig::test::DumpRecord;
using tetrig::test::parseDump;

// The number after "key": in the consumer's JSON (first occurrence), or NaN.
double jsonNumber(const std::string& json, const std::string& key) {
  const std::size_t at = json.find("\"" + key + "\":");
  if (at == std::string::npos) return std::nan("");
  return std::strtod(json.c_str() + at + key.size() + 3, nullptr);
}
std::string jsonObject(const std::string& json, const std::string& key) {
  const std::size_t at = json.find("\"" + key + "\":");
  if (at == std::string::npos) return {};
  return json.substr(at, json.find('}', at) - at + 1);
}

bool exactPattern(const DumpRecord& rec) {
  for (std::size_t i = 0; i < rec.positions.size(); ++i) {
    const float want = positionValue(rec.frame_id, i);
    if (std::memcmp(&rec.positions[i], &want, sizeof want) != 0) return false;
  }
  return true;
}

// Publishes frames every `period` (stamping receive_ns) until the consumer exits or 30 s pass.
void publishUntilExit(ShmPublisher& pub, CatRun& cat, std::chrono::microseconds period) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::seconds(30);
  while (!cat.exited() && std::chrono::steady_clock::now() < end) {
    const std::uint64_t id = pub.framesPublished() + 1;
    const std::size_t n = static_cast<std::size_t>(pub.vertexCount()) * 3;
    float* p = pub.beginPositions();
    for (std::size_t i = 0; i < n; ++i) p[i] = positionValue(id, i);
    if (float* m = pub.beginMarkerPositions()) {
      const auto markers = static_cast<std::size_t>(pub.markerCount());
      for (std::size_t i = 0; i < markers * 3; ++i) m[i] = markerValue(id, i);
      for (std::size_t k = 0; k < markers; ++k) pub.beginMarkerStates()[k] = markerStateValue(id, k);
    }
    ShmFrameInfo info = infoFor(id);
    info.receive_ns = tetrig::monotonicNowNs() - 50'000;  // "received" 50 us ago
    pub.commit(info);
    std::this_thread::sleep_for(period);
  }
}

TEST(ShmCat, PrintsFramesAndDumpsThemBitForBit) {
  const std::string name = uniqueName("cat");
  NameGuard guard{name};
  const int v = 50;
  const Mesh mesh(v);
  ShmPublisher pub(optionsFor(name), v, mesh.data());
  CatRun cat;
  ASSERT_TRUE(spawnCat(cat, {name, "--frames", "40", "--timeout-ms", "10000", "--dump", "@dump", "--json", "@json",
                             "--poll-us", "50"}));
  publishUntilExit(pub, cat, std::chrono::microseconds(1000));
  ASSERT_TRUE(cat.exited());
  EXPECT_EQ(cat.exit_code, 0) << cat.read("err.txt");

  // stdout: one line per frame, ids increasing
  std::istringstream out(cat.read("out.txt"));
  std::string line;
  std::vector<std::uint64_t> printed;
  while (std::getline(out, line)) {
    ASSERT_EQ(line.rfind("frame ", 0), 0u) << line;
    EXPECT_NE(line.find(" recv->pub "), std::string::npos) << line;
    EXPECT_NE(line.find(" pub->seen "), std::string::npos) << line;
    const std::uint64_t id = std::stoull(line.substr(6));
    std::ostringstream expect_source;
    expect_source << "source " << id * 3 + 1 << " iter " << id % 17;
    EXPECT_NE(line.find(expect_source.str()), std::string::npos) << line;
    if (!printed.empty()) {
      EXPECT_GT(id, printed.back());
    }
    printed.push_back(id);
  }
  EXPECT_EQ(printed.size(), 40u);

  // --dump: every frame bit for bit, the publisher's instance, the same ids as printed
  bool ok = false;
  const std::vector<DumpRecord> dump = parseDump(cat.read("dump.bin"), ok);
  ASSERT_TRUE(ok) << "malformed dump";
  ASSERT_EQ(dump.size(), 40u);
  std::uint64_t missed = 0;
  for (std::size_t k = 0; k < dump.size(); ++k) {
    EXPECT_EQ(dump[k].instance, pub.instanceId());
    EXPECT_EQ(dump[k].positions.size(), static_cast<std::size_t>(v) * 3);
    EXPECT_TRUE(exactPattern(dump[k])) << "frame " << dump[k].frame_id;
    EXPECT_EQ(dump[k].frame_id, printed[k]);
    if (k > 0) missed += dump[k].frame_id - dump[k - 1].frame_id - 1;
  }

  // --json: counts and latency percentiles
  const std::string json = cat.read("out.json");
  EXPECT_EQ(jsonNumber(json, "frames_seen"), 40.0) << json;
  EXPECT_EQ(jsonNumber(json, "frames_missed"), static_cast<double>(missed)) << json;
  EXPECT_EQ(jsonNumber(json, "instances"), 1.0) << json;
  const std::string recv = jsonObject(json, "receive_to_published");
  const std::string seen = jsonObject(json, "published_to_seen");
  const std::string total = jsonObject(json, "receive_to_seen");
  EXPECT_EQ(jsonNumber(recv, "count"), 40.0) << json;
  EXPECT_EQ(jsonNumber(seen, "count"), 40.0) << json;
  EXPECT_EQ(jsonNumber(total, "count"), 40.0) << json;
  // per frame receive->seen = receive->published + published->seen, so every percentile dominates
  EXPECT_GE(jsonNumber(total, "p50"), jsonNumber(recv, "p50") - 0.001) << json;
  EXPECT_GE(jsonNumber(total, "max"), jsonNumber(seen, "max") + 50.0 - 0.001) << json;
  const double p50 = jsonNumber(recv, "p50"), p99 = jsonNumber(recv, "p99"), mx = jsonNumber(recv, "max");
  EXPECT_GE(p50, 50.0) << json;  // receive was stamped 50 us before the commit
  EXPECT_LE(p50, p99);
  EXPECT_LE(p99, mx);
  const double s50 = jsonNumber(seen, "p50"), s99 = jsonNumber(seen, "p99"), smax = jsonNumber(seen, "max");
  EXPECT_GE(s50, 0.0);
  EXPECT_LE(s50, s99);
  EXPECT_LE(s99, smax);
  std::cout << "[ cat      ] receive->publish p50 " << p50 << " us; publish->seen p50 " << s50 << " us, p99 " << s99
            << " us, max " << smax << " us (poll 50 us, 2 shared cores); missed " << missed << "\n";
}

// --markers: under each frame line one line per marker (label, state, position printed exactly
// with %.9g), belonging to that frame; a segment without the block gets one note and no lines.
TEST(ShmCat, PrintsEachFramesMarkersWithMarkers) {
  const std::string name = uniqueName("cat_markers");
  NameGuard guard{name};
  const Mesh mesh(10);
  ShmPublisher pub(optionsFor(name), 10, mesh.data());
  CatRun cat;
  ASSERT_TRUE(spawnCat(cat, {name, "--frames", "10", "--timeout-ms", "10000", "--markers", "--poll-us", "50"}));
  publishUntilExit(pub, cat, std::chrono::microseconds(1000));
  ASSERT_TRUE(cat.exited());
  EXPECT_EQ(cat.exit_code, 0) << cat.read("err.txt");
  std::istringstream out(cat.read("out.txt"));
  std::string line;
  std::uint64_t id = 0;
  std::size_t frames = 0, marker_lines = 0, k = 0;
  static const char* const kStates[4] = {"unknown", "measured", "predicted", "blended"};
  while (std::getline(out, line)) {
    if (line.rfind("frame ", 0) == 0) {
      if (frames > 0) {
        EXPECT_EQ(k, 3u) << "frame " << id << " had " << k << " marker lines";
      }
      id = std::stoull(line.substr(6));
      ++frames;
      k = 0;
      continue;
    }
    ASSERT_EQ(line.rfind("  marker ", 0), 0u) << line;
    ASSERT_LT(k, 3u) << line;
    std::istringstream fields(line.substr(9));
    std::string label, state, x, y, z;
    fields >> label >> state >> x >> y >> z;
    EXPECT_EQ(label, mesh.labels[k]) << line;
    EXPECT_EQ(state, kStates[markerStateValue(id, k)]) << line;
    EXPECT_EQ(std::strtof(x.c_str(), nullptr), markerValue(id, 3 * k)) << line;
    EXPECT_EQ(std::strtof(y.c_str(), nullptr), markerValue(id, 3 * k + 1)) << line;
    EXPECT_EQ(std::strtof(z.c_str(), nullptr), markerValue(id, 3 * k + 2)) << line;
    ++k;
    ++marker_lines;
  }
  EXPECT_EQ(k, 3u);
  EXPECT_EQ(frames, 10u);
  EXPECT_EQ(marker_lines, 30u);

  // without the block: a note on stderr, frame lines only
  const std::string plain = uniqueName("cat_nomarkers");
  NameGuard plain_guard{plain};
  ShmPublisherOptions o = optionsFor(plain);
  o.marker_positions = false;
  ShmPublisher without(o, 10, mesh.data());
  CatRun cat2;
  ASSERT_TRUE(spawnCat(cat2, {plain, "--frames", "3", "--timeout-ms", "10000", "--markers", "--poll-us", "50"}));
  publishUntilExit(without, cat2, std::chrono::microseconds(1000));
  ASSERT_TRUE(cat2.exited());
  EXPECT_EQ(cat2.exit_code, 0) << cat2.read("err.txt");
  EXPECT_NE(cat2.read("err.txt").find("has no marker positions (layout 1.1, 3 marker labels)"), std::string::npos)
      << cat2.read("err.txt");
  EXPECT_EQ(cat2.read("out.txt").find("marker"), std::string::npos) << cat2.read("out.txt");
  EXPECT_EQ(cat2.frameLines(), 3);
}

TEST(ShmCat, ExitsZeroWhenTheProducerStopsCleanly) {
  const std::string name = uniqueName("cat_stop");
  NameGuard guard{name};
  const Mesh mesh(8);
  auto pub = std::make_unique<ShmPublisher>(optionsFor(name), 8, mesh.data());
  CatRun cat;
  ASSERT_TRUE(spawnCat(cat, {name, "--timeout-ms", "10000"}));
  ASSERT_TRUE(waitUntil(
      [&] {
        publishPattern(*pub);
        return cat.frameLines() >= 3 || cat.exited();
      },
      std::chrono::seconds(20)));
  pub.reset();
  ASSERT_TRUE(waitUntil([&] { return cat.exited(); }, std::chrono::seconds(20)));
  EXPECT_EQ(cat.exit_code, 0) << cat.read("err.txt");
  EXPECT_NE(cat.read("err.txt").find("stopped cleanly"), std::string::npos) << cat.read("err.txt");
}

TEST(ShmCat, FailsWithAMessageOnTimeoutAndOnADeadProducer) {
  {
    CatRun cat;
    ASSERT_TRUE(spawnCat(cat, {uniqueName("never"), "--timeout-ms", "200"}));
    ASSERT_TRUE(waitUntil([&] { return cat.exited(); }, std::chrono::seconds(20)));
    EXPECT_EQ(cat.exit_code, 2);
    EXPECT_NE(cat.read("err.txt").find("timed out"), std::string::npos) << cat.read("err.txt");
  }
  const std::string name = uniqueName("cat_dead");
  NameGuard guard{name};
  ChildWriter child;
  ASSERT_TRUE(startChildWriter(child, name, 8, 0, 1000));
  CatRun cat;
  ASSERT_TRUE(spawnCat(cat, {name, "--timeout-ms", "10000"}));
  ASSERT_TRUE(waitUntil([&] { return cat.frameLines() >= 2 || cat.exited(); }, std::chrono::seconds(20)));
  const std::string pid_text = std::to_string(child.pid);
  ASSERT_EQ(kill(child.pid, SIGKILL), 0);
  waitpid(child.pid, nullptr, 0);
  child.pid = -1;
  ASSERT_TRUE(waitUntil([&] { return cat.exited(); }, std::chrono::seconds(20)));
  EXPECT_EQ(cat.exit_code, 3) << cat.read("err.txt");
  const std::string err = cat.read("err.txt");
  EXPECT_NE(err.find("producer pid " + pid_text + " died"), std::string::npos) << err;
}

TEST(ShmCat, FollowsARestartedProducerAndSaysSo) {
  const std::string name = uniqueName("cat_restart");
  NameGuard guard{name};
  const int v = 12;
  ChildWriter child;
  ASSERT_TRUE(startChildWriter(child, name, v, 3, 5000));  // 3 frames, then heartbeats only
  CatRun cat;
  ASSERT_TRUE(spawnCat(cat, {name, "--follow", "--frames", "8", "--timeout-ms", "10000", "--dump", "@dump"}));
  ASSERT_TRUE(waitUntil([&] { return cat.frameLines() >= 1 || cat.exited(); }, std::chrono::seconds(20)));
  std::this_thread::sleep_for(std::chrono::milliseconds(50));  // all three frames are out
  const std::uint64_t old_instance = child.instance_id;
  ASSERT_EQ(kill(child.pid, SIGKILL), 0);
  waitpid(child.pid, nullptr, 0);
  child.pid = -1;
  const Mesh mesh(v);
  ShmPublisher fresh(optionsFor(name), v, mesh.data());  // replaces the crashed segment
  publishUntilExit(fresh, cat, std::chrono::microseconds(2000));
  ASSERT_TRUE(cat.exited());
  EXPECT_EQ(cat.exit_code, 0) << cat.read("err.txt");
  const std::string err = cat.read("err.txt");
  EXPECT_NE(err.find("producer restarted"), std::string::npos) << err;
  bool ok = false;
  const std::vector<DumpRecord> dump = parseDump(cat.read("dump.bin"), ok);
  ASSERT_TRUE(ok);
  ASSERT_EQ(dump.size(), 8u);
  std::size_t from_old = 0;
  while (from_old < dump.size() && dump[from_old].instance == old_instance) ++from_old;
  EXPECT_GE(from_old, 1u);
  EXPECT_LE(from_old, 3u);
  for (std::size_t k = 0; k < dump.size(); ++k) {
    EXPECT_EQ(dump[k].instance, k < from_old ? old_instance : fresh.instanceId()) << k;
    EXPECT_TRUE(exactPattern(dump[k])) << k;
  }
}

// What an unprivileged user could do to a segment made with --shm-mode 666 (slot_count 0 gave
// tetrig-shm-cat a SIGFPE, slots_offset past the end a SIGSEGV): every header field rewritten to
// every hostile value, twice over, while the consumer reads (all but `state`, whose "stopped"
// would end it early). It keeps printing exact frames, then exits 0 when the producer stops.
TEST(ShmCat, SurvivesItsSegmentsHeaderRewrittenWhileItReads) {
  const std::string name = uniqueName("cat_tamper");
  NameGuard guard{name};
  const int v = 50;
  const Mesh mesh(v);
  auto pub = std::make_unique<ShmPublisher>(optionsFor(name, 4, true), v, mesh.data());
  const std::uint64_t instance = pub->instanceId();
  std::atomic<bool> writing{true};
  std::thread writer([&] {
    while (writing.load(std::memory_order_relaxed)) {
      publishPattern(*pub);
      std::this_thread::sleep_for(std::chrono::microseconds(300));
    }
  });
  CatRun cat;
  ASSERT_TRUE(spawnCat(cat, {name, "--timeout-ms", "20000", "--dump", "@dump", "--markers", "--poll-us", "50"}));
  ASSERT_TRUE(waitUntil([&] { return cat.frameLines() >= 1 || cat.exited(); }, std::chrono::seconds(20)));  // opened
  RawMapping raw(name);
  ASSERT_TRUE(raw.ok());
  const std::uint64_t size = pub->segmentSize();
  std::size_t rewrites = 0;
  for (int cycle = 0; cycle < 2 && !cat.exited(); ++cycle) {
    for (const HeaderField& f : everyHeaderField()) {
      if (f.offset == offsetof(TetrigShmHeader, state)) continue;
      const std::uint64_t original = loadField(raw.bytes(), f);
      for (const std::uint64_t value : hostileValues(original, size)) {
        storeField(raw.bytes(), f, value);
        std::this_thread::sleep_for(std::chrono::microseconds(500));
        ++rewrites;
      }
      if (!f.live) storeField(raw.bytes(), f, original);
    }
  }
  const int frames_during = cat.frameLines();
  EXPECT_FALSE(cat.exited()) << "exit " << cat.exit_code << " while the header was rewritten: " << cat.read("err.txt");
  writing.store(false);
  writer.join();
  pub.reset();  // clean stop: the consumer exits 0
  ASSERT_TRUE(waitUntil([&] { return cat.exited(); }, std::chrono::seconds(20)));
  EXPECT_EQ(cat.exit_code, 0) << cat.read("err.txt");  // 136 = killed by SIGFPE, 139 = SIGSEGV
  EXPECT_NE(cat.read("err.txt").find("stopped cleanly"), std::string::npos) << cat.read("err.txt");
  bool ok = false;
  const std::vector<DumpRecord> dump = parseDump(cat.read("dump.bin"), ok);
  ASSERT_TRUE(ok) << "malformed dump";
  EXPECT_GE(dump.size(), 100u);
  for (std::size_t k = 0; k < dump.size(); ++k) {
    EXPECT_EQ(dump[k].instance, instance);
    EXPECT_EQ(dump[k].positions.size(), static_cast<std::size_t>(v) * 3);
    EXPECT_TRUE(exactPattern(dump[k])) << "frame " << dump[k].frame_id;
    if (k > 0) {
      EXPECT_GT(dump[k].frame_id, dump[k - 1].frame_id);
    }
  }
  EXPECT_EQ(static_cast<std::size_t>(cat.frameLines()), dump.size());
  std::cout << "[ cat      ] " << rewrites << " header rewrites while the consumer read " << frames_during << " frames ("
            << dump.size() << " in all)\n";
}

// A segment of another user is refused with its owner named, unless --owner accepts that user;
// a segment that group or others may write is refused either way.
TEST(ShmCat, RefusesAnotherUsersSegmentUnlessToldItsOwner) {
  const std::string name = uniqueName("cat_owner");
  NameGuard guard{name};
  const Mesh mesh(8);
  ShmPublisher pub(optionsFor(name), 8, mesh.data());
  publishPattern(pub);
  constexpr uid_t kOther = 12345;
  if (geteuid() == kOther) GTEST_SKIP() << "running as uid " << kOther;
  if (!chownSegment(name, kOther)) GTEST_SKIP() << "fchown of the segment not permitted (needs root or CAP_CHOWN)";
  {
    CatRun cat;
    ASSERT_TRUE(spawnCat(cat, {name, "--timeout-ms", "10000"}));
    ASSERT_TRUE(waitUntil([&] { return cat.exited(); }, std::chrono::seconds(20)));
    EXPECT_EQ(cat.exit_code, 4) << cat.read("err.txt");
    const std::string err = cat.read("err.txt");
    EXPECT_NE(err.find("belongs to uid 12345, not " + std::to_string(geteuid())), std::string::npos) << err;
    EXPECT_NE(err.find("--owner 12345"), std::string::npos) << err;
    EXPECT_EQ(cat.frameLines(), 0);
  }
  {
    CatRun cat;
    ASSERT_TRUE(spawnCat(cat, {name, "--owner", "12345", "--frames", "5", "--timeout-ms", "10000", "--poll-us", "50"}));
    publishUntilExit(pub, cat, std::chrono::microseconds(1000));
    ASSERT_TRUE(cat.exited());
    EXPECT_EQ(cat.exit_code, 0) << cat.read("err.txt");
    EXPECT_EQ(cat.frameLines(), 5);
  }
  {
    CatRun cat;  // the segment's own user, but not ours
    ASSERT_TRUE(spawnCat(cat, {name, "--owner", "12346", "--timeout-ms", "10000"}));
    ASSERT_TRUE(waitUntil([&] { return cat.exited(); }, std::chrono::seconds(20)));
    EXPECT_EQ(cat.exit_code, 4) << cat.read("err.txt");
  }
  ASSERT_TRUE(chmodSegment(name, 0620));
  {
    CatRun cat;
    ASSERT_TRUE(spawnCat(cat, {name, "--owner", "12345", "--timeout-ms", "10000"}));
    ASSERT_TRUE(waitUntil([&] { return cat.exited(); }, std::chrono::seconds(20)));
    EXPECT_EQ(cat.exit_code, 4) << cat.read("err.txt");
    EXPECT_NE(cat.read("err.txt").find("mode 0620 lets group or others write"), std::string::npos) << cat.read("err.txt");
  }
  for (const char* bad : {"abc", "-1", "4294967295", ""}) {
    CatRun cat;
    ASSERT_TRUE(spawnCat(cat, {name, "--owner", bad, "--timeout-ms", "10000"}));
    ASSERT_TRUE(waitUntil([&] { return cat.exited(); }, std::chrono::seconds(20)));
    EXPECT_EQ(cat.exit_code, 1) << bad << ": " << cat.read("err.txt");
  }
}

// Without NAME the cat reads tetrig run's default segment, /tetrig.
TEST(ShmCat, WithoutANameItReadsTetrigRunsDefaultSegment) {
  if (std::filesystem::exists("/dev/shm/tetrig")) GTEST_SKIP() << "a segment /tetrig exists on this machine (a tetrig run): not touched";
  CatRun run;
  ASSERT_TRUE(spawnCat(run, {"--timeout-ms", "200"}));
  for (int i = 0; i < 500 && !run.exited(); ++i) std::this_thread::sleep_for(std::chrono::milliseconds(10));
  ASSERT_TRUE(run.exited());
  EXPECT_EQ(run.exit_code, 2);  // timed out: no such segment
  EXPECT_NE(run.read("err.txt").find("timed out after 200 ms waiting for segment /tetrig\n"), std::string::npos) << run.read("err.txt");
}

#else   // TETRIG_SHM_CAT_PATH

TEST(ShmCat, NeedsTheConsumerProgram) {
  GTEST_SKIP() << "tetrig-shm-cat is not built (configure with TETRIG_BUILD_TOOLS=ON): consumer tests skipped";
}

#endif  // TETRIG_SHM_CAT_PATH

}  // namespace
