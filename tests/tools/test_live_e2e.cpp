// End-to-end test of the live path across processes (DESIGN.md 6a; issue: the live runtime):
//
//   this process: a umockdev-emulated HID device (tests/drivers/umockdev_devices.*) speaking the
//     tetrig marker-stream protocol (docs/protocol.md): it answers START / GET_DESCRIPTOR with a
//     descriptor (the HDM05 clip's labels, ids = C3D point indices) and streams the clip's first
//     frames as 64-byte input reports (encodeMarkerStreamFrame + encodeMarkerStreamFragment)
//        |  pty + ioctl socket of the umockdev testbed, inherited by the children
//        v
//   child 1: `tetrig run --source hid:VID:PID` (hidapi -> decoder -> mailbox -> FrameLoop ->
//     LiveRig on the SMPL rig -> shared-memory segment)
//        |  POSIX shared memory
//        v
//   child 2: `tetrig-shm-cat NAME --dump FILE` (the C99 consumer)
//
// Asserted: both children exit 0; the consumer saw every published frame in order (frame ids
// 1..N contiguous, source frame counters = the device's counters 1..N, nothing missed), the run's
// statistics show no frame dropped, lost or undecodable; and every frame in the dump equals, bit
// for bit (memcmp), an offline LiveRig loaded from the same rig file, bound to the same labels and
// fed the same MarkerFrames (this test's own encoded bytes decoded with MarkerStreamDecoder) with
// the iteration count that frame was published with. Each frame's source counter and iteration
// count come from the consumer's per-frame stdout line (docs/shm.md 7), printed from the same
// slot read as its dump record (the dump itself holds ids and positions only). The offline replay
// runs on a thread with flush-to-zero / denormals-are-zero on, as FrameLoop's solver thread does.
//
// Two runs: the product's configuration (3 iterations, default budget: 8 ms from receive, no rate
// being known for a HID device; a loaded machine may cut a step at an iteration boundary), and one
// where every step is cut by the deadline after its first of 4 iterations.
//
// Pacing: the device sends frame k no earlier than k / 120 s after the first and only once the
// consumer has printed frame k - 1 (lockstep), so no frame can be overwritten in the mailbox or
// in the segment whatever the load on the machine; the test prints how many frames the lockstep
// delayed past their 120 Hz time. Timing under umockdev says nothing about a device (every hidraw
// ioctl goes through umockdev's preload library and a socket to this process), so nothing here
// asserts a time.
#include "tetrig/deformer.hpp"
#include "tetrig/drivers/c3d_playback.hpp"
#include "tetrig/drivers/c3d_reader.hpp"
#include "tetrig/drivers/marker_stream.hpp"
#include "tetrig/live_rig.hpp"
#include "tetrig/rig_file.hpp"
#include "tetrig/rigbuild/build_rig.hpp"
#include "temp_dir.hpp"
#include "test_data.hpp"
#include "umockdev_devices.hpp"

#include <gtest/gtest.h>

#include "shm_dump.hpp"
#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cinttypes>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <memory>
#include <optional>
#include <span>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/mman.h>
#include <sys/wait.h>
#include <unistd.h>

#if defined(__x86_64__) || defined(__i386__)
#include <xmmintrin.h>
#endif

extern char** environ;

