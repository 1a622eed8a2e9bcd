// `tetrig view` (tools/view, docs/view.md) as a user runs it: the real command in a child process
// under `xvfb-run -a` (Xvfb, Mesa llvmpipe), following a segment published by a C++ producer in
// this process (ShmPublisher: a closed tube, z up, that bends as the frame id grows, 100 Hz):
//  - --screenshot after N frames gives a PNG of the window's size that shows the mesh (many
//    colours, a plausible share of clay-coloured pixels) and the overlay; a second screenshot
//    later in the performance shows a differently bent tube (the frame ids it reports grew);
//  - started before any producer, the viewer waits; the producer publishes a few frames and
//    stops cleanly (segment unlinked); the viewer keeps the last frame ("producer stopped"); a
//    new producer on the same name is picked up ("producer restarted") and the screenshot is of
//    the new instance (its id printed by the viewer);
//  - `tetrig run` (synthetic source, the small rig) as the producer: the screenshot shows its rig;
//  - a producer killed with SIGKILL ("died"), then a new one on the name: the viewer follows it;
//  - --markers on a layout 1.1 segment: the same frame with and without it differs exactly by
//    dots in the state colours (measured green, blended yellow, predicted red) near the markers'
//    projections, and the overlay counts them;
//  - errors: no display (says xvfb-run), bad arguments, no producer within --timeout, a segment
//    that is not a tetrig segment: one line, non-zero exit, no screenshot file.
// xvfb-run missing: the Xvfb tests are skipped with a message, and FAIL under CI=true (CI installs
// xvfb and xauth). Labels "tools;view". TETRIG_KEEP_TEMP=1 keeps the screenshots.
#include "find_on_path.hpp"
#include "small_rig.hpp"
#include "tetrig/clock.hpp"
#include "tetrig/render/picture_sheet.hpp"
#include "tetrig/shm_publisher.hpp"
#include "temp_dir.hpp"
#include "tetrig_shm.h"
#include "view.hpp"
#include "test_data.hpp"

#include <gtest/gtest.h>

#include <fcntl.h>
#include <spawn.h>
#include <sys/mman.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <optional>
#include <set>
#include <thread>

extern char** environ;

