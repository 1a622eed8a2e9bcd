// Tests of the C3D playback source: frame order and count, pacing schedule (with a fake clock, so
// no timing asserts), looping, stopping, selection, unit and axis conversion, invalid samples,
// marker capacity, a steady-clock run (lower bounds only) and real HDM05 data.
#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <memory>
#include <new>
#include <string>
#include <vector>

#include "fake_clock.hpp"
#include "c3d_test_writer.hpp"
#include "tetrig/drivers/c3d_playback.hpp"
#include "tetrig/drivers/raw_recording.hpp"
#include "tetrig/drivers/synthetic_source.hpp"
#include "tetrig/frame_mailbox.hpp"
#include "test_data.hpp"

#include "counting_allocator.hpp"

namespace tetrig::drivers {
namespace {

using test::smallSpec;
using test::TestC3DSpec;
using test::writeTestC3D;

using test::FakeClock;

struct Captured {
  std::uint64_t counter;
  std::int64_t device_ns;
  std::int64_t receive_ns;
  std::uint16_t count;
  std::uint32_t flags;
  std::vector<Marker> markers;
};

std::vector<Captured> collect(C3DPlayback& playback, FakeClock clock, const std::atomic<bool>* stop = nullptr,
                              PacedRunStats* stats_out = nullptr) {
  std::vector<Captured> out;
  const PacedRunStats stats = playback.run(
      [&](const MarkerFrame& f) {
        out.push_back({f.frame_counter, f.device_timestamp_ns, f.receive_timestamp_ns, f.marker_count, f.flags,
                       std::vector<Marker>(f.markers.begin(), f.markers.begin() + f.marker_count)});
      },
      stop, clock);
  if (stats_out != nullptr) *stats_out = stats;
  return out;
}

C3DClip makeClip(const TestC3DSpec& s) { return C3DClip::parse(writeTestC3D(s), "play.c3d"); }

TEST(C3DPlayback, RealTimeScheduleFollowsTheClipRate) {
  const TestC3DSpec s = smallSpec(C3DProcessor::kIntel, true, 3, 6);  // 100 Hz
  const C3DClip clip = makeClip(s);
  C3DPlayback playback(clip, {});
  EXPECT_EQ(playback.framePeriodNs(), 10'000'000);
  std::int64_t now = 5'000;
  std::vector<std::int64_t> sleeps;
  PacedRunStats stats;
  const auto frames = collect(playback, {&now, &sleeps}, nullptr, &stats);
  ASSERT_EQ(frames.size(), 6u);
  EXPECT_EQ(stats.items, 6u);
  EXPECT_EQ(stats.loops, 1u);
  EXPECT_FALSE(stats.stopped);
  // Frame 0 is due at the start (no sleep); frame k at start + k * 10 ms.
  ASSERT_EQ(sleeps.size(), 5u);
  for (std::size_t k = 1; k < 6; ++k) EXPECT_EQ(sleeps[k - 1], 5'000 + static_cast<std::int64_t>(k) * 10'000'000);
  for (std::size_t k = 0; k < 6; ++k) {
    EXPECT_EQ(frames[k].counter, k);
    EXPECT_EQ(frames[k].device_ns, static_cast<std::int64_t>(k) * 10'000'000);
    EXPECT_EQ(frames[k].receive_ns, 5'000 + static_cast<std::int64_t>(k) * 10'000'000);
  }
}

TEST(C3DPlayback, SpeedScalesTheSchedule) {
  const C3DClip clip = makeClip(smallSpec(C3DProcessor::kIntel, true, 2, 4));
  C3DPlaybackOptions o;
  o.speed = 4.0;
  C3DPlayback playback(clip, o);
  std::int64_t now = 0;
  std::vector<std::int64_t> sleeps;
  (void)collect(playback, {&now, &sleeps});
  ASSERT_EQ(sleeps.size(), 3u);
  EXPECT_EQ(sleeps[0], 2'500'000);
  EXPECT_EQ(sleeps[2], 7'500'000);
}

TEST(C3DPlayback, AsFastAsPossibleNeverSleepsAndKeepsOrder) {
  const TestC3DSpec s = smallSpec(C3DProcessor::kMips, false, 4, 9);
  const C3DClip clip = makeClip(s);
  C3DPlaybackOptions o;
  o.pacing = Pacing::kAsFastAsPossible;
  C3DPlayback playback(clip, o);
  std::int64_t now = 0;
  std::vector<std::int64_t> sleeps;
  const auto frames = collect(playback, {&now, &sleeps});
  EXPECT_TRUE(sleeps.empty());
  ASSERT_EQ(frames.size(), 9u);
  for (std::size_t f = 0; f < 9; ++f) {
    ASSERT_EQ(frames[f].count, 4);
    for (std::size_t p = 0; p < 4; ++p) {
      const std::size_t k = f * 4 + p;
      const Marker& m = frames[f].markers[p];
      EXPECT_EQ(m.id, p);
      EXPECT_EQ(m.valid, s.valid[k] ? 1 : 0);
      if (s.valid[k]) {
        for (int c = 0; c < 3; ++c) EXPECT_FLOAT_EQ(m.position_mm[c], s.xyz[k][static_cast<std::size_t>(c)]);
      } else {
        EXPECT_EQ(m.position_mm[0], 0.0f);
      }
    }
  }
}

TEST(C3DPlayback, LoopingContinuesCountersAndWrapsFrames) {
  const TestC3DSpec s = smallSpec(C3DProcessor::kDec, true, 2, 5);
  const C3DClip clip = makeClip(s);
  C3DPlaybackOptions o;
  o.pacing = Pacing::kAsFastAsPossible;
  o.loop = true;
  o.max_frames = 13;
  C3DPlayback playback(clip, o);
  std::int64_t now = 0;
  std::vector<std::int64_t> sleeps;
  PacedRunStats stats;
  const auto frames = collect(playback, {&now, &sleeps}, nullptr, &stats);
  ASSERT_EQ(frames.size(), 13u);
  EXPECT_EQ(stats.loops, 2u);
  for (std::size_t i = 0; i < 13; ++i) {
    EXPECT_EQ(frames[i].counter, i);
    EXPECT_EQ(frames[i].device_ns, static_cast<std::int64_t>(i) * playback.framePeriodNs());
    const std::size_t clip_frame = i % 5;
    const std::size_t k = clip_frame * 2;  // point 0
    EXPECT_EQ(frames[i].markers[0].valid, s.valid[k] ? 1 : 0);
    if (s.valid[k]) {
      EXPECT_FLOAT_EQ(frames[i].markers[0].position_mm[2], s.xyz[k][2]);
    }
  }
}

TEST(C3DPlayback, StopFlagAndSinkReturningFalse) {
  const C3DClip clip = makeClip(smallSpec(C3DProcessor::kIntel, true, 2, 10));
  C3DPlaybackOptions o;
  o.pacing = Pacing::kAsFastAsPossible;
  o.loop = true;
  C3DPlayback playback(clip, o);
  std::atomic<bool> stop{false};
  int seen = 0;
  PacedRunStats stats = playback.run([&](const MarkerFrame&) {
    if (++seen == 25) stop = true;
  }, &stop);
  EXPECT_EQ(seen, 25);
  EXPECT_TRUE(stats.stopped);
  seen = 0;
  stats = playback.run([&](const MarkerFrame&) { return ++seen < 7; });
  EXPECT_EQ(seen, 7);
  EXPECT_EQ(stats.items, 7u);
  EXPECT_TRUE(stats.stopped);
}

TEST(C3DPlayback, SelectionSkipsUnlabeledAndModelledByDefault) {
  TestC3DSpec s = smallSpec(C3DProcessor::kIntel, true, 5, 2);
  s.labels = {"A", "*0", "LHipAngles", "B", "*1"};
  s.point_string_params = {{"ANGLES", {"LHipAngles"}}};
  const C3DClip clip = makeClip(s);
  EXPECT_EQ(C3DPlayback(clip, {}).selectedPoints(), (std::vector<int>{0, 3}));
  C3DPlaybackOptions o;
  o.selection.include_unlabeled = true;
  EXPECT_EQ(C3DPlayback(clip, o).selectedPoints(), (std::vector<int>{0, 1, 3, 4}));
  o.selection.include_modelled = true;
  EXPECT_EQ(C3DPlayback(clip, o).selectedPoints(), (std::vector<int>{0, 1, 2, 3, 4}));
  C3DPlaybackOptions named;
  named.selection.labels = {"B", "*1", "A"};
  C3DPlayback pick(clip, named);
  EXPECT_EQ(pick.selectedPoints(), (std::vector<int>{3, 4, 0}));
  MarkerFrame f;
  pick.fillFrame(1, 0, f);
  ASSERT_EQ(f.marker_count, 3);
  EXPECT_EQ(f.markers[0].id, 3);
  EXPECT_EQ(f.markers[2].id, 0);
  EXPECT_FLOAT_EQ(f.markers[0].position_mm[0], s.xyz[1 * 5 + 3][0]);
  C3DPlaybackOptions unknown;
  unknown.selection.labels = {"Z"};
  EXPECT_THROW(C3DPlayback(clip, unknown), std::invalid_argument);
}

TEST(C3DPlayback, UnitAndAxisConversion) {
  TestC3DSpec s = smallSpec(C3DProcessor::kIntel, true, 1, 1);
  s.units = "m";
  s.xyz[0] = {1.0f, 2.0f, 3.0f};
  s.valid[0] = true;
  const C3DClip clip = makeClip(s);
  MarkerFrame f;
  C3DPlaybackOptions o;
  C3DPlayback(clip, o).fillFrame(0, 0, f);
  EXPECT_FLOAT_EQ(f.markers[0].position_mm[0], 1000.0f);
  EXPECT_FLOAT_EQ(f.markers[0].position_mm[2], 3000.0f);
  // Z-up -> Y-up: (x, y, z) -> (x, z, -y), a proper rotation.
  o.axes = AxisTransform::zUpToYUp();
  C3DPlayback(clip, o).fillFrame(0, 0, f);
  EXPECT_FLOAT_EQ(f.markers[0].position_mm[0], 1000.0f);
  EXPECT_FLOAT_EQ(f.markers[0].position_mm[1], 3000.0f);
  EXPECT_FLOAT_EQ(f.markers[0].position_mm[2], -2000.0f);
  const auto& m = o.axes.matrix;
  const float det = m[0] * (m[4] * m[8] - m[5] * m[7]) - m[1] * (m[3] * m[8] - m[5] * m[6]) +
                    m[2] * (m[3] * m[7] - m[4] * m[6]);
  EXPECT_FLOAT_EQ(det, 1.0f);
  // Scale on top (e.g. to metres) and no unit conversion.
  o.axes.scale = 0.5f;
  o.convert_units_to_mm = false;
  C3DPlayback(clip, o).fillFrame(0, 0, f);
  EXPECT_FLOAT_EQ(f.markers[0].position_mm[1], 1.5f);
}

TEST(C3DPlayback, NonFiniteSamplesAreRejectedAndFlagged) {
  TestC3DSpec s = smallSpec(C3DProcessor::kIntel, true, 2, 1);
  s.xyz[1] = {std::nanf(""), 0.0f, 0.0f};
  s.valid = {true, true};
  const C3DClip clip = makeClip(s);
  MarkerFrame f;
  C3DPlayback(clip, {}).fillFrame(0, 0, f);
  EXPECT_EQ(f.markers[0].valid, 1);
  EXPECT_EQ(f.markers[1].valid, 0);
  EXPECT_EQ(f.rejected_count, 1);
  EXPECT_NE(f.flags & kFrameRejectedMarkers, 0u);
  // An overflowing scale makes a finite sample non-finite after the transform.
  C3DPlaybackOptions o;
  o.axes.scale = 1e38f;
  C3DPlayback(clip, o).fillFrame(0, 0, f);
  EXPECT_EQ(f.markers[0].valid, 0);
  EXPECT_EQ(f.rejected_count, 2);
}

TEST(C3DPlayback, MoreThanCapacityIsTruncatedAndFlagged) {
  const TestC3DSpec s = smallSpec(C3DProcessor::kIntel, true, kMaxMarkers + 10, 1);
  const C3DClip clip = makeClip(s);
  C3DPlayback playback(clip, {});
  EXPECT_EQ(playback.markerCount(), kMaxMarkers);
  MarkerFrame f;
  playback.fillFrame(0, 0, f);
  EXPECT_EQ(f.marker_count, kMaxMarkers);
  EXPECT_NE(f.flags & kFrameTruncatedMarkers, 0u);
  EXPECT_EQ(f.markers[kMaxMarkers - 1].id, kMaxMarkers - 1);
}

TEST(C3DPlayback, RealTimeNeedsARate) {
  TestC3DSpec s = smallSpec(C3DProcessor::kIntel, true, 1, 2);
  s.rate = 0.0f;
  const C3DClip clip = makeClip(s);
  EXPECT_THROW(C3DPlayback(clip, {}), std::invalid_argument);
  C3DPlaybackOptions o;
  o.rate_override_hz = 50.0;
  EXPECT_EQ(C3DPlayback(clip, o).framePeriodNs(), 20'000'000);
  o = {};
  o.pacing = Pacing::kAsFastAsPossible;
  EXPECT_NO_THROW(C3DPlayback(clip, o));
  o.speed = 0.0;
  EXPECT_THROW(C3DPlayback(clip, o), std::invalid_argument);
}

TEST(C3DPlayback, SteadyClockRunNeverReleasesAFrameEarly) {
  // Lower bounds only: sleep_until on a steady clock never returns before its target.
  TestC3DSpec s = smallSpec(C3DProcessor::kIntel, true, 2, 12);
  s.rate = 500.0f;
  const C3DClip clip = makeClip(s);
  C3DPlayback playback(clip, {});
  const std::int64_t before = SteadyPacingClock{}.nowNs();
  std::vector<std::int64_t> stamps;
  std::vector<std::uint64_t> counters;
  playback.run([&](const MarkerFrame& f) {
    stamps.push_back(f.receive_timestamp_ns);
    counters.push_back(f.frame_counter);
  });
  ASSERT_EQ(stamps.size(), 12u);
  for (std::size_t k = 0; k < stamps.size(); ++k) {
    EXPECT_EQ(counters[k], k);
    EXPECT_GE(stamps[k], before + static_cast<std::int64_t>(k) * 2'000'000);
    if (k > 0) {
      EXPECT_GE(stamps[k], stamps[k - 1]);
    }
  }
}

TEST(C3DPlayback, PublishesIntoTheFrameMailbox) {
  const TestC3DSpec s = smallSpec(C3DProcessor::kIntel, true, 3, 8);
  const C3DClip clip = makeClip(s);
  C3DPlaybackOptions o;
  o.pacing = Pacing::kAsFastAsPossible;
  C3DPlayback playback(clip, o);
  auto mailbox = std::make_unique<FrameMailbox>();
  const PacedRunStats stats = playback.run(mailboxSink(*mailbox));
  EXPECT_EQ(stats.items, 8u);
  EXPECT_EQ(mailbox->published(), 8u);
  MarkerFrame latest;
  ASSERT_TRUE(mailbox->tryTakeLatest(latest));
  EXPECT_EQ(latest.frame_counter, 7u);  // the newest frame wins
  EXPECT_EQ(latest.marker_count, 3);
}

TEST(PlaybackSources, RunAllocatesNothingPerFrame) {
  // Everything is sized at construction/load; the frame path (fill + pace + sink) allocates nothing.
  TestC3DSpec s = smallSpec(C3DProcessor::kDec, false, 20, 30);
  const C3DClip clip = makeClip(s);
  C3DPlaybackOptions o;
  o.pacing = Pacing::kAsFastAsPossible;
  o.loop = true;
  o.max_frames = 1000;
  o.axes = AxisTransform::zUpToYUp();
  C3DPlayback playback(clip, o);
  SyntheticOptions so;
  so.pacing = Pacing::kAsFastAsPossible;
  so.max_frames = 1000;
  so.noise_sigma_mm = 1.0f;
  so.dropout_probability = 0.05f;
  SyntheticSource synthetic(so);
  auto mailbox = std::make_unique<FrameMailbox>();
  std::vector<std::uint8_t> bytes = {'T', 'E', 'T', 'R', 'I', 'G', 'R', 'W', 1, 0, 30, 0};
  bytes.resize(26, 0);
  const std::uint32_t hcrc = recordingCrc32(bytes);
  for (int i = 0; i < 4; ++i) bytes.push_back(static_cast<std::uint8_t>(hcrc >> (8 * i)));
  const RawRecording recording = RawRecording::parse(bytes, "empty.trr");
  RawReplay replay(recording, {Pacing::kAsFastAsPossible, 1.0, false});
  std::uint64_t frames = 0;
  const std::uint64_t before = ::tetrig::test::allocationCount();
  playback.run([&](const MarkerFrame& f) {
    mailbox->publish(f);
    ++frames;
  });
  synthetic.run([&](const MarkerFrame& f) {
    mailbox->publish(f);
    ++frames;
  });
  replay.run([&](const RawRecordView&) { ++frames; });
  const std::uint64_t after = ::tetrig::test::allocationCount();
  EXPECT_EQ(frames, 2000u);
  EXPECT_EQ(after - before, 0u);
  // The counter works: an allocation is seen.
  void* probe = ::operator new(16);  // explicit: new-expressions may be elided
  ::operator delete(probe);
  EXPECT_EQ(::tetrig::test::allocationCount() - after, 1u);
}

TEST(C3DPlaybackRealData, Hdm05ZUpToYUpInMillimetres) {
  TETRIG_REQUIRE_DATA(path, "mocap/hdm05/HDM_mm_01-02_03_120.c3d");
  const C3DClip clip = C3DClip::load(path);
  C3DPlaybackOptions o;
  o.pacing = Pacing::kAsFastAsPossible;
  o.axes = AxisTransform::zUpToYUp();
  C3DPlayback playback(clip, o);
  EXPECT_EQ(playback.markerCount(), 41);  // the 3 virtual "*n" points are skipped
  EXPECT_EQ(playback.framePeriodNs(), 8'333'333);
  std::uint64_t n = 0;
  float head_height = 0.0f;
  const int lfhd = clip.findPoint("LFHD");
  bool ids_ok = true;
  playback.run([&](const MarkerFrame& f) {
    if (f.frame_counter != n) ids_ok = false;
    if (n == 0) {
      for (int k = 0; k < f.marker_count; ++k) {
        if (f.markers[static_cast<std::size_t>(k)].id == lfhd) head_height = f.markers[static_cast<std::size_t>(k)].position_mm[1];
      }
    }
    ++n;
  });
  EXPECT_TRUE(ids_ok);
  EXPECT_EQ(n, 3990u);
  EXPECT_NEAR(head_height, 1710.0f, 60.0f);  // Y is up now; NOTES: LFHD z ~ 1.71 m
}

TEST(C3DPlaybackRealData, Mocap36DropoutComesOutInvalid) {
  TETRIG_REQUIRE_DATA(path, "mocap/btkdata/mocap36.c3d");
  const C3DClip clip = C3DClip::load(path);
  C3DPlaybackOptions o;
  o.pacing = Pacing::kAsFastAsPossible;
  C3DPlayback playback(clip, o);
  int bad_frames = 0;
  playback.run([&](const MarkerFrame& f) {
    if (f.frame_counter >= 1151) {
      for (int k = 0; k < f.marker_count; ++k) {
        if (f.markers[static_cast<std::size_t>(k)].valid != 0) ++bad_frames;
      }
    }
  });
  EXPECT_EQ(bad_frames, 0);
}

}  // namespace
}  // namespace tetrig::drivers