namespace {

namespace drv = tetrig::drivers;
using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;

constexpr const char* kMan = "meshes/odedstein-meshes/human_man.obj";
constexpr const char* kClip = "mocap/hdm05/HDM_mm_01-02_03_120.c3d";
constexpr std::uint16_t kVendorId = 0x1209;
constexpr std::uint16_t kProductId = 0x7e72;  // not the transport tests' 7e70/7e71
constexpr std::size_t kFrames = 300;           // first 300 frames of the clip: 2.5 s at 120 Hz
constexpr std::int64_t kPeriodNs = 1'000'000'000 / 120;
constexpr std::uint32_t kTableId = 0x00010001;
constexpr auto kStartupTimeout = 60s;  // rig load + factorization in the child, label exchange
constexpr auto kFrameTimeout = 10s;    // one frame from injection to the consumer's line
constexpr auto kExitTimeout = 30s;

std::string readFile(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

// The same floating-point environment as FrameLoop's solver thread (frame_loop.cpp): FTZ + DAZ.
bool flushDenormalsOnThisThread() {
#if defined(__x86_64__) || defined(__i386__)
  _mm_setcsr(_mm_getcsr() | 0x8040u);
  return true;
#elif defined(__aarch64__)
  std::uint64_t fpcr = 0;
  __asm__ volatile("mrs %0, fpcr" : "=r"(fpcr));
  fpcr |= (1ull << 24);
  __asm__ volatile("msr fpcr, %0" : : "r"(fpcr));
  return true;
#else
  return false;
#endif
}

// A child process with stdout and stderr in files; killed (SIGKILL) and reaped if still running
// when the test ends early.
class Child {
 public:
  Child() = default;
  Child(const Child&) = delete;
  Child& operator=(const Child&) = delete;
  ~Child() {
    if (pid_ > 0 && !status_) {
      kill(pid_, SIGKILL);
      int status = 0;
      waitpid(pid_, &status, 0);
    }
  }

  ::testing::AssertionResult spawn(const std::string& exe, const std::vector<std::string>& args, const std::filesystem::path& out,
                                   const std::filesystem::path& err) {
    out_ = out;
    err_ = err;
    name_ = std::filesystem::path(exe).filename().string();
    std::vector<std::string> all = {exe};
    all.insert(all.end(), args.begin(), args.end());
    std::vector<char*> argv;
    for (std::string& a : all) argv.push_back(a.data());
    argv.push_back(nullptr);
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_addopen(&actions, 1, out.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0600);
    posix_spawn_file_actions_addopen(&actions, 2, err.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0600);
#if defined(__GLIBC__) && (__GLIBC__ > 2 || (__GLIBC__ == 2 && __GLIBC_MINOR__ >= 34))
    // Nothing else: the testbed's pty master is not close-on-exec, and a child holding a copy
    // would keep the emulated device "plugged" through MockHidDevice::unplug()'s hang-up.
    posix_spawn_file_actions_addclosefrom_np(&actions, 3);
#endif
    // environ carries LD_PRELOAD (umockdev's preload library) and UMOCKDEV_DIR (the testbed).
    const int rc = posix_spawn(&pid_, exe.c_str(), &actions, nullptr, argv.data(), environ);
    posix_spawn_file_actions_destroy(&actions);
    if (rc != 0) return ::testing::AssertionFailure() << "posix_spawn " << exe << ": " << std::strerror(rc);
    return ::testing::AssertionSuccess();
  }

  // The exit status if the child has ended (reaped once), else nothing.
  std::optional<int> poll() {
    if (status_) return status_;
    int status = 0;
    if (pid_ > 0 && waitpid(pid_, &status, WNOHANG) == pid_) {
      status_ = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + (WIFSIGNALED(status) ? WTERMSIG(status) : 0);
    }
    return status_;
  }

  // Waits up to `timeout`; kills the child when it is still running then. Returns the status or
  // -1 after a kill.
  int wait(std::chrono::milliseconds timeout) {
    const auto end = Clock::now() + timeout;
    while (Clock::now() < end) {
      if (poll()) return *status_;
      std::this_thread::sleep_for(10ms);
    }
    kill(pid_, SIGKILL);
    int status = 0;
    waitpid(pid_, &status, 0);
    status_ = -1;
    return -1;
  }

  std::string describe() const {
    return name_ + " (pid " + std::to_string(pid_) + ")\n--- stdout (last 3000 bytes) ---\n" + tail(readFile(out_)) +
           "\n--- stderr ---\n" + tail(readFile(err_));
  }
  std::string out() const { return readFile(out_); }
  std::string err() const { return readFile(err_); }

 private:
  static std::string tail(const std::string& s) { return s.size() > 3000 ? "..." + s.substr(s.size() - 3000) : s; }
  pid_t pid_ = -1;
  std::optional<int> status_;
  std::filesystem::path out_, err_;
  std::string name_;
};

// One line the consumer prints per frame: "frame ID source S iter K recv->pub ... flags 0xF ...".
struct ConsumerLine {
  std::uint64_t frame_id = 0;
  std::uint64_t source_frame = 0;
  int iterations = -1;
  unsigned long flags = 0;
};

std::vector<ConsumerLine> parseConsumerLines(const std::string& text, bool& ok) {
  std::vector<ConsumerLine> lines;
  ok = true;
  std::istringstream in(text);
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("frame ", 0) != 0) continue;
    ConsumerLine c;
    if (std::sscanf(line.c_str(), "frame %" SCNu64 " source %" SCNu64 " iter %d", &c.frame_id, &c.source_frame, &c.iterations) != 3) {
      ok = false;
      continue;
    }
    const std::size_t at = line.find(" flags 0x");
    if (at == std::string::npos) {
      ok = false;
      continue;
    }
    c.flags = std::strtoul(line.c_str() + at + 9, nullptr, 16);
    lines.push_back(c);
  }
  return lines;
}