namespace tetrig {
namespace {

using render::Image;
using test::TempDir;

using test::findOnPath;

#define TETRIG_REQUIRE_XVFB(var)                                                                               \
  const std::optional<std::filesystem::path> var = findOnPath("xvfb-run");                                    \
  if (!var || !findOnPath("xauth")) {                                                                          \
    if (::tetrig::test::runningInCi()) FAIL() << "xvfb-run or xauth not found in CI (apt-get install xvfb xauth)"; \
    GTEST_SKIP() << "xvfb-run or xauth not found: apt-get install xvfb xauth to run the viewer headless";      \
  }

struct Child {
  pid_t pid = -1;
};

// Starts args[0] with stdout into `out` and stderr into `err`; `env` replaces the environment when given.
Child spawn(const std::vector<std::string>& args, const std::filesystem::path& out, const std::filesystem::path& err,
            const std::optional<std::vector<std::string>>& env = std::nullopt) {
  posix_spawn_file_actions_t fa;
  posix_spawn_file_actions_init(&fa);
  posix_spawn_file_actions_addopen(&fa, STDOUT_FILENO, out.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_addopen(&fa, STDERR_FILENO, err.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  std::vector<char*> argv;
  for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  std::vector<char*> envp;
  if (env) {
    for (const std::string& e : *env) envp.push_back(const_cast<char*>(e.c_str()));
  } else {
    for (char** e = environ; *e != nullptr; ++e) envp.push_back(*e);
  }
  envp.push_back(nullptr);
  Child c;
  if (posix_spawn(&c.pid, argv[0], &fa, nullptr, argv.data(), envp.data()) != 0) c.pid = -1;
  posix_spawn_file_actions_destroy(&fa);
  return c;
}

// Exit status, or -1 when it did not end within `timeout` (then killed).
int wait(Child c, std::chrono::milliseconds timeout) {
  const auto end = std::chrono::steady_clock::now() + timeout;
  int status = 0;
  while (std::chrono::steady_clock::now() < end) {
    if (waitpid(c.pid, &status, WNOHANG) == c.pid) return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  kill(c.pid, SIGKILL);
  waitpid(c.pid, &status, 0);
  return -1;
}

std::string slurp(const std::filesystem::path& p) {
  std::ifstream in(p);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

// Waits until `path` contains `text` (a child's log); false after `timeout`.
bool waitForText(const std::filesystem::path& path, const std::string& text, std::chrono::seconds timeout = std::chrono::seconds(20)) {
  const auto end = std::chrono::steady_clock::now() + timeout;
  while (std::chrono::steady_clock::now() < end) {
    if (slurp(path).find(text) != std::string::npos) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return false;
}

struct ViewerRun {
  int status = -1;
  std::string out, err;
};

// `tetrig view ARGS` under xvfb-run -a (its own X server: tests may run in parallel).
Child startViewer(const std::filesystem::path& xvfb_run, const std::vector<std::string>& args, const TempDir& dir, const std::string& tag) {
  std::vector<std::string> argv = {xvfb_run.string(), "-a", "-s", "-screen 0 1024x768x24", TETRIG_EXE, "view"};
  argv.insert(argv.end(), args.begin(), args.end());
  return spawn(argv, dir / (tag + ".out"), dir / (tag + ".err"));
}
ViewerRun finish(Child c, const TempDir& dir, const std::string& tag, std::chrono::milliseconds timeout = std::chrono::seconds(30)) {
  ViewerRun r;
  r.status = c.pid > 0 ? wait(c, timeout) : -1;
  r.out = slurp(dir / (tag + ".out"));
  r.err = slurp(dir / (tag + ".err"));
  return r;
}

// A closed tube along z (radius 0.08, length 1), rings x segments, with both ends capped.
struct Tube {
  std::vector<float> rest;
  std::vector<std::int32_t> triangles;
};
Tube makeTube(int rings = 24, int segments = 32) {
  Tube t;
  for (int r = 0; r <= rings; ++r) {
    for (int s = 0; s < segments; ++s) {
      const float a = 6.2831853f * static_cast<float>(s) / static_cast<float>(segments);
      t.rest.insert(t.rest.end(), {0.08f * std::cos(a), 0.08f * std::sin(a), static_cast<float>(r) / static_cast<float>(rings)});
    }
  }
  auto id = [&](int r, int s) { return r * segments + (s % segments); };
  for (int r = 0; r < rings; ++r) {
    for (int s = 0; s < segments; ++s) {
      t.triangles.insert(t.triangles.end(), {id(r, s), id(r, s + 1), id(r + 1, s + 1), id(r, s), id(r + 1, s + 1), id(r + 1, s)});
    }
  }
  const int bottom = static_cast<int>(t.rest.size() / 3), top = bottom + 1;
  t.rest.insert(t.rest.end(), {0.0f, 0.0f, 0.0f, 0.0f, 0.0f, 1.0f});
  for (int s = 0; s < segments; ++s) {
    t.triangles.insert(t.triangles.end(), {bottom, id(0, s + 1), id(0, s), top, id(rings, s), id(rings, s + 1)});
  }
  return t;
}
const Tube& tube() {
  static const Tube t = makeTube();
  return t;
}

// Frame `id`: the tube bent sideways (+x), more as the id grows (0 at id 0, 0.45 m at the tip by id 200+).
void tubeFrame(std::uint64_t id, float* out) {
  const std::vector<float>& rest = tube().rest;
  const float bend = 0.45f * std::min(1.0f, static_cast<float>(id) / 200.0f);
  for (std::size_t i = 0; i < rest.size(); i += 3) {
    const float z = rest[i + 2];
    out[i] = rest[i] + bend * z * z;
    out[i + 1] = rest[i + 1];
    out[i + 2] = rest[i + 2];
  }
}

// The producer's markers (labels TIP, MID, BASE) in frame `id`: beside the bent tube on its +x
// side at heights 0.68 (measured) and 0.4 (blended), below the bottom cap (predicted); all in view
// of the default camera and below the overlay panel.
void tubeMarkers(std::uint64_t id, float* xyz, std::uint8_t* states) {
  const float bend = 0.45f * std::min(1.0f, static_cast<float>(id) / 200.0f);
  const float m[9] = {0.4624f * bend + 0.16f, 0.0f, 0.68f, 0.16f * bend + 0.16f, 0.0f, 0.4f, 0.0f, 0.0f, -0.08f};
  std::copy(m, m + 9, xyz);
  states[0] = kShmMarkerMeasured;
  states[1] = kShmMarkerBlended;
  states[2] = kShmMarkerPredicted;
}

// Publishes tube frames at about 100 Hz on its own thread until stopped or `frames` were published.
class Producer {
 public:
  Producer(const std::string& name, std::uint64_t frames = 0, std::uint64_t first_id_offset = 0)
      : pub_({.name = name}, static_cast<std::int32_t>(tube().rest.size() / 3), {tube().triangles, tube().rest, "bending tube", labels_}),
        thread_([this, frames, first_id_offset] {
          while (!stop_.load() && (frames == 0 || pub_.framesPublished() < frames)) {
            const std::uint64_t id = pub_.framesPublished() + 1 + first_id_offset;
            tubeFrame(id, pub_.beginPositions());
            tubeMarkers(id, pub_.beginMarkerPositions(), pub_.beginMarkerStates());
            ShmFrameInfo info;
            info.source_frame = id;
            info.iterations = 3;
            info.occluded_markers = 1;
            info.flags = kShmFrameMarkersPredicted;
            info.receive_ns = monotonicNowNs();
            (void)pub_.commit(info);
            std::this_thread::sleep_for(std::chrono::milliseconds(10));
          }
        }) {}
  ~Producer() {
    stop_ = true;
    thread_.join();
  }
  std::uint64_t published() const { return pub_.framesPublished(); }
  std::uint64_t instance() const { return pub_.instanceId(); }

 private:
  std::vector<std::string> labels_ = {"TIP", "MID", "BASE"};
  ShmPublisher pub_;
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

std::string segment(const char* what) { return "/tetrig-view-" + std::string(what) + "-" + std::to_string(getpid()); }

const std::uint8_t* px(const Image& im, int x, int y) { return &im.rgba[(static_cast<std::size_t>(y) * static_cast<std::size_t>(im.width) + static_cast<std::size_t>(x)) * 4]; }
bool isSurface(const std::uint8_t* p) { return int{p[0]} - int{p[2]} > 12; }  // clay is warm; background, grid, overlay are grey

struct PictureFacts {
  std::size_t colours = 0;
  double surface = 0;
};
PictureFacts facts(const Image& im) {
  PictureFacts f;
  std::set<std::uint32_t> c;
  std::size_t n = 0;
  for (int y = 0; y < im.height; ++y) {
    for (int x = 0; x < im.width; ++x) {
      const std::uint8_t* p = px(im, x, y);
      c.insert(std::uint32_t{p[0]} << 16 | std::uint32_t{p[1]} << 8 | p[2]);
      n += isSurface(p) ? 1 : 0;
    }
  }
  f.colours = c.size();
  f.surface = static_cast<double>(n) / (static_cast<double>(im.width) * im.height);
  return f;
}

// "frame F of producer instance I": F and I from the viewer's screenshot line.
std::pair<std::uint64_t, std::uint64_t> shotFrameAndInstance(const std::string& out) {
  const std::size_t at = out.find(": frame ");
  if (at == std::string::npos) return {0, 0};
  std::uint64_t frame = 0, instance = 0;
  std::sscanf(out.c_str() + at, ": frame %lu of producer instance %lx", &frame, &instance);
  return {frame, instance};
}


// The overlay names each frame flag of tetrig_shm.h, keeps unknown bits visible, and says nothing
// for 0.
TEST(ViewFlags, EveryFrameFlagIsNamedAndUnknownBitsStayVisible) {
  EXPECT_EQ(tools::frameFlagText(0), "");
  EXPECT_EQ(tools::frameFlagText(TETRIG_SHM_FRAME_POSE_HELD | TETRIG_SHM_FRAME_MARKERS_PREDICTED), "pose held, markers predicted");
  EXPECT_EQ(tools::frameFlagText(TETRIG_SHM_FRAME_POSE_REJECTED), "pose rejected: last pose repeated");
  EXPECT_EQ(tools::frameFlagText(TETRIG_SHM_FRAME_BUDGET_MISS | 0x400u | 0x80000000u), "budget miss, flags 0x80000400");
  std::vector<std::string> names;
  for (const std::uint32_t bit : {TETRIG_SHM_FRAME_STALE_SOURCE, TETRIG_SHM_FRAME_POSE_HELD, TETRIG_SHM_FRAME_BUDGET_MISS,
                                  TETRIG_SHM_FRAME_MARKERS_PREDICTED, TETRIG_SHM_FRAME_INPUT_REJECTED, TETRIG_SHM_FRAME_POSE_REJECTED}) {
    const std::string name = tools::frameFlagText(bit);
    EXPECT_EQ(name.find("0x"), std::string::npos) << "bit " << bit << " has no name";
    EXPECT_EQ(std::count(names.begin(), names.end(), name), 0) << name;
    names.push_back(name);
  }
}
TEST(View, ScreenshotShowsTheMeshAndFollowsThePerformance) {
  TETRIG_REQUIRE_XVFB(xvfb_run);
  const TempDir dir("tetrig-view");
  const std::string name = segment("shot");
  const Producer producer(name);
  const std::vector<std::string> common = {name.substr(1), "--up", "z", "--width", "480", "--height", "360", "--after-frames", "5",
                                           "--timeout", "20", "--markers"};
  std::vector<std::string> a = common;
  a.insert(a.end(), {"--screenshot", (dir / "early.png").string()});
  const ViewerRun early = finish(startViewer(*xvfb_run, a, dir, "early"), dir, "early");
  ASSERT_EQ(early.status, 0) << early.err;
  // Later in the performance: the tube is bent further.
  while (producer.published() < 230) std::this_thread::sleep_for(std::chrono::milliseconds(10));
  std::vector<std::string> b = common;
  b.insert(b.end(), {"--screenshot", (dir / "late.png").string()});
  const ViewerRun late = finish(startViewer(*xvfb_run, b, dir, "late"), dir, "late");
  ASSERT_EQ(late.status, 0) << late.err;

  const auto [early_frame, early_instance] = shotFrameAndInstance(early.out);
  const auto [late_frame, late_instance] = shotFrameAndInstance(late.out);
  EXPECT_EQ(early_instance, producer.instance()) << early.out;
  EXPECT_EQ(late_instance, producer.instance()) << late.out;
  EXPECT_GE(late_frame, early_frame + 150) << early.out << late.out;

  const Image e = render::readPng(dir / "early.png"), l = render::readPng(dir / "late.png");
  ASSERT_EQ(e.width, 480);
  ASSERT_EQ(e.height, 360);
  ASSERT_EQ(l.width, 480);
  ASSERT_EQ(l.height, 360);
  for (const Image* im : {&e, &l}) {
    const PictureFacts f = facts(*im);
    EXPECT_GT(f.colours, 200u);   // shaded mesh, floor grid, overlay text: not a flat picture
    EXPECT_GT(f.surface, 0.01);   // the tube is in the window...
    EXPECT_LT(f.surface, 0.6);    // ...and framed
  }
  // Below the overlay panel, the bent tube covers other pixels.
  std::size_t differ = 0;
  for (int y = 120; y < 360; ++y)
    for (int x = 0; x < 480; ++x) differ += isSurface(px(e, x, y)) != isSurface(px(l, x, y)) ? 1 : 0;
  EXPECT_GT(differ, 500u);
  // The overlay's text is there: light pixels in the top-left panel.
  std::size_t light = 0;
  for (int y = 8; y < 60; ++y)
    for (int x = 8; x < 300; ++x) light += px(e, x, y)[0] > 200 && px(e, x, y)[1] > 200 && px(e, x, y)[2] > 200 ? 1 : 0;
  EXPECT_GT(light, 100u);
}

// Marker colours as drawn (the dot's centre or its darker rim): measured green, blended yellow,
// predicted red-orange. Clay, background, grid and overlay text are none of these.
bool isMeasuredDot(const std::uint8_t* p) { return int{p[1]} - int{p[0]} > 50 && int{p[1]} - int{p[2]} > 40; }
bool isBlendedDot(const std::uint8_t* p) { return int{p[0]} > 120 && int{p[1]} > 100 && int{p[0]} - int{p[2]} > 100; }
bool isPredictedDot(const std::uint8_t* p) { return int{p[0]} - int{p[1]} > 70 && int{p[0]} - int{p[2]} > 90; }

TEST(View, MarkersAreDrawnAsDotsColouredByState) {
  TETRIG_REQUIRE_XVFB(xvfb_run);
  const TempDir dir("tetrig-view-markers");
  const std::string name = segment("markers");
  const Producer producer(name, 40);  // 40 frames, then the segment keeps frame 40: both pictures show it
  while (producer.published() < 40) std::this_thread::sleep_for(std::chrono::milliseconds(10));
  const std::vector<std::string> common = {name.substr(1), "--up", "z", "--width", "480", "--height", "360", "--after-frames", "1",
                                           "--timeout", "20"};
  std::vector<std::string> a = common, b = common;
  a.insert(a.end(), {"--markers", "--screenshot", (dir / "dots.png").string()});
  b.insert(b.end(), {"--screenshot", (dir / "plain.png").string()});
  const ViewerRun with = finish(startViewer(*xvfb_run, a, dir, "dots"), dir, "dots");
  ASSERT_EQ(with.status, 0) << with.err;
  const ViewerRun without = finish(startViewer(*xvfb_run, b, dir, "plain"), dir, "plain");
  ASSERT_EQ(without.status, 0) << without.err;
  EXPECT_EQ(shotFrameAndInstance(with.out).first, 40u) << with.out;
  EXPECT_EQ(shotFrameAndInstance(without.out).first, 40u) << without.out;
  const Image d = render::readPng(dir / "dots.png"), p = render::readPng(dir / "plain.png");
  ASSERT_EQ(d.width, 480);
  ASSERT_EQ(p.width, 480);
  ASSERT_EQ(d.height, p.height);
  // Below the overlay panel (whose markers line differs): the pictures differ only by the dots.
  std::size_t measured = 0, blended = 0, predicted = 0, differ = 0, differ_not_dot = 0;
  for (int y = 120; y < d.height; ++y) {
    for (int x = 0; x < d.width; ++x) {
      const std::uint8_t* q = px(d, x, y);
      const std::uint8_t* r = px(p, x, y);
      const bool dot = isMeasuredDot(q) || isBlendedDot(q) || isPredictedDot(q);
      measured += isMeasuredDot(q) ? 1 : 0;
      blended += isBlendedDot(q) ? 1 : 0;
      predicted += isPredictedDot(q) ? 1 : 0;
      EXPECT_FALSE(isMeasuredDot(r) || isBlendedDot(r) || isPredictedDot(r)) << "a dot colour without --markers at " << x << "," << y;
      if (std::memcmp(q, r, 3) != 0) {
        ++differ;
        if (!dot) ++differ_not_dot;
      }
    }
  }
  // a 9-pixel dot covers about 60 pixels (multisampled edges blend with what is behind)
  EXPECT_GE(measured, 20u) << "the measured marker (TIP) is not drawn green";
  EXPECT_GE(blended, 20u) << "the blended marker (MID) is not drawn yellow";
  EXPECT_GE(predicted, 20u) << "the predicted marker (BASE) is not drawn red";
  EXPECT_LE(measured + blended + predicted, 3u * 90u) << "more than three dots' worth of marker colour";
  EXPECT_GE(differ, measured + blended + predicted);
  EXPECT_LE(differ_not_dot, 3u * 40u) << "the pictures differ beyond the dots' antialiased edges";
  // the overlay counts them (stderr carries the status lines, not the overlay: check the picture's panel grew)
  std::size_t light_with = 0, light_without = 0;
  for (int y = 8; y < 110; ++y)
    for (int x = 8; x < 470; ++x) {
      light_with += px(d, x, y)[0] > 200 && px(d, x, y)[1] > 200 && px(d, x, y)[2] > 200 ? 1 : 0;
      light_without += px(p, x, y)[0] > 200 && px(p, x, y)[1] > 200 && px(p, x, y)[2] > 200 ? 1 : 0;
    }
  EXPECT_GT(light_with, light_without + 200) << "no markers line in the overlay";
}

TEST(View, SurvivesTheProducerStoppingAndRestarting) {
  TETRIG_REQUIRE_XVFB(xvfb_run);
  const TempDir dir("tetrig-view");
  const std::string name = segment("restart");
  // The viewer first: it waits for the producer.
  const Child viewer = startViewer(*xvfb_run,
                                   {name, "--up", "z", "--width", "320", "--height", "240", "--after-frames", "40", "--timeout", "25",
                                    "--screenshot", (dir / "after-restart.png").string()},
                                   dir, "restart");
  ASSERT_GT(viewer.pid, 0);
  ASSERT_TRUE(waitForText(dir / "restart.err", "waiting for a producer")) << slurp(dir / "restart.err");  // its window is up
  {
    const Producer first(name, 15);  // 15 frames, then a clean stop (the segment is unlinked)
    while (first.published() < 15) std::this_thread::sleep_for(std::chrono::milliseconds(10));
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
  }
  EXPECT_TRUE(waitForText(dir / "restart.err", "producer stopped")) << slurp(dir / "restart.err");  // last frame kept
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  const Producer second(name, 0, 1000);                          // a new instance; its frames show the tube fully bent
  const ViewerRun r = finish(viewer, dir, "restart");
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_NE(r.err.find("producer stopped"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("producer restarted"), std::string::npos) << r.err;
  EXPECT_EQ(shotFrameAndInstance(r.out).second, second.instance()) << r.out;
  const Image im = render::readPng(dir / "after-restart.png");
  EXPECT_EQ(im.width, 320);
  const PictureFacts f = facts(im);
  EXPECT_GT(f.colours, 100u);
  EXPECT_GT(f.surface, 0.01);
}

TEST(View, SurvivesAProducerThatDies) {
  TETRIG_REQUIRE_XVFB(xvfb_run);
  const TempDir dir("tetrig-view");
  const std::string name = segment("crash");
  // A producer in a forked child (10 frames per second), killed with SIGKILL: its segment stays
  // behind with state "running" and a dead pid.
  const pid_t child = fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    try {
      ShmPublisher pub({.name = name}, static_cast<std::int32_t>(tube().rest.size() / 3), {tube().triangles, tube().rest, "bending tube", {}});
      for (;;) {
        tubeFrame(pub.framesPublished() + 1, pub.beginPositions());
        (void)pub.commit(ShmFrameInfo{});
        std::this_thread::sleep_for(std::chrono::milliseconds(100));
      }
    } catch (...) {
    }
    _exit(1);
  }
  const Child viewer = startViewer(*xvfb_run,
                                   {name, "--up", "z", "--width", "320", "--height", "240", "--after-frames", "30", "--timeout", "25",
                                    "--screenshot", (dir / "after-crash.png").string()},
                                   dir, "crash");
  ASSERT_GT(viewer.pid, 0);
  EXPECT_TRUE(waitForText(dir / "crash.err", "rig 'bending tube'")) << slurp(dir / "crash.err");  // it follows the child
  std::this_thread::sleep_for(std::chrono::milliseconds(500));                                    // a few of its frames
  kill(child, SIGKILL);
  int status = 0;
  waitpid(child, &status, 0);  // reaped: the pid is gone
  EXPECT_TRUE(waitForText(dir / "crash.err", "died")) << slurp(dir / "crash.err");
  const Producer second(name);  // replaces the dead segment
  const ViewerRun r = finish(viewer, dir, "crash");
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_NE(r.err.find("pid " + std::to_string(child) + " died"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("producer restarted"), std::string::npos) << r.err;
  EXPECT_EQ(shotFrameAndInstance(r.out).second, second.instance()) << r.out;
  EXPECT_GT(facts(render::readPng(dir / "after-crash.png")).surface, 0.01);
}

// The real live path as the producer: `tetrig run` with the synthetic source on the small rig.
TEST(View, FollowsTetrigRun) {
  TETRIG_REQUIRE_XVFB(xvfb_run);
  const TempDir dir("tetrig-view");
  const std::filesystem::path rig = dir.writeBytes("small.rig", serializeRig(test::buildSmallRig(dir)));
  const std::string name = segment("run");
  const Child run = spawn({TETRIG_EXE, "run", "--rig", rig.string(), "--source", "synthetic", "--rate", "120", "--publish", name.substr(1),
                           "--no-mlock", "--quiet"},
                          dir / "run.out", dir / "run.err");
  ASSERT_GT(run.pid, 0);
  const ViewerRun r = finish(startViewer(*xvfb_run, {name, "--width", "400", "--height", "300", "--after-frames", "20", "--timeout", "20",
                                                     "--follow", "--screenshot", (dir / "run.png").string()},
                                         dir, "run-view"),
                             dir, "run-view");
  kill(run.pid, SIGINT);
  EXPECT_EQ(wait(run, std::chrono::seconds(20)), 0) << slurp(dir / "run.err");
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_NE(r.err.find("rig 'small block'"), std::string::npos) << r.err;
  EXPECT_GE(shotFrameAndInstance(r.out).first, 20u) << r.out;
  const PictureFacts f = facts(render::readPng(dir / "run.png"));
  EXPECT_GT(f.colours, 100u);
  EXPECT_GT(f.surface, 0.02);
  EXPECT_LT(f.surface, 0.7);
}

TEST(View, RefusesWithoutADisplayAndOnBadArguments) {
  const TempDir dir("tetrig-view");
  std::vector<std::string> env;
  for (char** e = environ; *e != nullptr; ++e) {
    const std::string v = *e;
    if (v.rfind("DISPLAY=", 0) != 0 && v.rfind("WAYLAND_DISPLAY=", 0) != 0) env.push_back(v);
  }
  auto run = [&](const std::vector<std::string>& args, const std::string& tag) {
    std::vector<std::string> argv = {TETRIG_EXE, "view"};
    argv.insert(argv.end(), args.begin(), args.end());
    return finish(spawn(argv, dir / (tag + ".out"), dir / (tag + ".err"), env), dir, tag);
  };
  const ViewerRun no_display = run({"some-segment"}, "nodisplay");
  EXPECT_NE(no_display.status, 0);
  EXPECT_NE(no_display.err.find("no display"), std::string::npos) << no_display.err;
  EXPECT_NE(no_display.err.find("xvfb-run -a"), std::string::npos) << no_display.err;
  const ViewerRun jpg = run({"seg", "--screenshot", (dir / "x.jpg").string()}, "jpg");
  EXPECT_NE(jpg.status, 0);
  EXPECT_NE(jpg.err.find(".png"), std::string::npos) << jpg.err;
  const ViewerRun zero = run({"seg", "--after-frames", "0", "--screenshot", (dir / "x.png").string()}, "zero");
  EXPECT_NE(zero.status, 0);
  EXPECT_NE(zero.err.find("after-frames"), std::string::npos) << zero.err;
  const ViewerRun slash = run({"a/b"}, "slash");
  EXPECT_NE(slash.status, 0);
  EXPECT_NE(slash.err.find("segment name"), std::string::npos) << slash.err;
  const ViewerRun nodir = run({"seg", "--screenshot", (dir / "missing" / "x.png").string()}, "nodir");
  EXPECT_NE(nodir.status, 0);
  EXPECT_NE(nodir.err.find("does not exist"), std::string::npos) << nodir.err;
  const ViewerRun none = run({}, "none");
  EXPECT_NE(none.status, 0);
  EXPECT_FALSE(std::filesystem::exists(dir / "x.png"));
}

TEST(View, FailsClearlyWithoutAProducerOrOnAForeignSegment) {
  TETRIG_REQUIRE_XVFB(xvfb_run);
  const TempDir dir("tetrig-view");
  const std::string name = segment("absent");
  const auto t0 = std::chrono::steady_clock::now();
  const ViewerRun absent = finish(startViewer(*xvfb_run, {name, "--timeout", "1.5", "--screenshot", (dir / "a.png").string()}, dir, "absent"), dir, "absent");
  EXPECT_NE(absent.status, 0);
  EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(15));
  EXPECT_NE(absent.err.find("no producer appeared"), std::string::npos) << absent.err;
  EXPECT_FALSE(std::filesystem::exists(dir / "a.png"));
  // A shared-memory object that is not a tetrig segment.
  const std::string foreign = segment("foreign");
  const int fd = shm_open(foreign.c_str(), O_CREAT | O_EXCL | O_RDWR, 0600);
  ASSERT_GE(fd, 0);
  std::vector<char> junk(4096, 'x');
  ASSERT_EQ(write(fd, junk.data(), junk.size()), static_cast<ssize_t>(junk.size()));
  close(fd);
  const ViewerRun bad = finish(startViewer(*xvfb_run, {foreign, "--timeout", "10", "--screenshot", (dir / "b.png").string()}, dir, "foreign"), dir, "foreign");
  shm_unlink(foreign.c_str());
  EXPECT_NE(bad.status, 0);
  EXPECT_NE(bad.err.find("cannot use segment " + foreign), std::string::npos) << bad.err;
  EXPECT_FALSE(std::filesystem::exists(dir / "b.png"));
}

}  // namespace
}  // namespace tetrig
