// Tests of the playback sources in the one MarkerSource shape (playback_sources.hpp) and of the
// source factory (source_factory.hpp): labels per kind, frames delivered in order with the
// content of the clip / recording, finished(), prompt stop during real-time pacing, restart, no
// allocation per frame on the driver thread, replay of marker-stream (HID and USB) and Hydra
// recordings against decoding the recording directly, and every spec form of the factory.
//
// The mailbox keeps only the newest frame, so a consumer may miss frames; the tests therefore
// check that every frame the consumer took is the right one for its frame counter, that the
// counters it saw increase, that the source published exactly the clip's frame count and that
// the last frame taken is the clip's last.
#include <gtest/gtest.h>

#include <array>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <memory>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "c3d_test_writer.hpp"
#include "counting_allocator.hpp"
#include "tetrig/clock.hpp"
#include "tetrig/drivers/hydra.hpp"
#include "tetrig/drivers/marker_stream.hpp"
#include "tetrig/drivers/playback_sources.hpp"
#include "tetrig/drivers/raw_recording.hpp"
#include "tetrig/drivers/source_factory.hpp"
#include "tetrig/frame_mailbox.hpp"
#include "temp_dir.hpp"
#include "test_data.hpp"

namespace tetrig::drivers {
namespace {

using namespace std::chrono_literals;
using test::TestC3DSpec;

constexpr auto kDrainLimit = 60s;  // hang guard only

// ---- helpers ----

// Takes frames on the calling thread (the mailbox's consumer) until the source has finished and
// the mailbox is empty, calling on_frame for each. Returns the number taken.
std::uint64_t drain(MarkerSource& source, FrameMailbox& mailbox, const std::function<void(const MarkerFrame&)>& on_frame) {
  std::uint64_t taken = 0;
  const auto deadline = std::chrono::steady_clock::now() + kDrainLimit;
  while (std::chrono::steady_clock::now() < deadline) {
    const bool done = source.finished();  // read before the take: the last commit precedes it
    if (const MarkerFrame* f = mailbox.tryAcquireLatest()) {
      ++taken;
      on_frame(*f);
    } else if (done) {
      break;
    } else {
      std::this_thread::yield();
    }
  }
  return taken;
}

bool waitFor(const std::function<bool()>& condition, std::chrono::milliseconds limit = 10s) {
  const auto deadline = std::chrono::steady_clock::now() + limit;
  while (!condition()) {
    if (std::chrono::steady_clock::now() > deadline) return false;
    std::this_thread::sleep_for(1ms);
  }
  return true;
}

void expectSameMarkers(const MarkerFrame& a, const MarkerFrame& b) {
  ASSERT_EQ(a.marker_count, b.marker_count);
  for (std::size_t k = 0; k < a.marker_count; ++k) {
    const Marker& x = a.markers[k];
    const Marker& y = b.markers[k];
    EXPECT_EQ(x.id, y.id) << "marker " << k;
    EXPECT_EQ(x.valid, y.valid) << "marker " << k;
    EXPECT_EQ(x.has_orientation, y.has_orientation) << "marker " << k;
    EXPECT_EQ(x.buttons, y.buttons) << "marker " << k;
    for (int c = 0; c < 3; ++c) EXPECT_EQ(x.position_mm[c], y.position_mm[c]) << "marker " << k;
    for (int c = 0; c < 4; ++c) EXPECT_EQ(x.orientation[c], y.orientation[c]) << "marker " << k;
  }
}

// Everything a decoder or playback sets, except the receive time.
void expectSameFrame(const MarkerFrame& got, const MarkerFrame& want) {
  EXPECT_EQ(got.frame_counter, want.frame_counter);
  EXPECT_EQ(got.device_timestamp_ns, want.device_timestamp_ns);
  EXPECT_EQ(got.flags, want.flags);
  EXPECT_EQ(got.rejected_count, want.rejected_count);
  expectSameMarkers(got, want);
}

using test::TempDir;  // a fresh private directory per test (tests/support/temp_dir.hpp)

void writeFile(const std::filesystem::path& path, const std::vector<std::uint8_t>& bytes) {
  std::ofstream out(path, std::ios::binary);
  out.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
  ASSERT_TRUE(out.good());
}

// A small clip whose ground truth is the writer's spec: `points` markers, `frames` frames, some
// samples invalid, mm.
TestC3DSpec clipSpec(std::vector<std::string> labels, std::size_t frames, float rate = 100.0f) {
  TestC3DSpec s;
  s.rate = rate;
  s.frames = frames;
  s.labels = std::move(labels);
  const std::size_t points = s.labels.size();
  for (std::size_t f = 0; f < frames; ++f) {
    for (std::size_t p = 0; p < points; ++p) {
      const auto v = static_cast<float>(f * 10 + p);
      s.xyz.push_back({v + 0.25f, -2.0f * v, 1000.0f + v});
      s.valid.push_back((f + 2 * p) % 7 != 3);
    }
  }
  return s;
}

std::shared_ptr<const C3DClip> clipOf(const TestC3DSpec& s, const char* name = "clip.c3d") {
  return std::make_shared<const C3DClip>(C3DClip::parse(test::writeTestC3D(s), name));
}

// Checks frame `frame` of the playback against the writer's spec for the selected points.
void expectClipFrame(const MarkerFrame& got, const TestC3DSpec& s, std::size_t clip_frame,
                     const std::vector<int>& points) {
  ASSERT_EQ(got.marker_count, points.size());
  const std::size_t n = s.labels.size();
  for (std::size_t k = 0; k < points.size(); ++k) {
    const auto p = static_cast<std::size_t>(points[k]);
    const Marker& m = got.markers[k];
    EXPECT_EQ(m.id, p);
    const bool valid = s.valid[clip_frame * n + p];
    EXPECT_EQ(m.valid, valid ? 1 : 0) << "frame " << clip_frame << " point " << p;
    if (valid) {
      for (std::size_t c = 0; c < 3; ++c) EXPECT_EQ(m.position_mm[c], s.xyz[clip_frame * n + p][c]);
    }
  }
}

// ---- C3D ----

TEST(C3DSource, LabelsAreTheStoredOnesForSelectedPointsWithPrefixKept) {
  // Point 1 "*0" is a virtual point, point 3 has no label in a labelled file: both unlabelled.
  const TestC3DSpec s = clipSpec({"subj:LFHD", "*0", "subj:RFHD", ""}, 3);
  auto source = makeC3DSource(clipOf(s), {}, "clip.c3d");
  std::vector<std::string> labels;
  ASSERT_TRUE(source->waitForLabels(0ms, labels));  // known before start
  EXPECT_EQ(labels, (std::vector<std::string>{"subj:LFHD", "", "subj:RFHD"}));

  C3DPlaybackOptions all;
  all.selection.include_unlabeled = true;
  auto with_unlabelled = makeC3DSource(clipOf(s), all, "clip.c3d");
  ASSERT_TRUE(with_unlabelled->waitForLabels(0ms, labels));
  EXPECT_EQ(labels, (std::vector<std::string>{"subj:LFHD", "*0", "subj:RFHD", "point3"}));

  // An explicit selection in another order: ids are point indices, so the table is by index.
  C3DPlaybackOptions some;
  some.selection.labels = {"RFHD"};
  auto selected = makeC3DSource(clipOf(s), some, "clip.c3d");
  ASSERT_TRUE(selected->waitForLabels(0ms, labels));
  EXPECT_EQ(labels, (std::vector<std::string>{"", "", "subj:RFHD"}));
}

TEST(C3DSource, FileWithoutLabelsUsesTheRigBuilderNames) {
  TestC3DSpec s = clipSpec({"a", "b", "c"}, 2);
  s.write_parameters = false;  // header only (like PhaseSpace files): no labels at all
  auto clip = clipOf(s);
  ASSERT_TRUE(clip->labels().empty() || clip->labels()[0].empty());
  auto source = makeC3DSource(clip, {}, "nolabels.c3d");
  std::vector<std::string> labels;
  ASSERT_TRUE(source->waitForLabels(0ms, labels));
  // tools/rigbuild/build_rig.cpp names a point without a label "point<index>".
  EXPECT_EQ(labels, (std::vector<std::string>{"point0", "point1", "point2"}));
}

// The rate frames arrive at sets tetrig run's default budget: a clip paced at speed 2 delivers
// twice its rate; as fast as possible, the clip's rate stands (there is no arrival rate to give).
TEST(C3DSource, NominalRateIsTheArrivalRateAtItsSpeed) {
  const TestC3DSpec s = clipSpec({"A", "B"}, 4);
  C3DPlaybackOptions options;
  options.speed = 2.0;
  EXPECT_DOUBLE_EQ(makeC3DSource(clipOf(s), options, "clip.c3d")->nominalRateHz(), 200.0);
  options.speed = 0.5;
  EXPECT_DOUBLE_EQ(makeC3DSource(clipOf(s), options, "clip.c3d")->nominalRateHz(), 50.0);
  options.pacing = Pacing::kAsFastAsPossible;
  EXPECT_DOUBLE_EQ(makeC3DSource(clipOf(s), options, "clip.c3d")->nominalRateHz(), 100.0);
  SyntheticOptions synthetic;
  synthetic.rate_hz = 120.0;
  synthetic.speed = 3.0;
  EXPECT_DOUBLE_EQ(makeSyntheticSource(synthetic)->nominalRateHz(), 360.0);
}

TEST(C3DSource, DeliversTheClipInOrderAndFinishes) {
  const TestC3DSpec s = clipSpec({"A", "B", "C"}, 40);
  C3DPlaybackOptions options;
  options.pacing = Pacing::kAsFastAsPossible;
  auto source = makeC3DSource(clipOf(s), options, "clip.c3d");
  EXPECT_EQ(source->nominalRateHz(), 100.0);
  EXPECT_NE(source->describe().find("c3d:clip.c3d"), std::string::npos) << source->describe();
  EXPECT_NE(source->describe().find("3 markers"), std::string::npos) << source->describe();
  EXPECT_FALSE(source->finished());

  auto mailbox = std::make_unique<FrameMailbox>();
  const std::int64_t before = monotonicNowNs();
  ASSERT_TRUE(source->start(*mailbox)) << source->lastError();
  std::int64_t last_counter = -1;
  MarkerFrame last{};
  const std::uint64_t taken = drain(*source, *mailbox, [&](const MarkerFrame& f) {
    EXPECT_GT(static_cast<std::int64_t>(f.frame_counter), last_counter);
    last_counter = static_cast<std::int64_t>(f.frame_counter);
    ASSERT_LT(f.frame_counter, 40u);
    expectClipFrame(f, s, f.frame_counter, {0, 1, 2});
    EXPECT_EQ(f.device_timestamp_ns, static_cast<std::int64_t>(f.frame_counter) * 10'000'000);
    EXPECT_GE(f.receive_timestamp_ns, before);
    EXPECT_LE(f.receive_timestamp_ns, monotonicNowNs());
    last = f;
  });
  EXPECT_TRUE(source->finished());
  EXPECT_GE(taken, 1u);
  EXPECT_EQ(last.frame_counter, 39u);  // the last frame is always taken
  expectClipFrame(last, s, 39, {0, 1, 2});
  const MarkerSourceStats stats = source->stats();
  EXPECT_EQ(stats.frames_published, 40u);
  EXPECT_EQ(mailbox->published(), 40u);
  EXPECT_EQ(mailbox->taken() + mailbox->dropped(), 40u);
  source->stop();
  EXPECT_TRUE(source->finished());  // stop after the end does not undo it
  EXPECT_FALSE(source->stats().connected);
}

TEST(C3DSource, RealTimeFramesComeInOrderAtTheClipTimes) {
  // 20 frames at 200 Hz: 95 ms of playback; every frame taken must be the clip frame of its counter.
  const TestC3DSpec s = clipSpec({"A", "B"}, 20, 200.0f);
  auto source = makeC3DSource(clipOf(s), {}, "rt.c3d");
  auto mailbox = std::make_unique<FrameMailbox>();
  const std::int64_t start = monotonicNowNs();
  ASSERT_TRUE(source->start(*mailbox));
  std::vector<std::uint64_t> counters;
  drain(*source, *mailbox, [&](const MarkerFrame& f) {
    counters.push_back(f.frame_counter);
    expectClipFrame(f, s, f.frame_counter, {0, 1});
    // Never released before its time on the clip's time line (lower bound only).
    EXPECT_GE(f.receive_timestamp_ns - start, static_cast<std::int64_t>(f.frame_counter) * 5'000'000);
  });
  ASSERT_FALSE(counters.empty());
  for (std::size_t i = 1; i < counters.size(); ++i) EXPECT_GT(counters[i], counters[i - 1]);
  EXPECT_EQ(counters.back(), 19u);
  EXPECT_EQ(source->stats().frames_published, 20u);
  EXPECT_TRUE(source->finished());
}

TEST(C3DSource, LoopWithMaxFramesFinishesAfterMaxFrames) {
  const TestC3DSpec s = clipSpec({"A", "B"}, 4);
  C3DPlaybackOptions options;
  options.pacing = Pacing::kAsFastAsPossible;
  options.loop = true;
  options.max_frames = 10;
  auto source = makeC3DSource(clipOf(s), options, "loop.c3d");
  EXPECT_NE(source->describe().find("loop"), std::string::npos);
  auto mailbox = std::make_unique<FrameMailbox>();
  ASSERT_TRUE(source->start(*mailbox));
  MarkerFrame last{};
  drain(*source, *mailbox, [&](const MarkerFrame& f) {
    expectClipFrame(f, s, f.frame_counter % 4, {0, 1});
    last = f;
  });
  EXPECT_TRUE(source->finished());
  EXPECT_EQ(source->stats().frames_published, 10u);
  EXPECT_EQ(last.frame_counter, 9u);
  expectClipFrame(last, s, 1, {0, 1});
}

TEST(C3DSource, RestartsFromTheBeginningAndRefusesASecondStart) {
  const TestC3DSpec s = clipSpec({"A"}, 5);
  C3DPlaybackOptions options;
  options.pacing = Pacing::kAsFastAsPossible;
  auto source = makeC3DSource(clipOf(s), options, "again.c3d");
  auto mailbox = std::make_unique<FrameMailbox>();
  ASSERT_TRUE(source->start(*mailbox));
  drain(*source, *mailbox, [](const MarkerFrame&) {});
  ASSERT_TRUE(source->finished());
  std::vector<std::uint64_t> counters;
  ASSERT_TRUE(source->start(*mailbox)) << source->lastError();
  drain(*source, *mailbox, [&](const MarkerFrame& f) { counters.push_back(f.frame_counter); });
  EXPECT_TRUE(source->finished());
  EXPECT_EQ(source->stats().frames_published, 10u);  // counters are kept across runs
  ASSERT_FALSE(counters.empty());
  EXPECT_EQ(counters.back(), 4u);  // the second run counts from 0 again

  // A long real-time clip: a second start while it runs is refused with a message.
  TestC3DSpec slow = clipSpec({"A"}, 3, 0.01f);  // one frame per 100 s
  auto running = makeC3DSource(clipOf(slow), {}, "slow.c3d");
  ASSERT_TRUE(running->start(*mailbox));
  EXPECT_FALSE(running->start(*mailbox));
  EXPECT_NE(running->lastError().find("already running"), std::string::npos) << running->lastError();
  running->stop();
}

TEST(C3DSource, RejectsANullClipAndBadOptions) {
  EXPECT_THROW(makeC3DSource(nullptr, {}, "x"), std::invalid_argument);
  const TestC3DSpec s = clipSpec({"A"}, 2);
  C3DPlaybackOptions bad_speed;
  bad_speed.speed = 0.0;
  EXPECT_THROW(makeC3DSource(clipOf(s), bad_speed, "x"), std::invalid_argument);
  C3DPlaybackOptions bad_label;
  bad_label.selection.labels = {"NOPE"};
  EXPECT_THROW(makeC3DSource(clipOf(s), bad_label, "x"), std::invalid_argument);
}

TEST(C3DSource, RealHdm05ClipPlaysWholeWithPrefixedLabels) {
  TETRIG_REQUIRE_DATA(path, "mocap/hdm05/HDM_mm_01-02_03_120.c3d");
  auto clip = std::make_shared<const C3DClip>(C3DClip::load(path));
  C3DPlaybackOptions options;
  options.pacing = Pacing::kAsFastAsPossible;
  auto source = makeC3DSource(clip, options, "HDM_mm_01-02_03_120.c3d");
  EXPECT_EQ(source->nominalRateHz(), 120.0);
  std::vector<std::string> labels;
  ASSERT_TRUE(source->waitForLabels(0ms, labels));
  std::size_t named = 0;
  for (const std::string& l : labels) named += l.empty() ? 0u : 1u;
  EXPECT_EQ(named, 41u);  // the 41 physical markers; the virtual "*0".."*2" are not selected
  const int lfhd = clip->findPoint("LFHD");
  ASSERT_GE(lfhd, 0);
  EXPECT_EQ(labels.at(static_cast<std::size_t>(lfhd)), "meinard:LFHD");

  auto mailbox = std::make_unique<FrameMailbox>();
  ASSERT_TRUE(source->start(*mailbox));
  MarkerFrame last{};
  std::uint64_t previous = 0;
  bool first = true;
  drain(*source, *mailbox, [&](const MarkerFrame& f) {
    EXPECT_TRUE(first || f.frame_counter > previous);
    first = false;
    previous = f.frame_counter;
    last = f;
  });
  EXPECT_TRUE(source->finished());
  EXPECT_EQ(source->stats().frames_published, clip->frameCount());
  ASSERT_EQ(last.frame_counter, clip->frameCount() - 1);
  ASSERT_EQ(last.marker_count, 41);
  const float* pos = clip->positions(clip->frameCount() - 1);
  for (std::size_t k = 0; k < last.marker_count; ++k) {
    const Marker& m = last.markers[k];
    EXPECT_FALSE(labels.at(m.id).empty());
    for (std::size_t c = 0; c < 3; ++c) {
      EXPECT_EQ(m.position_mm[c], static_cast<float>(clip->unitsToMm()) * pos[3u * m.id + c]);
    }
  }
}

// ---- synthetic ----

TEST(SyntheticSourceShape, LabelsDefaultOrGiven) {
  SyntheticOptions options;
  options.marker_count = 5;
  auto source = makeSyntheticSource(options);
  std::vector<std::string> labels;
  ASSERT_TRUE(source->waitForLabels(0ms, labels));
  EXPECT_EQ(labels, (std::vector<std::string>{"M0", "M1", "M2", "M3", "M4"}));
  EXPECT_EQ(source->nominalRateHz(), 120.0);

  auto named = makeSyntheticSource(options, {"a", "b", "c", "d", "e"});
  ASSERT_TRUE(named->waitForLabels(0ms, labels));
  EXPECT_EQ(labels, (std::vector<std::string>{"a", "b", "c", "d", "e"}));

  EXPECT_THROW(makeSyntheticSource(options, {"a", "b"}), std::invalid_argument);
  SyntheticOptions too_many;
  too_many.marker_count = kMaxMarkers + 1;
  EXPECT_THROW(makeSyntheticSource(too_many), std::invalid_argument);
}

TEST(SyntheticSourceShape, DeliversTheSyntheticFramesInOrder) {
  SyntheticOptions options;
  options.marker_count = 7;
  options.pacing = Pacing::kAsFastAsPossible;
  options.max_frames = 300;
  options.dropout_probability = 0.05f;
  options.noise_sigma_mm = 1.0f;
  auto source = makeSyntheticSource(options);
  const SyntheticSource reference(options);
  auto expected = std::make_unique<MarkerFrame>();
  auto mailbox = std::make_unique<FrameMailbox>();
  ASSERT_TRUE(source->start(*mailbox));
  std::int64_t last_counter = -1;
  drain(*source, *mailbox, [&](const MarkerFrame& f) {
    EXPECT_GT(static_cast<std::int64_t>(f.frame_counter), last_counter);
    last_counter = static_cast<std::int64_t>(f.frame_counter);
    reference.fillFrame(f.frame_counter, *expected);
    expectSameFrame(f, *expected);
  });
  EXPECT_EQ(last_counter, 299);
  EXPECT_TRUE(source->finished());
  EXPECT_EQ(source->stats().frames_published, 300u);
}

TEST(SyntheticSourceShape, EndlessSourceNeverFinishesAndStops) {
  SyntheticOptions options;
  options.marker_count = 3;
  options.pacing = Pacing::kAsFastAsPossible;
  auto source = makeSyntheticSource(options);
  auto mailbox = std::make_unique<FrameMailbox>();
  ASSERT_TRUE(source->start(*mailbox));
  EXPECT_TRUE(waitFor([&] { return source->stats().frames_published > 1000; }));
  EXPECT_TRUE(source->stats().connected);
  source->stop();
  EXPECT_FALSE(source->finished());
  EXPECT_FALSE(source->stats().connected);
  const std::uint64_t published = source->stats().frames_published;
  EXPECT_EQ(mailbox->published(), published);  // nothing is published after stop() returned
  std::this_thread::sleep_for(20ms);
  EXPECT_EQ(mailbox->published(), published);
  source->stop();  // idempotent
}

// Lockstep (tetrig run --as-fast-as-possible): the source publishes the next frame only once the
// consumer took the last one. Without a consumer it waits (one frame published) and still stops at
// once; with a slow consumer every frame is taken in order and none is dropped.
TEST(SyntheticSourceShape, LockstepWaitsForTheConsumerAndDropsNothing) {
  SyntheticOptions options;
  options.marker_count = 3;
  options.max_frames = 200;
  options.pacing = Pacing::kLockstep;
  auto source = makeSyntheticSource(options);
  EXPECT_NE(source->describe().find("as fast as the solver takes frames"), std::string::npos) << source->describe();
  auto mailbox = std::make_unique<FrameMailbox>();
  ASSERT_TRUE(source->start(*mailbox));
  EXPECT_TRUE(waitFor([&] { return mailbox->published() >= 1; }));
  std::this_thread::sleep_for(30ms);
  EXPECT_EQ(mailbox->published(), 1u) << "no consumer took the first frame: the source waits";
  const auto t0 = std::chrono::steady_clock::now();
  source->stop();
  EXPECT_LT(std::chrono::steady_clock::now() - t0, 500ms);

  auto source2 = makeSyntheticSource(options);
  auto mailbox2 = std::make_unique<FrameMailbox>();
  ASSERT_TRUE(source2->start(*mailbox2));
  auto frame = std::make_unique<MarkerFrame>();
  std::uint64_t taken = 0;
  std::int64_t last = -1;
  while (taken < 200 && waitFor([&] { return mailbox2->hasPending(); }, 2s)) {
    ASSERT_TRUE(mailbox2->tryTakeLatest(*frame));
    EXPECT_EQ(static_cast<std::int64_t>(frame->frame_counter), last + 1);
    last = static_cast<std::int64_t>(frame->frame_counter);
    ++taken;
    if (taken % 50 == 0) std::this_thread::sleep_for(5ms);  // a slow consumer now and then
  }
  EXPECT_EQ(taken, 200u);
  EXPECT_TRUE(waitFor([&] { return source2->finished(); }));
  EXPECT_EQ(mailbox2->dropped(), 0u);
  source2->stop();
}

// The driver thread allocates nothing per frame: a run of 2000 frames costs the same number of
// allocations (thread start) as a run of 10.
TEST(SourceShape, NoAllocationPerFrame) {
  auto allocationsFor = [](std::uint64_t frames) {
    SyntheticOptions options;
    options.marker_count = 41;
    options.pacing = Pacing::kAsFastAsPossible;
    options.max_frames = frames;
    auto source = makeSyntheticSource(options);
    auto mailbox = std::make_unique<FrameMailbox>();
    const std::uint64_t before = test::allocationCount();
    EXPECT_TRUE(source->start(*mailbox));
    drain(*source, *mailbox, [](const MarkerFrame&) {});
    source->stop();
    const std::uint64_t after = test::allocationCount();
    EXPECT_EQ(source->stats().frames_published, frames);
    return after - before;
  };
  const std::uint64_t small = allocationsFor(10);
  const std::uint64_t large = allocationsFor(2000);
  EXPECT_EQ(large, small);
  EXPECT_GE(small, 1u);  // the count does see the thread start (the test can fail)
}

// ---- stop during real-time pacing ----

// Each source sleeps about 100 s before its second frame; stop() must cut the sleep short.
void expectPromptStop(MarkerSource& source) {
  auto mailbox = std::make_unique<FrameMailbox>();
  ASSERT_TRUE(source.start(*mailbox)) << source.lastError();
  ASSERT_TRUE(waitFor([&] { return source.stats().frames_published >= 1; }));
  std::this_thread::sleep_for(30ms);  // let the driver thread go to sleep
  const auto t0 = std::chrono::steady_clock::now();
  source.stop();
  const auto elapsed = std::chrono::steady_clock::now() - t0;
  EXPECT_LT(elapsed, 2s) << source.describe();
  EXPECT_EQ(source.stats().frames_published, 1u);
  EXPECT_EQ(mailbox->published(), 1u);
  EXPECT_FALSE(source.finished());
  EXPECT_FALSE(source.stats().connected);
}

TEST(SourceShape, StopDuringRealTimePacingReturnsPromptly) {
  const TestC3DSpec s = clipSpec({"A"}, 3, 0.01f);  // 100 s per frame
  auto c3d = makeC3DSource(clipOf(s), {}, "slow.c3d");
  expectPromptStop(*c3d);

  SyntheticOptions options;
  options.marker_count = 2;
  options.rate_hz = 0.01;
  auto synthetic = makeSyntheticSource(options);
  expectPromptStop(*synthetic);

  // A recording with records 100 s apart.
  TempDir dir;
  const auto path = dir.path() / "gap.trr";
  {
    RawRecordingHeader h;
    h.vendor_id = kHydraVendorId;
    h.product_id = kHydraProductId;
    RawRecorder rec(path, h);
    std::array<std::uint8_t, kHydraReportSize> report{};
    HydraRawReport raw;
    for (int i = 0; i < 3; ++i) {
      raw.sequence = static_cast<std::uint8_t>(i);
      for (auto& c : raw.controllers) c.quaternion[0] = 32767;
      ASSERT_EQ(encodeHydraReport(raw, report), kHydraReportSize);
      rec.write(0, i * 100'000'000'000LL, report);
    }
    rec.close();
  }
  auto replay = makeReplaySource(path, Pacing::kRealTime);
  expectPromptStop(*replay);

  // Also a slowed-down replay (speed 0.001), and the destructor stops a running source.
  auto slow = makeReplaySource(path, Pacing::kRealTime, 0.001);
  auto mailbox = std::make_unique<FrameMailbox>();
  ASSERT_TRUE(slow->start(*mailbox));
  ASSERT_TRUE(waitFor([&] { return slow->stats().frames_published >= 1; }));
  const auto t0 = std::chrono::steady_clock::now();
  slow.reset();
  EXPECT_LT(std::chrono::steady_clock::now() - t0, 2s);
}

// ---- replay ----

struct TimedBytes {
  std::int64_t ns;
  std::uint32_t channel;
  std::vector<std::uint8_t> bytes;
};

std::filesystem::path writeRecording(const std::filesystem::path& path, const RawRecordingHeader& header,
                                     const std::vector<TimedBytes>& records) {
  RawRecorder rec(path, header);
  for (const TimedBytes& r : records) rec.write(r.channel, r.ns, r.bytes);
  rec.close();
  return path;
}

MarkerFrame streamFrame(std::uint64_t counter, std::uint16_t markers) {
  MarkerFrame f{};
  f.frame_counter = counter;
  f.device_timestamp_ns = static_cast<std::int64_t>(counter) * 5'000'000 + 123;
  f.marker_count = markers;
  const std::uint16_t ids[] = {0, 1, 2, 5, 7, 9};
  for (std::uint16_t k = 0; k < markers; ++k) {
    Marker& m = f.markers[k];
    m.id = ids[k % 6];
    m.valid = (counter + k) % 5 != 2 ? 1 : 0;
    m.position_mm[0] = static_cast<float>(counter) + 0.5f * k;
    m.position_mm[1] = -100.0f * k;
    m.position_mm[2] = 900.0f + static_cast<float>(counter % 17);
  }
  return f;
}

std::vector<std::uint8_t> encodeFrame(const MarkerFrame& f) {
  std::vector<std::uint8_t> bytes(kMarkerStreamMaxFrameSize);
  bytes.resize(encodeMarkerStreamFrame(f, {}, bytes));
  return bytes;
}

std::vector<std::uint8_t> encodeDescriptor(const std::vector<MarkerLabel>& labels, std::uint32_t table_id) {
  std::vector<std::uint8_t> bytes(kMarkerStreamMaxDescriptorSize);
  bytes.resize(encodeMarkerStreamDescriptor(labels, table_id, bytes));
  return bytes;
}

// A message as 64-byte HID reports, all recorded at `ns` + 10 us per fragment.
void appendHidReports(std::vector<TimedBytes>& out, const std::vector<std::uint8_t>& message, std::int64_t ns) {
  const std::size_t n = markerStreamFragmentCount(message.size());
  ASSERT_GT(n, 0u);
  for (std::size_t i = 0; i < n; ++i) {
    std::vector<std::uint8_t> report(kMarkerStreamHidReportSize);
    ASSERT_EQ(encodeMarkerStreamFragment(message, i, report), kMarkerStreamHidReportSize);
    out.push_back({ns + static_cast<std::int64_t>(i) * 10'000, 0, std::move(report)});
  }
}

const std::vector<MarkerLabel> kDescriptorLabels = {{0, "LFHD"}, {1, "RFHD"}, {2, "LBHD"}, {5, "C7"}, {7, "T10"},
                                                     {9, "STRN"}};
const std::vector<std::string> kExpectedLabels = {"LFHD", "RFHD", "LBHD", "", "", "C7", "", "T10", "", "STRN"};

// Decodes the recording directly (the reference the replay is compared with): frames by counter.
std::map<std::uint64_t, MarkerFrame> decodeDirectly(const std::filesystem::path& path) {
  const RawRecording recording = RawRecording::load(path);
  MarkerStreamDecoder decoder;
  std::map<std::uint64_t, MarkerFrame> frames;
  auto frame = std::make_unique<MarkerFrame>();
  for (std::size_t i = 0; i < recording.size(); ++i) {
    const RawRecordView r = recording.record(i);
    const bool hid = r.bytes.size() == kMarkerStreamHidReportSize && r.bytes[0] == kMarkerStreamHidInputReportId;
    const MarkerStreamStatus status =
        hid ? decoder.decodeHidReport(r.bytes, r.receive_ns, *frame) : decoder.decodeFrame(r.bytes, r.receive_ns, *frame);
    if (status == MarkerStreamStatus::kFrame) frames[frame->frame_counter] = *frame;
  }
  return frames;
}

// Replays `path` as fast as possible and checks every frame taken against the direct decoding.
void expectReplayMatchesDirectDecoding(const std::filesystem::path& path, std::uint64_t frame_count,
                                       MarkerSource& source) {
  const std::map<std::uint64_t, MarkerFrame> reference = decodeDirectly(path);
  ASSERT_EQ(reference.size(), frame_count);
  auto mailbox = std::make_unique<FrameMailbox>();
  const std::int64_t before = monotonicNowNs();
  ASSERT_TRUE(source.start(*mailbox)) << source.lastError();
  std::int64_t last_counter = -1;
  MarkerFrame last{};
  drain(source, *mailbox, [&](const MarkerFrame& f) {
    EXPECT_GT(static_cast<std::int64_t>(f.frame_counter), last_counter);
    last_counter = static_cast<std::int64_t>(f.frame_counter);
    const auto it = reference.find(f.frame_counter);
    ASSERT_NE(it, reference.end()) << "counter " << f.frame_counter;
    expectSameFrame(f, it->second);
    // Stamped with the live clock, not the recorded time (the recording's times are < 1 s).
    EXPECT_GE(f.receive_timestamp_ns, before);
    EXPECT_LE(f.receive_timestamp_ns, monotonicNowNs());
    last = f;
  });
  EXPECT_TRUE(source.finished());
  EXPECT_EQ(source.stats().frames_published, frame_count);
  EXPECT_EQ(last.frame_counter, reference.rbegin()->first);
  expectSameFrame(last, reference.rbegin()->second);
}

TEST(ReplaySource, HidMarkerStreamWithDescriptorGivesItsLabelsAndTheDecodedFrames) {
  TempDir dir;
  std::vector<TimedBytes> records;
  appendHidReports(records, encodeDescriptor(kDescriptorLabels, 7), 1'000);
  constexpr std::uint64_t kFrames = 50;
  for (std::uint64_t k = 0; k < kFrames; ++k) {
    appendHidReports(records, encodeFrame(streamFrame(k, 6)), 2'000'000 + static_cast<std::int64_t>(k) * 5'000'000);
  }
  RawRecordingHeader h;
  h.vendor_id = 0x1209;
  h.product_id = 0x0001;
  h.description = "tetrig marker stream, HID interface 0";
  const auto path = writeRecording(dir.path() / "hid.trr", h, records);

  auto source = makeReplaySource(path, Pacing::kAsFastAsPossible);
  std::vector<std::string> labels;
  ASSERT_TRUE(source->waitForLabels(0ms, labels));  // known before start
  EXPECT_EQ(labels, kExpectedLabels);
  EXPECT_DOUBLE_EQ(source->nominalRateHz(), 200.0);  // frames complete every 5 ms
  EXPECT_NE(source->describe().find("marker stream"), std::string::npos) << source->describe();
  expectReplayMatchesDirectDecoding(path, kFrames, *source);
  // The last frame also equals what was encoded (ground truth, not only the decoder's view).
  EXPECT_EQ(source->stats().decode_errors, 0u);
}

TEST(ReplaySource, UsbMarkerStreamWithLateDescriptorCountsErrorsAndGaps) {
  TempDir dir;
  std::vector<TimedBytes> records;
  std::int64_t t = 1'000;
  std::uint64_t frames = 0;
  for (std::uint64_t k = 0; k < 30; ++k) {
    if (k == 3) records.push_back({t, 0x81, encodeDescriptor(kDescriptorLabels, 1)});  // after three frames
    if (k == 10) continue;                                                              // a lost frame
    std::vector<std::uint8_t> bytes = encodeFrame(streamFrame(k, 4));
    if (k == 20) {
      bytes[30] ^= 0x40;  // corrupted: CRC mismatch, dropped
    } else {
      ++frames;
    }
    records.push_back({t, 0x81, std::move(bytes)});
    t += 4'000'000;
  }
  const auto path = writeRecording(dir.path() / "usb.trr", {}, records);
  auto source = makeReplaySource(path, Pacing::kAsFastAsPossible);
  std::vector<std::string> labels;
  ASSERT_TRUE(source->waitForLabels(0ms, labels));
  EXPECT_EQ(labels, kExpectedLabels);
  EXPECT_DOUBLE_EQ(source->nominalRateHz(), 250.0);  // median of 4 ms gaps (one 8 ms gap ignored)
  expectReplayMatchesDirectDecoding(path, frames, *source);
  const MarkerSourceStats stats = source->stats();
  EXPECT_EQ(stats.decode_errors, 1u);  // the corrupted frame
  EXPECT_EQ(stats.frames_lost, 2u);    // frames 10 and 20 never arrived whole
}

TEST(ReplaySource, MarkerStreamWithoutDescriptorHasNoLabels) {
  TempDir dir;
  std::vector<TimedBytes> records;
  for (std::uint64_t k = 0; k < 5; ++k) records.push_back({static_cast<std::int64_t>(k) * 1'000'000, 0x81, encodeFrame(streamFrame(k, 2))});
  const auto path = writeRecording(dir.path() / "nodesc.trr", {}, records);
  auto source = makeReplaySource(path, Pacing::kAsFastAsPossible);
  std::vector<std::string> labels{"untouched"};
  const auto t0 = std::chrono::steady_clock::now();
  EXPECT_FALSE(source->waitForLabels(5s, labels));
  EXPECT_LT(std::chrono::steady_clock::now() - t0, 2s);  // answers at once: nothing can change
  EXPECT_EQ(labels, std::vector<std::string>{"untouched"});
  EXPECT_NE(source->describe().find("no descriptor"), std::string::npos) << source->describe();
  EXPECT_DOUBLE_EQ(source->nominalRateHz(), 1000.0);
  expectReplayMatchesDirectDecoding(path, 5, *source);
}

// Issue 37: the receive times come from the file. A step from +5e18 to -5e18 ns does not fit
// in int64: the rate scan subtracted them unchecked (signed overflow, UBSan aborts) and the
// wrapped difference, +8.4e18, read as a frame gap: a tiny positive rate. A backwards step
// gives no rate.
TEST(ReplaySource, ReceiveTimesWhoseDifferenceOverflowsGiveNoRate) {
  TempDir dir;
  std::vector<TimedBytes> records;
  records.push_back({5'000'000'000'000'000'000, 0x81, encodeFrame(streamFrame(0, 2))});
  records.push_back({-5'000'000'000'000'000'000, 0x81, encodeFrame(streamFrame(1, 2))});
  const auto path = writeRecording(dir.path() / "wild_times.trr", {}, records);
  auto source = makeReplaySource(path, Pacing::kAsFastAsPossible);
  EXPECT_EQ(source->nominalRateHz(), 0.0);
  EXPECT_NE(source->describe().find("rate unknown"), std::string::npos) << source->describe();
  expectReplayMatchesDirectDecoding(path, 2, *source);
}

std::vector<TimedBytes> hydraRecords(int count, std::int64_t gap_ns, std::vector<HydraRawReport>* raw_out = nullptr) {
  std::vector<TimedBytes> records;
  for (int i = 0; i < count; ++i) {
    HydraRawReport raw;
    raw.sequence = static_cast<std::uint8_t>(i * 1 + 3);
    for (std::size_t c = 0; c < kHydraControllerCount; ++c) {
      const float pos[3] = {static_cast<float>(10 * i + 100 * static_cast<int>(c)), -50.0f, 300.0f + static_cast<float>(i)};
      const float angle = 0.01f * static_cast<float>(i);
      const float q[4] = {std::cos(angle), 0.0f, std::sin(angle), 0.0f};
      raw.controllers[c] = hydraControllerFromPose(pos, q);
      raw.controllers[c].buttons = static_cast<std::uint8_t>(c + 1);
    }
    if (raw_out != nullptr) raw_out->push_back(raw);
    std::vector<std::uint8_t> bytes(kHydraReportSize);
    EXPECT_EQ(encodeHydraReport(raw, bytes), kHydraReportSize);
    records.push_back({5'000 + i * gap_ns, 0, std::move(bytes)});
  }
  return records;
}

void expectHydraReplay(const std::filesystem::path& path, int count) {
  auto source = makeReplaySource(path, Pacing::kAsFastAsPossible);
  std::vector<std::string> labels;
  ASSERT_TRUE(source->waitForLabels(0ms, labels));
  EXPECT_EQ(labels, (std::vector<std::string>{"hydra0", "hydra1"}));
  EXPECT_DOUBLE_EQ(source->nominalRateHz(), 250.0);
  EXPECT_NE(source->describe().find("Razer Hydra"), std::string::npos) << source->describe();

  // Reference: the recording decoded directly.
  const RawRecording recording = RawRecording::load(path);
  HydraDecoder decoder;
  std::map<std::uint64_t, MarkerFrame> reference;
  auto frame = std::make_unique<MarkerFrame>();
  for (std::size_t i = 0; i < recording.size(); ++i) {
    const RawRecordView r = recording.record(i);
    if (decoder.decode(r.bytes, r.receive_ns, *frame) == HydraStatus::kFrame) reference[frame->frame_counter] = *frame;
  }
  ASSERT_EQ(reference.size(), static_cast<std::size_t>(count));

  auto mailbox = std::make_unique<FrameMailbox>();
  ASSERT_TRUE(source->start(*mailbox));
  MarkerFrame last{};
  drain(*source, *mailbox, [&](const MarkerFrame& f) {
    const auto it = reference.find(f.frame_counter);
    ASSERT_NE(it, reference.end());
    expectSameFrame(f, it->second);
    ASSERT_EQ(f.marker_count, 2);
    EXPECT_EQ(f.markers[0].id, 0);
    EXPECT_EQ(f.markers[1].id, 1);
    last = f;
  });
  EXPECT_TRUE(source->finished());
  EXPECT_EQ(source->stats().frames_published, static_cast<std::uint64_t>(count));
  expectSameFrame(last, reference.rbegin()->second);
  // Ground truth: the last report's controller 1 position as encoded.
  EXPECT_EQ(last.markers[1].position_mm[0], static_cast<float>(10 * (count - 1) + 100));
}

TEST(ReplaySource, HydraRecordingGivesHydraLabelsAndTheDecodedFrames) {
  TempDir dir;
  RawRecordingHeader h;
  h.vendor_id = kHydraVendorId;
  h.product_id = kHydraProductId;
  h.description = "Razer Hydra, HID interface 0, motion mode";
  const auto path = writeRecording(dir.path() / "hydra.trr", h, hydraRecords(40, 4'000'000));
  expectHydraReplay(path, 40);
}

TEST(ReplaySource, HydraRecognisedByItsReportSizeWithoutIds) {
  TempDir dir;
  const auto path = writeRecording(dir.path() / "hydra_noid.trr", {}, hydraRecords(12, 4'000'000));
  expectHydraReplay(path, 12);
}

TEST(ReplaySource, RefusesUnknownOrEmptyRecordingsAndBadSpeed) {
  TempDir dir;
  const auto unknown = writeRecording(dir.path() / "unknown.trr", {}, {{0, 0, std::vector<std::uint8_t>(10, 0xAB)}});
  try {
    (void)makeReplaySource(unknown, Pacing::kAsFastAsPossible);
    FAIL() << "expected std::invalid_argument";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("unknown.trr"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("10 bytes"), std::string::npos) << e.what();
  }
  const auto empty = writeRecording(dir.path() / "empty.trr", {}, {});
  EXPECT_THROW((void)makeReplaySource(empty, Pacing::kAsFastAsPossible), std::invalid_argument);
  const auto hydra = writeRecording(dir.path() / "h.trr", {}, hydraRecords(2, 1'000'000));
  EXPECT_THROW((void)makeReplaySource(hydra, Pacing::kRealTime, 0.0), std::invalid_argument);
  EXPECT_THROW((void)makeReplaySource(dir.path() / "missing.trr", Pacing::kRealTime), RawRecordingError);
}

// ---- factory ----

using devices::markerSourceSpecForms;
using devices::openMarkerSource;
using devices::SourceOpenOptions;

bool waitForFinish(MarkerSource& source) {
  return waitFor([&] { return source.finished(); });
}

std::string invalidArgumentOf(std::string_view spec, const SourceOpenOptions& options = {}) {
  try {
    (void)openMarkerSource(spec, options);
  } catch (const std::invalid_argument& e) {
    return e.what();
  } catch (const std::exception& e) {
    return std::string("wrong exception type: ") + e.what();
  }
  return "no exception";
}

class FactoryTest : public ::testing::Test {
 protected:
  void SetUp() override {
    tmp_ = std::make_unique<test::TempDir>("tetrig-factory");
    dir_ = tmp_->path();
  }
  void TearDown() override { tmp_.reset(); }
  std::unique_ptr<test::TempDir> tmp_;
  std::filesystem::path dir_;
};

TEST_F(FactoryTest, C3DSpecLoadsTheFileWithTheOptions) {
  test::TestC3DSpec s;
  s.rate = 50.0f;
  s.frames = 6;
  s.labels = {"x:A", "x:B"};
  for (std::size_t i = 0; i < 12; ++i) {
    s.xyz.push_back({static_cast<float>(i), 1.0f, 2.0f});
    s.valid.push_back(true);
  }
  const auto path = dir_ / "walk.c3d";
  writeFile(path, test::writeTestC3D(s));
  SourceOpenOptions options;
  options.pacing = Pacing::kAsFastAsPossible;
  options.loop = true;
  options.max_frames = 15;
  auto source = openMarkerSource("c3d:" + path.string(), options);
  ASSERT_NE(source, nullptr);
  EXPECT_EQ(source->nominalRateHz(), 50.0);
  EXPECT_NE(source->describe().find("walk.c3d"), std::string::npos) << source->describe();
  std::vector<std::string> labels;
  ASSERT_TRUE(source->waitForLabels(0ms, labels));
  EXPECT_EQ(labels, (std::vector<std::string>{"x:A", "x:B"}));
  auto mailbox = std::make_unique<FrameMailbox>();
  ASSERT_TRUE(source->start(*mailbox));
  ASSERT_TRUE(waitForFinish(*source));
  EXPECT_EQ(source->stats().frames_published, 15u);  // loop + max_frames reached the playback

  SourceOpenOptions rate;
  rate.rate_hz = 25;
  EXPECT_EQ(openMarkerSource("c3d:" + path.string(), rate)->nominalRateHz(), 25.0);
}

TEST_F(FactoryTest, C3DKeepZeroPointsReachesTheReader) {
  // Marker B sits at the origin with residual word 0: a gap by default, a point with the option.
  test::TestC3DSpec s;
  s.frames = 1;
  s.labels = {"A", "B"};
  s.xyz = {{10.0f, 20.0f, 30.0f}, {0.0f, 0.0f, 0.0f}};
  s.fourth_words = {515.0, 0.0};
  const auto path = dir_ / "zeros.c3d";
  writeFile(path, test::writeTestC3D(s));
  for (const bool keep : {false, true}) {
    SourceOpenOptions options;
    options.pacing = Pacing::kAsFastAsPossible;
    options.c3d_keep_zero_points = keep;
    auto source = openMarkerSource("c3d:" + path.string(), options);
    auto mailbox = std::make_unique<FrameMailbox>();
    ASSERT_TRUE(source->start(*mailbox));
    ASSERT_TRUE(waitForFinish(*source));
    MarkerFrame frame{};
    ASSERT_TRUE(mailbox->tryTakeLatest(frame));
    ASSERT_EQ(frame.marker_count, 2);
    EXPECT_EQ(frame.markers[0].valid, 1);
    EXPECT_EQ(frame.markers[1].valid, keep ? 1 : 0) << "keep_zero_points " << keep;
    EXPECT_EQ(frame.rejected_count, 0);  // a zero gap is an ordinary gap, not a rejected value
  }
}

TEST_F(FactoryTest, ReplaySpecOpensTheRecording) {
  const auto path = dir_ / "hydra.trr";
  {
    RawRecordingHeader h;
    h.vendor_id = kHydraVendorId;
    h.product_id = kHydraProductId;
    RawRecorder rec(path, h);
    for (int i = 0; i < 3; ++i) {
      HydraRawReport raw;
      raw.sequence = static_cast<std::uint8_t>(i);
      for (auto& c : raw.controllers) c.quaternion[0] = 32767;
      std::vector<std::uint8_t> bytes(kHydraReportSize);
      ASSERT_EQ(encodeHydraReport(raw, bytes), kHydraReportSize);
      rec.write(0, i * 4'000'000, bytes);
    }
    rec.close();
  }
  SourceOpenOptions options;
  options.pacing = Pacing::kAsFastAsPossible;
  auto source = openMarkerSource("replay:" + path.string(), options);
  std::vector<std::string> labels;
  ASSERT_TRUE(source->waitForLabels(0ms, labels));
  EXPECT_EQ(labels, (std::vector<std::string>{"hydra0", "hydra1"}));
  auto mailbox = std::make_unique<FrameMailbox>();
  ASSERT_TRUE(source->start(*mailbox));
  ASSERT_TRUE(waitForFinish(*source));
  EXPECT_EQ(source->stats().frames_published, 3u);

  SourceOpenOptions loop;
  loop.loop = true;
  const std::string message = invalidArgumentOf("replay:" + path.string(), loop);
  EXPECT_NE(message.find("plays its recording once"), std::string::npos) << message;
}

TEST_F(FactoryTest, SyntheticSpecs) {
  SourceOpenOptions options;
  auto source = openMarkerSource("synthetic", options);
  std::vector<std::string> labels;
  ASSERT_TRUE(source->waitForLabels(0ms, labels));
  EXPECT_EQ(labels.size(), 41u);
  EXPECT_EQ(labels.front(), "M0");
  EXPECT_EQ(labels.back(), "M40");
  EXPECT_EQ(source->nominalRateHz(), 120.0);

  auto seven = openMarkerSource("synthetic:7", options);
  ASSERT_TRUE(seven->waitForLabels(0ms, labels));
  EXPECT_EQ(labels, (std::vector<std::string>{"M0", "M1", "M2", "M3", "M4", "M5", "M6"}));

  // A rig's markers: rest positions and labels, at a requested rate, for a fixed frame count.
  SourceOpenOptions rig;
  rig.synthetic_rest_mm = {{0.0f, 0.0f, 1000.0f}, {100.0f, 0.0f, 1000.0f}, {0.0f, 100.0f, 1500.0f}};
  rig.synthetic_labels = {"LFHD", "RFHD", "C7"};
  rig.rate_hz = 60;
  rig.pacing = Pacing::kAsFastAsPossible;
  rig.max_frames = 5;
  auto from_rig = openMarkerSource("synthetic", rig);
  ASSERT_TRUE(from_rig->waitForLabels(0ms, labels));
  EXPECT_EQ(labels, rig.synthetic_labels);
  EXPECT_EQ(from_rig->nominalRateHz(), 60.0);
  auto mailbox = std::make_unique<FrameMailbox>();
  ASSERT_TRUE(from_rig->start(*mailbox));
  ASSERT_TRUE(waitForFinish(*from_rig));
  EXPECT_EQ(from_rig->stats().frames_published, 5u);
  MarkerFrame frame{};
  ASSERT_TRUE(mailbox->tryTakeLatest(frame));
  ASSERT_EQ(frame.marker_count, 3);

  // Labels alone set the count.
  SourceOpenOptions named;
  named.synthetic_labels = {"a", "b"};
  ASSERT_TRUE(openMarkerSource("synthetic", named)->waitForLabels(0ms, labels));
  EXPECT_EQ(labels, named.synthetic_labels);

  // Disagreements are refused.
  EXPECT_NE(invalidArgumentOf("synthetic:4", rig).find("4 markers asked for but 3 rest positions"), std::string::npos)
      << invalidArgumentOf("synthetic:4", rig);
  SourceOpenOptions wrong_labels;
  wrong_labels.synthetic_labels = {"a", "b"};
  EXPECT_NE(invalidArgumentOf("synthetic:3", wrong_labels).find("2 labels given for 3 markers"), std::string::npos);
}

TEST_F(FactoryTest, DeviceSpecsBuildSourcesWithoutOpeningAnything) {
  SourceOpenOptions options;
  options.rate_hz = 200;
  for (const char* spec : {"hid:1209:0001", "usb:1209:7e71", "hydra", "hydra:ABC123", "HID:1209:1", "usb:a:B"}) {
    SCOPED_TRACE(spec);
    if (std::string_view(spec) == "HID:1209:1") {
      EXPECT_NE(invalidArgumentOf(spec).find("unknown kind \"HID\""), std::string::npos) << invalidArgumentOf(spec);
      continue;
    }
    std::unique_ptr<MarkerSource> source = openMarkerSource(spec, options);
    ASSERT_NE(source, nullptr);
    EXPECT_FALSE(source->finished());
    EXPECT_FALSE(source->stats().connected);  // nothing started
    EXPECT_FALSE(source->describe().empty());
    std::vector<std::string> labels;
    if (std::string_view(spec).starts_with("hydra")) {
      // Fixed sensor names, known before start (device_marker_sources.hpp).
      EXPECT_TRUE(source->waitForLabels(0ms, labels));
      EXPECT_EQ(labels, (std::vector<std::string>{"hydra0", "hydra1"}));
      EXPECT_EQ(source->nominalRateHz(), 250.0);
    } else {
      // A marker-stream device names its markers only once it runs; the rate asked for went through.
      EXPECT_FALSE(source->waitForLabels(0ms, labels));
      EXPECT_EQ(source->nominalRateHz(), 200.0);
    }
  }
}

TEST_F(FactoryTest, BadSpecsSayWhatIsWrongAndListTheForms) {
  struct Case {
    std::string spec;
    std::string says;
  };
  const std::vector<Case> cases = {
      {"", "empty"},
      {"webcam", "unknown kind \"webcam\""},
      {"c3d", "c3d needs a path"},
      {"c3d:", "c3d needs a path"},
      {"replay:", "replay needs a path"},
      {"hid", "hid needs a vendor and product id"},
      {"hid:1209", "hid needs a vendor and product id"},
      {"hid:12g9:0001", "VID \"12g9\" is not a hex number"},
      {"hid:12345:0001", "VID \"12345\" is not a hex number"},
      {"usb:1209:", "PID \"\" is not a hex number"},
      {"usb:1209:0001:3", "PID \"0001:3\" is not a hex number"},
      {"synthetic:0", "marker count \"0\""},
      {"synthetic:257", "marker count \"257\""},
      {"synthetic:ten", "marker count \"ten\""},
      {"synthetic:", "marker count \"\""},
      {"hydra:", "needs a serial"},
  };
  for (const Case& c : cases) {
    const std::string message = invalidArgumentOf(c.spec);
    EXPECT_NE(message.find(c.says), std::string::npos) << "spec \"" << c.spec << "\": " << message;
    EXPECT_NE(message.find("accepted: c3d:PATH, replay:PATH, synthetic[:N], synthetic:character, hid:VID:PID, usb:VID:PID, hydra[:SERIAL]"),
              std::string::npos)
        << message;
    EXPECT_EQ(message.find('\n'), std::string::npos) << message;  // one line
  }
  EXPECT_NE(markerSourceSpecForms().find("hydra[:SERIAL]"), std::string::npos);

  SourceOpenOptions bad_speed;
  bad_speed.speed = -1.0;
  EXPECT_NE(invalidArgumentOf("synthetic", bad_speed).find("speed"), std::string::npos);
}

TEST_F(FactoryTest, MissingFilesNameThePath) {
  for (const std::string kind : {"c3d", "replay"}) {
    const std::string path = (dir_ / ("absent." + kind)).string();
    try {
      (void)openMarkerSource(kind + ":" + path, {});
      ADD_FAILURE() << "expected std::runtime_error for " << kind;
    } catch (const std::invalid_argument& e) {
      ADD_FAILURE() << "a missing file is not a bad spec: " << e.what();
    } catch (const std::runtime_error& e) {
      EXPECT_NE(std::string(e.what()).find("file not found: " + path), std::string::npos) << e.what();
    }
  }
  // A damaged file: the reader's message, naming the file.
  const auto damaged = dir_ / "damaged.c3d";
  {
    std::ofstream out(damaged, std::ios::binary);
    out << "not a c3d file at all";
  }
  try {
    (void)openMarkerSource("c3d:" + damaged.string(), {});
    ADD_FAILURE() << "expected C3DError";
  } catch (const C3DError& e) {
    EXPECT_NE(std::string(e.what()).find("damaged.c3d"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace tetrig::drivers