// Counts the frame lines the consumer has printed so far (its stdout is flushed after every
// line), reading only what was appended since the last call.
class ConsumerProgress {
 public:
  explicit ConsumerProgress(const std::filesystem::path& out) : fd_(open(out.c_str(), O_RDONLY | O_CLOEXEC)) {}
  ~ConsumerProgress() {
    if (fd_ >= 0) close(fd_);
  }
  ConsumerProgress(const ConsumerProgress&) = delete;
  ConsumerProgress& operator=(const ConsumerProgress&) = delete;
  std::size_t frames() {
    char buf[4096];
    ssize_t n = 0;
    while (fd_ >= 0 && (n = read(fd_, buf, sizeof buf)) > 0) {
      for (ssize_t i = 0; i < n; ++i) {
        if (buf[i] != '\n') {
          line_ += buf[i];
          continue;
        }
        if (line_.rfind("frame ", 0) == 0) ++frames_;
        line_.clear();
      }
    }
    return frames_;
  }

 private:
  int fd_ = -1;
  std::string line_;
  std::size_t frames_ = 0;
};

using tetrig::test::DumpRecord;
using tetrig::test::parseDump;

// The 64-byte HID input reports carrying one encoded message (frame or descriptor).
std::vector<std::vector<std::uint8_t>> messageReports(std::span<const std::uint8_t> message) {
  std::vector<std::vector<std::uint8_t>> out;
  for (std::size_t i = 0; i < drv::markerStreamFragmentCount(message.size()); ++i) {
    std::vector<std::uint8_t> report(drv::kMarkerStreamHidReportSize);
    if (drv::encodeMarkerStreamFragment(message, i, report) != report.size()) return {};
    out.push_back(std::move(report));
  }
  return out;
}

// Everything the device sends and the host should decode, built once per binary.
struct Scene {
  tetrig::test::TempDir dir{"tetrig-e2e"};  // fresh and private (tests/support/temp_dir.hpp); TETRIG_KEEP_TEMP keeps it
  std::filesystem::path rig_path;
  std::size_t rig_markers = 0;
  std::vector<std::vector<std::uint8_t>> descriptor_reports;
  std::vector<std::vector<std::vector<std::uint8_t>>> frame_reports;  // per frame: its input reports
  std::vector<tetrig::MarkerFrame> decoded;                             // per frame, as MarkerStreamDecoder gives it
  std::vector<std::string> labels_by_id;                                // the decoded descriptor
  double rig_build_s = 0;
};

// Builds the scene (the rig takes about a second). Fails the calling test on error.
void buildScene(const std::filesystem::path& man_path, const std::filesystem::path& clip_path, Scene& s) {
  const auto t0 = Clock::now();
  // 1. The rig (as bench/tools/bench_rig_frame.cpp), written with serializeRig. Built before any
  //    umockdev testbed exists: the rig builder forks for TetGen.
  tetrig::rigbuild::BuildRigInputs in;
  in.mesh = man_path;
  in.clip = clip_path;
  in.tet_vertices = 1500;
  in.max_marker_distance = 0.15;
  in.check_deformer = false;
  const tetrig::Rig built = tetrig::rigbuild::buildRig(in);
  s.rig_markers = built.markers.size();
  s.rig_path = s.dir.path() / "smpl_hdm05.rig";
  {
    const std::vector<std::uint8_t> bytes = tetrig::serializeRig(built);
    std::ofstream out(s.rig_path, std::ios::binary);
    out.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
    ASSERT_TRUE(out.good()) << "cannot write " << s.rig_path;
  }
  s.rig_build_s = std::chrono::duration<double>(Clock::now() - t0).count();

  // 2. What the device sends: the descriptor (the selected points' labels, ids = point indices)
  //    and the first kFrames frames, counters 1..N, device time = counter / 120 s, STREAM_START
  //    on the first.
  const drv::C3DClip clip = drv::C3DClip::load(clip_path);
  ASSERT_GE(clip.frameCount(), kFrames);
  drv::C3DPlaybackOptions playback_options;
  playback_options.pacing = drv::Pacing::kAsFastAsPossible;
  const drv::C3DPlayback playback(clip, playback_options);
  std::vector<drv::MarkerLabel> label_entries;
  for (const int p : playback.selectedPoints()) {
    label_entries.push_back({static_cast<std::uint16_t>(p), clip.labels()[static_cast<std::size_t>(p)]});
  }
  ASSERT_EQ(label_entries.size(), 41u) << "HDM05: 41 labelled physical markers";
  std::sort(label_entries.begin(), label_entries.end(), [](const auto& a, const auto& b) { return a.id < b.id; });
  std::vector<std::uint8_t> descriptor(drv::kMarkerStreamMaxDescriptorSize);
  descriptor.resize(drv::encodeMarkerStreamDescriptor(label_entries, kTableId, descriptor));
  ASSERT_FALSE(descriptor.empty());
  s.descriptor_reports = messageReports(descriptor);
  ASSERT_GT(s.descriptor_reports.size(), 1u);

  s.frame_reports.resize(kFrames);
  auto frame = std::make_unique<tetrig::MarkerFrame>();
  std::vector<std::uint8_t> bytes(drv::kMarkerStreamMaxFrameSize);
  for (std::size_t k = 0; k < kFrames; ++k) {
    const std::uint64_t counter = k + 1;
    playback.fillFrame(k, counter, *frame);
    frame->device_timestamp_ns = static_cast<std::int64_t>(counter) * kPeriodNs;
    drv::MarkerStreamEncodeOptions encode;
    encode.frame_flags = k == 0 ? drv::kStreamFlagStreamStart : std::uint16_t{0};
    const std::size_t n = drv::encodeMarkerStreamFrame(*frame, encode, bytes);
    ASSERT_GT(n, 0u);
    s.frame_reports[k] = messageReports(std::span(bytes).first(n));
    ASSERT_FALSE(s.frame_reports[k].empty());
  }

  // 3. The frames as the host decodes them: the same reports through MarkerStreamDecoder.
  drv::MarkerStreamDecoder decoder;
  auto scratch = std::make_unique<tetrig::MarkerFrame>();
  for (std::size_t i = 0; i < s.descriptor_reports.size(); ++i) {
    const drv::MarkerStreamStatus st = decoder.decodeHidReport(s.descriptor_reports[i], 0, *scratch);
    ASSERT_EQ(st, i + 1 < s.descriptor_reports.size() ? drv::MarkerStreamStatus::kNeedMore : drv::MarkerStreamStatus::kDescriptor);
  }
  for (std::size_t e = 0; e < decoder.labels().count; ++e) {
    const drv::MarkerLabelEntry& entry = decoder.labels().entries[e];
    if (s.labels_by_id.size() <= entry.id) s.labels_by_id.resize(static_cast<std::size_t>(entry.id) + 1);
    s.labels_by_id[entry.id] = std::string(entry.label());
  }
  s.decoded.resize(kFrames);
  for (std::size_t k = 0; k < kFrames; ++k) {
    for (std::size_t i = 0; i < s.frame_reports[k].size(); ++i) {
      const drv::MarkerStreamStatus st = decoder.decodeHidReport(s.frame_reports[k][i], 0, s.decoded[k]);
      ASSERT_EQ(st, i + 1 < s.frame_reports[k].size() ? drv::MarkerStreamStatus::kNeedMore : drv::MarkerStreamStatus::kFrame)
          << "frame " << k << " report " << i;
    }
    ASSERT_EQ(s.decoded[k].frame_counter, k + 1);
  }
}

// The scene of this binary, or nullptr (with the test failed) when it could not be built.
const Scene* scene(const std::filesystem::path& man_path, const std::filesystem::path& clip_path) {
  static std::unique_ptr<Scene> cached;
  static bool tried = false;
  if (!tried) {
    tried = true;
    auto s = std::make_unique<Scene>();
    buildScene(man_path, clip_path, *s);
    if (!::testing::Test::HasFatalFailure()) cached = std::move(s);
  }
  if (!cached) ADD_FAILURE() << "the scene could not be built (see the first test's failure)";
  return cached.get();
}

// What one end-to-end run left behind.
struct Outcome {
  std::vector<ConsumerLine> lines;  // the consumer's per-frame lines, in order
  std::vector<DumpRecord> dump;     // the consumer's dump, in order
  nlohmann::json stats;             // tetrig run --stats-json
  nlohmann::json consumer;          // tetrig-shm-cat --json
  double startup_s = 0, streaming_s = 0;
  std::size_t lockstep_paced = 0;   // frames sent after their 120 Hz time: the consumer had not printed the previous one yet
};

// Runs device (this process) -> `tetrig run <run_args>` -> segment -> tetrig-shm-cat once and
// checks the transport-level properties: both exit 0, every frame in order, nothing dropped.
void runEndToEnd(const Scene& s, const std::string& tag, const std::vector<std::string>& run_args, Outcome& o) {
  ASSERT_TRUE(std::filesystem::exists(TETRIG_EXE)) << TETRIG_EXE;
  ASSERT_TRUE(std::filesystem::exists(TETRIG_SHM_CAT_EXE)) << TETRIG_SHM_CAT_EXE;
  // 4. The emulated device on an in-process umockdev testbed. The children inherit LD_PRELOAD (the
  //    preload library redirects /sys and /dev and forwards the hidraw node's ioctls through a
  //    socket in the testbed to the handler in this process) and UMOCKDEV_DIR (the testbed).
  ASSERT_TRUE(tetrig::testing::inMockEnvironment()) << tetrig::testing::mockEnvironmentHelp();
  tetrig::testing::Testbed testbed;
  const char* umockdev_dir = std::getenv("UMOCKDEV_DIR");
  ASSERT_TRUE(umockdev_dir != nullptr && *umockdev_dir != '\0')
      << "the testbed did not export UMOCKDEV_DIR: child processes would not see the emulated device";
  tetrig::testing::MockHidSpec spec;
  spec.vendor_id = kVendorId;
  spec.product_id = kProductId;
  spec.product = "e2e marker stream";
  tetrig::testing::MockHidDevice device(testbed, spec);
  device.plug();
  ASSERT_TRUE(device.plugged());

  // 5. The consumer first (it waits for the segment), then the producer.
  const std::string segment = "tetrig-e2e-" + tag + "-" + std::to_string(getpid());
  const std::filesystem::path base = s.dir.path() / tag;
  const std::filesystem::path dump_path = base.string() + ".dump", cat_json = base.string() + ".cat.json",
                              stats_json = base.string() + ".stats.json", cat_out = base.string() + ".cat.out",
                              cat_err = base.string() + ".cat.err", run_out = base.string() + ".run.out",
                              run_err = base.string() + ".run.err";
  struct SegmentCleanup {  // a producer killed on a failure leaves its segment behind; destroyed after the children
    std::string name;
    ~SegmentCleanup() { shm_unlink(name.c_str()); }
  } cleanup{"/" + segment};
  Child cat, run;
  ASSERT_TRUE(cat.spawn(TETRIG_SHM_CAT_EXE,
                        {segment, "--frames", std::to_string(kFrames), "--timeout-ms", "60000", "--dump", dump_path.string(),
                         "--json", cat_json.string()},
                        cat_out, cat_err));
  char source[32];
  std::snprintf(source, sizeof source, "hid:%04x:%04x", kVendorId, kProductId);
  std::vector<std::string> args = {"run",    "--rig",    s.rig_path.string(),      "--source",     source,
                                   "--publish", segment, "--frames", std::to_string(kFrames), "--stats-json",
                                   stats_json.string(), "--label-timeout-ms", "30000"};
  args.insert(args.end(), run_args.begin(), run_args.end());
  ASSERT_TRUE(run.spawn(TETRIG_EXE, args, run_out, run_err));
  const auto both = [&] { return "\n=== " + run.describe() + "\n=== " + cat.describe(); };
  const auto childEnded = [&] { return run.poll().has_value() || cat.poll().has_value(); };
  const auto t_spawned = Clock::now();

  // 6. The device side of the control exchange: every START and GET_DESCRIPTOR is answered with
  //    the descriptor (docs/protocol.md 2a.1) until both were seen.
  bool start_seen = false, get_descriptor_seen = false;
  std::vector<int> opcodes;
  std::vector<std::uint8_t> pending;
  const auto startup_end = Clock::now() + kStartupTimeout;
  while (!(start_seen && get_descriptor_seen)) {
    ASSERT_LT(Clock::now(), startup_end) << "no START + GET_DESCRIPTOR from `tetrig run` (" << opcodes.size()
                                         << " commands seen)" << both();
    ASSERT_FALSE(childEnded()) << "a child ended during start-up" << both();
    const std::vector<std::uint8_t> got = device.readOutput(drv::kMarkerStreamHidReportSize - pending.size(), 100);
    pending.insert(pending.end(), got.begin(), got.end());
    if (pending.size() < drv::kMarkerStreamHidReportSize) continue;
    drv::MarkerStreamCommand command{};
    std::uint16_t param = 0;
    ASSERT_TRUE(drv::decodeMarkerStreamCommandReport(pending, command, param)) << "undecodable output report";
    pending.clear();
    opcodes.push_back(static_cast<int>(command));
    if (command == drv::MarkerStreamCommand::kStart || command == drv::MarkerStreamCommand::kGetDescriptor) {
      for (const auto& r : s.descriptor_reports) ASSERT_TRUE(device.inject(r));
      (command == drv::MarkerStreamCommand::kStart ? start_seen : get_descriptor_seen) = true;
    }
  }
  EXPECT_EQ(opcodes, (std::vector<int>{0x01, 0x05})) << "START, then GET_DESCRIPTOR (no rate asked)";

  // The consumer has the segment open (its first stderr line names the rig) before frames flow.
  while (cat.err().find("rig '") == std::string::npos) {
    ASSERT_LT(Clock::now(), startup_end) << "the consumer never opened the segment" << both();
    ASSERT_FALSE(childEnded()) << "a child ended during start-up" << both();
    std::this_thread::sleep_for(5ms);
  }
  const auto t_streaming = Clock::now();

  // 7. Stream: frame k at >= k / 120 s, and only once the consumer printed frame k - 1.
  ConsumerProgress progress(cat_out);
  for (std::size_t k = 0; k < kFrames; ++k) {
    const auto due = t_streaming + std::chrono::nanoseconds(static_cast<std::int64_t>(k) * kPeriodNs);
    if (k > 0 && Clock::now() > due) ++o.lockstep_paced;
    std::this_thread::sleep_until(due);
    for (const auto& r : s.frame_reports[k]) ASSERT_TRUE(device.inject(r)) << "frame " << k;
    const auto end = Clock::now() + kFrameTimeout;
    while (progress.frames() < k + 1) {
      ASSERT_LT(Clock::now(), end) << "frame " << k + 1 << " never reached the consumer" << both();
      ASSERT_FALSE(childEnded()) << "a child ended while streaming (frame " << k + 1 << ")" << both();
      std::this_thread::sleep_for(200us);
    }
  }
  o.startup_s = std::chrono::duration<double>(t_streaming - t_spawned).count();
  o.streaming_s = std::chrono::duration<double>(Clock::now() - t_streaming).count();

  // 8. Both exit 0, and the producer removed its segment.
  const int run_status = run.wait(kExitTimeout);
  const int cat_status = cat.wait(kExitTimeout);
  ASSERT_EQ(run_status, 0) << "tetrig run failed" << both();
  ASSERT_EQ(cat_status, 0) << "tetrig-shm-cat failed" << both();
  EXPECT_EQ(shm_unlink(("/" + segment).c_str()), -1) << "tetrig run left its segment behind";

  // 9. Producer statistics: nothing dropped, lost or undecodable; every rig marker bound.
  o.stats = nlohmann::json::parse(readFile(stats_json), nullptr, false);
  ASSERT_FALSE(o.stats.is_discarded()) << "unreadable " << stats_json << both();
  const std::string st = o.stats.dump(2);
  EXPECT_EQ(o.stats.at("frames").get<std::uint64_t>(), kFrames) << st;
  EXPECT_EQ(o.stats.at("dropped_frames").get<std::uint64_t>(), 0u) << st;
  EXPECT_EQ(o.stats.at("held_frames").get<std::uint64_t>(), 0u) << st;
  EXPECT_EQ(o.stats.at("rejected_target_frames").get<std::uint64_t>(), 0u) << st;
  EXPECT_EQ(o.stats.at("rejected_poses").get<std::uint64_t>(), 0u) << st;
  EXPECT_EQ(o.stats.at("occluded_marker_frames").get<std::uint64_t>(), 0u) << st;
  EXPECT_EQ(o.stats.at("unknown_marker_frames").get<std::uint64_t>(), 0u) << st;
  EXPECT_EQ(o.stats.at("end").get<std::string>(), "frame limit reached") << st;
  EXPECT_EQ(o.stats.at("source").at("frames_published").get<std::uint64_t>(), kFrames) << st;
  EXPECT_EQ(o.stats.at("source").at("frames_lost").get<std::uint64_t>(), 0u) << st;
  EXPECT_EQ(o.stats.at("source").at("decode_errors").get<std::uint64_t>(), 0u) << st;
  EXPECT_EQ(o.stats.at("rig").at("markers_bound").get<std::size_t>(), s.rig_markers) << st;

  // 10. The consumer: every frame, in order, none missed. Each frame's source counter and
  //     iteration count come from its stdout line (docs/shm.md 7), printed from the same read as
  //     the dump record.
  o.consumer = nlohmann::json::parse(readFile(cat_json), nullptr, false);
  ASSERT_FALSE(o.consumer.is_discarded()) << "unreadable " << cat_json << both();
  EXPECT_EQ(o.consumer.at("frames_seen").get<std::uint64_t>(), kFrames) << o.consumer.dump(2);
  EXPECT_EQ(o.consumer.at("frames_missed").get<std::uint64_t>(), 0u) << o.consumer.dump(2);
  EXPECT_EQ(o.consumer.at("instances").get<std::uint64_t>(), 1u) << o.consumer.dump(2);
  bool lines_ok = false;
  o.lines = parseConsumerLines(cat.out(), lines_ok);
  ASSERT_TRUE(lines_ok) << "unparsable consumer line" << both();
  ASSERT_EQ(o.lines.size(), kFrames) << both();
  bool dump_ok = false;
  o.dump = parseDump(readFile(dump_path), dump_ok);
  ASSERT_TRUE(dump_ok) << "malformed dump " << dump_path;
  ASSERT_EQ(o.dump.size(), kFrames);
  for (std::size_t k = 0; k < kFrames; ++k) {
    ASSERT_EQ(o.lines[k].frame_id, k + 1) << "frame ids must be 1..N, contiguous";
    ASSERT_EQ(o.lines[k].source_frame, k + 1) << "source frame counters must be the device's, in order";
    ASSERT_EQ(o.dump[k].frame_id, o.lines[k].frame_id) << "dump record " << k;
    ASSERT_EQ(o.dump[k].instance, o.dump[0].instance);
    ASSERT_GE(o.lines[k].iterations, 1) << "frame " << k + 1;
    EXPECT_EQ(o.lines[k].flags & 0x1Bu, 0u) << "stale / held / predicted / rejected at frame " << k + 1;
  }
}

// The offline run: the same rig file, the same labels, the same decoded frames, each frame's
// published iteration count, on a thread with the solver thread's floating-point environment.
// Returns the number of frames whose published positions differ (memcmp) from it.
struct OfflineResult {
  std::size_t mismatched = 0, first_mismatch = 0;
  float worst = 0.0f;
  std::vector<float> rest;
};
void compareWithOfflineRun(const Scene& s, const Outcome& o, OfflineResult& r) {
  const tetrig::Rig rig = tetrig::loadRigFile(s.rig_path);
  std::string error;
  std::thread offline([&] {
    flushDenormalsOnThisThread();
    tetrig::LiveRig live(rig);
    const tetrig::MarkerBindingReport binding = live.bindLabels(s.labels_by_id);
    if (binding.matched != static_cast<std::int32_t>(rig.markers.size())) {
      error = "offline binding matched " + std::to_string(binding.matched) + " markers";
      return;
    }
    const std::size_t floats = static_cast<std::size_t>(live.fineVertexCount()) * 3;
    r.rest.assign(live.restPositions().begin(), live.restPositions().end());
    std::vector<float> want(floats);
    for (std::size_t k = 0; k < kFrames; ++k) {
      if (o.dump[k].positions.size() != floats) {
        error = "dump record " + std::to_string(k) + " has " + std::to_string(o.dump[k].positions.size()) + " floats, not " +
                std::to_string(floats);
        return;
      }
      live.processFrame(s.decoded[k], tetrig::StepBudget{o.lines[k].iterations}, want.data(), nullptr);
      if (std::memcmp(want.data(), o.dump[k].positions.data(), floats * sizeof(float)) != 0) {
        if (r.mismatched++ == 0) r.first_mismatch = k + 1;
        for (std::size_t i = 0; i < floats; ++i) r.worst = std::max(r.worst, std::abs(want[i] - o.dump[k].positions[i]));
      }
    }
  });
  offline.join();
  ASSERT_TRUE(error.empty()) << error;
  // The comparison is not trivial: the body moves (the last frame is neither the first nor the
  // rest pose).
  const std::size_t bytes = r.rest.size() * sizeof(float);
  EXPECT_NE(std::memcmp(o.dump.back().positions.data(), o.dump.front().positions.data(), bytes), 0);
  EXPECT_NE(std::memcmp(o.dump.back().positions.data(), r.rest.data(), bytes), 0);
}

void report(const char* what, const Scene& s, const Outcome& o) {
  int histogram[5] = {0, 0, 0, 0, 0};
  for (const ConsumerLine& l : o.lines) ++histogram[std::min(l.iterations, 4)];
  std::printf("[ e2e %s ] rig build %.1f s; spawn to first frame %.1f s; %zu frames in %.2f s (%.1f Hz), %zu sent late by the "
              "lockstep; iterations 1/2/3/4+: %d/%d/%d/%d; deadline hits %llu; solver thread: %s\n",
              what, s.rig_build_s, o.startup_s, kFrames, o.streaming_s, static_cast<double>(kFrames) / o.streaming_s, o.lockstep_paced,
              histogram[1], histogram[2], histogram[3], histogram[4],
              static_cast<unsigned long long>(o.stats.at("deadline_hits").get<std::uint64_t>()),
              o.stats.at("solver_thread").get<std::string>().c_str());
}

// The product's configuration: 3 iterations, the default budget (8 ms from receive, no rate being
// known for a HID device). A loaded machine may cut a step at an iteration boundary; the offline
// run then runs exactly the published count.
TEST(LiveEndToEnd, EmulatedHidDeviceToTetrigRunToCConsumerMatchesAnOfflineRunBitForBit) {
  TETRIG_REQUIRE_DATA(man_path, kMan);
  TETRIG_REQUIRE_DATA(clip_path, kClip);
  const Scene* s = scene(man_path, clip_path);
  ASSERT_NE(s, nullptr);
  Outcome o;
  runEndToEnd(*s, "default", {}, o);
  if (HasFatalFailure()) return;
  for (const ConsumerLine& l : o.lines) ASSERT_LE(l.iterations, 3) << "frame " << l.frame_id;
  OfflineResult r;
  compareWithOfflineRun(*s, o, r);
  EXPECT_EQ(r.mismatched, 0u) << "published frames differing from the offline run: first frame " << r.first_mismatch
                              << ", largest difference " << r.worst;
  report("default", *s, o);
}

// Every step cut by the deadline: 4 iterations asked, a 10 us budget from receive (one iteration
// alone takes about 100 us here, so the deadline has always passed when the first ends). Every
// frame is published after 1 iteration and flagged as a budget miss; the offline run with 1
// iteration must equal it, where the 4 asked would not.
TEST(LiveEndToEnd, StepsCutByTheDeadlineMatchTheOfflineRunWithThePublishedIterationCount) {
  TETRIG_REQUIRE_DATA(man_path, kMan);
  TETRIG_REQUIRE_DATA(clip_path, kClip);
  const Scene* s = scene(man_path, clip_path);
  ASSERT_NE(s, nullptr);
  Outcome o;
  runEndToEnd(*s, "cut", {"--iterations", "4", "--budget-ms", "0.01"}, o);
  if (HasFatalFailure()) return;
  for (const ConsumerLine& l : o.lines) {
    ASSERT_EQ(l.iterations, 1) << "frame " << l.frame_id;
    ASSERT_NE(l.flags & 0x4u, 0u) << "budget miss not flagged at frame " << l.frame_id;
  }
  EXPECT_EQ(o.stats.at("deadline_hits").get<std::uint64_t>(), kFrames);
  // Frames received before the solver was ready are kept out of the budget misses (docs/live.md).
  EXPECT_EQ(o.stats.at("budget_misses").get<std::uint64_t>() + o.stats.at("frames_before_start").get<std::uint64_t>(), kFrames);
  OfflineResult r;
  compareWithOfflineRun(*s, o, r);
  EXPECT_EQ(r.mismatched, 0u) << "published frames differing from the offline run: first frame " << r.first_mismatch
                              << ", largest difference " << r.worst;
  report("cut", *s, o);
}

}  // namespace
