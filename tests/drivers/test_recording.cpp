// Tests of the raw stream recorder and replay: CRC-32 check value, bit-exact round trip, the
// replay's timing schedule (fake clock), damage detection (CRC, sync, truncation at every
// length), the documented header layout, and how the recorder writes its file (a temporary
// renamed at close: modes, planted links, failures).
#include <gtest/gtest.h>

#include <sys/resource.h>
#include <sys/stat.h>

#include <csignal>

#include <atomic>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "file_checks.hpp"
#include "fake_clock.hpp"
#include "temp_dir.hpp"
#include "tetrig/drivers/raw_recording.hpp"

namespace tetrig::drivers {
namespace {

using test::FakeClock;
using ::tetrig::test::modeOf;
using ::tetrig::test::temporaries;

struct Rec {
  std::int64_t ns;
  std::uint32_t channel;
  std::vector<std::uint8_t> bytes;
};

std::vector<Rec> makeRecords(std::uint32_t seed, int count) {
  std::mt19937 rng(seed);
  std::vector<Rec> out;
  std::int64_t t = 1'000'000'000'000;
  for (int i = 0; i < count; ++i) {
    t += 1'000'000 + static_cast<std::int64_t>(rng() % 8'000'000);
    Rec r{t, static_cast<std::uint32_t>(0x81 + rng() % 3), {}};
    r.bytes.resize(rng() % 300);  // includes empty records
    for (auto& b : r.bytes) b = static_cast<std::uint8_t>(rng());
    out.push_back(std::move(r));
  }
  return out;
}

class RecordingTest : public ::testing::Test {
 protected:
  void SetUp() override {
    tmp_ = std::make_unique<test::TempDir>("tetrig-rec");
    dir_ = tmp_->path();
  }
  void TearDown() override { tmp_.reset(); }

  std::filesystem::path write(const std::vector<Rec>& recs, const RawRecordingHeader& h, const char* name = "a.trr") {
    const auto path = dir_ / name;
    RawRecorder rec(path, h);
    for (const Rec& r : recs) rec.write(r.channel, r.ns, r.bytes);
    EXPECT_EQ(rec.recordCount(), recs.size());
    rec.close();
    return path;
  }

  static std::vector<std::uint8_t> readAll(const std::filesystem::path& p) {
    std::ifstream in(p, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
  }

  std::unique_ptr<test::TempDir> tmp_;  // a fresh private directory per test (tests/support/temp_dir.hpp)
  std::filesystem::path dir_;
};

TEST(RecordingCrc, CheckValue) {
  const char* s = "123456789";
  EXPECT_EQ(recordingCrc32(std::span(reinterpret_cast<const std::uint8_t*>(s), 9)), 0xCBF43926u);
  // Incremental == one shot.
  const auto a = recordingCrc32(std::span(reinterpret_cast<const std::uint8_t*>(s), 4));
  EXPECT_EQ(recordingCrc32(std::span(reinterpret_cast<const std::uint8_t*>(s) + 4, 5), a), 0xCBF43926u);
  EXPECT_EQ(recordingCrc32({}), 0u);
}

TEST_F(RecordingTest, RoundTripIsBitExact) {
  const auto recs = makeRecords(7, 500);
  RawRecordingHeader h;
  h.vendor_id = 0x1532;
  h.product_id = 0x0300;
  h.created_unix_ns = 1'700'000'000'123'456'789;
  h.description = "Razer Hydra, HID interface 0 (test)";
  const auto path = write(recs, h);
  const RawRecording r = RawRecording::load(path);
  EXPECT_EQ(r.header().vendor_id, 0x1532);
  EXPECT_EQ(r.header().product_id, 0x0300);
  EXPECT_EQ(r.header().created_unix_ns, h.created_unix_ns);
  EXPECT_EQ(r.header().description, h.description);
  EXPECT_EQ(r.header().version, 1);
  EXPECT_FALSE(r.truncatedTail());
  ASSERT_EQ(r.size(), recs.size());
  for (std::size_t i = 0; i < recs.size(); ++i) {
    const RawRecordView v = r.record(i);
    EXPECT_EQ(v.receive_ns, recs[i].ns);
    EXPECT_EQ(v.channel, recs[i].channel);
    ASSERT_EQ(v.bytes.size(), recs[i].bytes.size());
    EXPECT_TRUE(std::equal(v.bytes.begin(), v.bytes.end(), recs[i].bytes.begin())) << "record " << i;
  }
  // Replay as fast as possible yields the same sequence, bit for bit.
  RawReplay replay(r, {Pacing::kAsFastAsPossible, 1.0, false});
  std::size_t i = 0;
  bool same = true;
  const PacedRunStats stats = replay.run([&](const RawRecordView& v) {
    same = same && v.receive_ns == recs[i].ns && v.channel == recs[i].channel &&
           v.bytes.size() == recs[i].bytes.size() && std::equal(v.bytes.begin(), v.bytes.end(), recs[i].bytes.begin());
    ++i;
  });
  EXPECT_TRUE(same);
  EXPECT_EQ(stats.items, recs.size());
}

TEST_F(RecordingTest, HeaderLayoutMatchesTheDocumentation) {
  RawRecordingHeader h;
  h.vendor_id = 0xABCD;
  h.product_id = 0x1234;
  h.description = "xy";
  const auto path = write({{5, 2, {0xAA, 0xBB}}}, h);
  const auto b = readAll(path);
  // 26 fixed bytes + 2 description + 4 CRC, then one record of 20 + 2 + 4 bytes.
  ASSERT_EQ(b.size(), 32u + 26u);
  EXPECT_EQ(std::string(b.begin(), b.begin() + 8), "TETRIGRW");
  EXPECT_EQ(b[8] | (b[9] << 8), 1);
  EXPECT_EQ(b[10] | (b[11] << 8), 32);
  EXPECT_EQ(b[12] | (b[13] << 8), 0xABCD);
  EXPECT_EQ(b[14] | (b[15] << 8), 0x1234);
  EXPECT_EQ(b[24] | (b[25] << 8), 2);
  EXPECT_EQ(b[26], 'x');
  const std::uint32_t crc = b[28] | (b[29] << 8) | (b[30] << 16) | (static_cast<std::uint32_t>(b[31]) << 24);
  EXPECT_EQ(crc, recordingCrc32(std::span(b.data(), 28)));
  EXPECT_EQ(std::string(b.begin() + 32, b.begin() + 36), "REC1");
  EXPECT_EQ(b[32 + 4], 5);        // receive_ns low byte
  EXPECT_EQ(b[32 + 12], 2);       // channel
  EXPECT_EQ(b[32 + 16], 2);       // length
  EXPECT_EQ(b[32 + 20], 0xAA);
  const std::uint32_t rcrc = b[54] | (b[55] << 8) | (b[56] << 16) | (static_cast<std::uint32_t>(b[57]) << 24);
  EXPECT_EQ(rcrc, recordingCrc32(std::span(b.data() + 32, 22)));
}

TEST_F(RecordingTest, RealTimeReplayKeepsRelativeTiming) {
  const std::vector<Rec> recs = {{1'000'000'000, 1, {1}}, {1'004'000'000, 1, {2}}, {1'004'000'000, 2, {3}},
                                 {1'010'000'000, 1, {4}}, {1'003'000'000, 1, {5}}};  // last goes backwards
  const auto path = write(recs, {});
  const RawRecording r = RawRecording::load(path);
  RawReplay replay(r, {});
  std::int64_t now = 777;
  std::vector<std::int64_t> sleeps;
  std::vector<std::int64_t> released;
  replay.run([&](const RawRecordView&) { released.push_back(now); }, nullptr, FakeClock{&now, &sleeps});
  ASSERT_EQ(released.size(), 5u);
  const std::int64_t expected[] = {0, 4'000'000, 4'000'000, 10'000'000, 10'000'000};  // clamped, never earlier
  for (int i = 0; i < 5; ++i) EXPECT_EQ(released[static_cast<std::size_t>(i)], 777 + expected[i]) << i;
  EXPECT_EQ(replay.relativeTimeNs(4), 10'000'000);
  // Twice as fast halves every gap.
  RawReplay fast(r, {Pacing::kRealTime, 2.0, false});
  now = 0;
  released.clear();
  fast.run([&](const RawRecordView&) { released.push_back(now); }, nullptr, FakeClock{&now, &sleeps});
  EXPECT_EQ(released[3], 5'000'000);
}

TEST_F(RecordingTest, LoopingReplayRepeatsAfterOneMeanGap) {
  const std::vector<Rec> recs = {{0, 1, {1}}, {2'000'000, 1, {2}}, {4'000'000, 1, {3}}};
  const RawRecording r = RawRecording::load(write(recs, {}));
  RawReplay replay(r, {Pacing::kRealTime, 1.0, true});
  EXPECT_EQ(replay.loopPeriodNs(), 6'000'000);
  std::int64_t now = 0;
  std::vector<std::int64_t> sleeps;
  std::vector<std::int64_t> released;
  std::vector<std::uint8_t> payloads;
  replay.run(
      [&](const RawRecordView& v) {
        released.push_back(now);
        payloads.push_back(v.bytes[0]);
        return released.size() < 7;
      },
      nullptr, FakeClock{&now, &sleeps});
  ASSERT_EQ(released.size(), 7u);
  EXPECT_EQ(payloads, (std::vector<std::uint8_t>{1, 2, 3, 1, 2, 3, 1}));
  EXPECT_EQ(released[3], 6'000'000);
  EXPECT_EQ(released[6], 12'000'000);
}

TEST_F(RecordingTest, DamageIsDetectedWithOffsets) {
  const auto recs = makeRecords(3, 20);
  const auto path = write(recs, {0x1, 0x2, 0, "d", 1});
  const auto good = readAll(path);
  ASSERT_NO_THROW((void)RawRecording::parse(good, "good"));
  // Payload bit flip: CRC mismatch naming the record.
  const std::size_t header = 26 + 1 + 4;
  auto bad = good;
  bad[header + 20 + 0] ^= 0x01;  // first payload byte of record 0 (its payload may be empty: then it hits the CRC)
  try {
    (void)RawRecording::parse(bad, "bad.trr");
    FAIL();
  } catch (const RawRecordingError& e) {
    EXPECT_NE(std::string(e.what()).find("bad.trr: "), std::string::npos);
    EXPECT_NE(std::string(e.what()).find("record 0"), std::string::npos) << e.what();
  }
  // Header damage.
  bad = good;
  bad[20] ^= 0x40;
  EXPECT_THROW((void)RawRecording::parse(bad, "h"), RawRecordingError);
  bad = good;
  bad[0] = 'X';
  EXPECT_THROW((void)RawRecording::parse(bad, "m"), RawRecordingError);
  bad = good;
  bad[8] = 2;
  EXPECT_THROW((void)RawRecording::parse(bad, "v"), RawRecordingError);
  // Sync word damage.
  bad = good;
  bad[header] = 'X';
  EXPECT_THROW((void)RawRecording::parse(bad, "s"), RawRecordingError);
}

TEST_F(RecordingTest, EveryTruncationFailsOrYieldsAPrefix) {
  const auto recs = makeRecords(11, 12);
  const auto good = readAll(write(recs, {}));
  // Record boundaries: a cut exactly there is a valid, shorter recording.
  std::vector<std::size_t> ends = {30};
  for (const Rec& r : recs) ends.push_back(ends.back() + 24 + r.bytes.size());
  ASSERT_EQ(ends.back(), good.size());
  for (std::size_t len = 0; len < good.size(); ++len) {
    const std::vector<std::uint8_t> cut(good.begin(), good.begin() + static_cast<std::ptrdiff_t>(len));
    std::size_t complete = 0;
    while (complete + 1 < ends.size() && ends[complete + 1] <= len) ++complete;
    const bool at_boundary = len >= 30 && ends[complete] == len;
    if (at_boundary) {
      const RawRecording r = RawRecording::parse(cut, "cut");
      EXPECT_EQ(r.size(), complete);
      continue;
    }
    EXPECT_THROW((void)RawRecording::parse(cut, "cut"), RawRecordingError) << len;
    if (len >= 30) {
      const RawRecording r = RawRecording::parse(cut, "cut", true);
      EXPECT_TRUE(r.truncatedTail());
      ASSERT_EQ(r.size(), complete) << len;
      for (std::size_t i = 0; i < complete; ++i) EXPECT_EQ(r.record(i).receive_ns, recs[i].ns);
    }
  }
}

TEST_F(RecordingTest, RecorderRejectsBadInput) {
  RawRecordingHeader h;
  h.description.assign(kRawRecordingMaxDescription + 1, 'x');
  EXPECT_THROW(RawRecorder(dir_ / "big.trr", h), RawRecordingError);
  EXPECT_THROW(RawRecorder(dir_ / "no/such/dir/x.trr", {}), RawRecordingError);
  RawRecorder rec(dir_ / "ok.trr", {});
  rec.close();
  const std::uint8_t b[1] = {0};
  EXPECT_THROW(rec.write(0, 0, b), RawRecordingError);
  EXPECT_THROW(RawReplay(RawRecording::load(dir_ / "ok.trr"), {Pacing::kRealTime, 0.0, false}), std::invalid_argument);
}

TEST_F(RecordingTest, AnExistingRecordingStaysWholeUntilClose) {
  const auto recs = makeRecords(7, 20);
  const auto path = write(recs, {}, "session.trr");
  const std::vector<std::uint8_t> old_bytes = readAll(path);
  {
    RawRecorder rec(path, {});
    EXPECT_EQ(rec.temporaryPath().parent_path(), dir_);
    EXPECT_NE(rec.temporaryPath(), path);
    for (int i = 0; i < 5; ++i) rec.write(1, 1000 + i, recs[static_cast<std::size_t>(i)].bytes);
    rec.flush();
    EXPECT_EQ(readAll(path), old_bytes);  // not truncated, not half-written
    EXPECT_TRUE(std::filesystem::exists(rec.temporaryPath()));
    rec.close();
    EXPECT_TRUE(rec.temporaryPath().empty());
  }
  const RawRecording r = RawRecording::load(path);
  ASSERT_EQ(r.size(), 5u);
  EXPECT_EQ(r.record(4).receive_ns, 1004);
  EXPECT_TRUE(temporaries(dir_).empty());
  // Destroyed without close(): finished all the same.
  {
    RawRecorder rec(dir_ / "dropped.trr", {});
    rec.write(2, 7, recs[0].bytes);
  }
  EXPECT_EQ(RawRecording::load(dir_ / "dropped.trr").size(), 1u);
  EXPECT_TRUE(temporaries(dir_).empty());
}

TEST_F(RecordingTest, RecorderHonoursTheUmaskAndKeepsAnExistingMode) {
  const mode_t old_mask = ::umask(077);
  { RawRecorder(dir_ / "private.trr", {}).close(); }
  EXPECT_EQ(modeOf(dir_ / "private.trr"), 0600u);
  ::umask(022);
  { RawRecorder(dir_ / "shared.trr", {}).close(); }
  EXPECT_EQ(modeOf(dir_ / "shared.trr"), 0644u);
  ASSERT_EQ(::chmod((dir_ / "shared.trr").c_str(), 0640), 0);
  ::umask(077);
  { RawRecorder(dir_ / "shared.trr", {}).close(); }
  EXPECT_EQ(modeOf(dir_ / "shared.trr"), 0640u);
  ::umask(old_mask);
}

TEST_F(RecordingTest, RecorderDoesNotWriteThroughPlantedLinks) {
  const std::vector<std::uint8_t> secret = {'s', 'e', 'c', 'r', 'e', 't'};
  {
    std::ofstream(dir_ / "victim", std::ios::binary).write(reinterpret_cast<const char*>(secret.data()), 6);
  }
  std::filesystem::create_symlink(dir_ / "victim", dir_ / "rec.trr");      // at the target
  std::filesystem::create_symlink(dir_ / "victim", dir_ / "rec.trr.tmp");  // at a predictable temporary name
  RawRecorder rec(dir_ / "rec.trr", {});
  rec.write(1, 1, secret);
  rec.close();
  EXPECT_EQ(readAll(dir_ / "victim"), secret);
  EXPECT_FALSE(std::filesystem::is_symlink(dir_ / "rec.trr"));
  EXPECT_TRUE(std::filesystem::is_symlink(dir_ / "rec.trr.tmp"));
  EXPECT_EQ(RawRecording::load(dir_ / "rec.trr").size(), 1u);
}

TEST_F(RecordingTest, AFailedRecordingLeavesNoTemporaryAndTheOldFile) {
  const auto recs = makeRecords(9, 4);
  const auto path = write(recs, {}, "keep.trr");
  const std::vector<std::uint8_t> old_bytes = readAll(path);
  {
    RawRecorder rec(path, {});
    const std::vector<std::uint8_t> big(256 * 1024, 0x5a);
    // The disk fills up: files of this process may not grow beyond 64 KiB (SIGXFSZ ignored, so
    // write(2) fails with EFBIG).
    void (*old_handler)(int) = std::signal(SIGXFSZ, SIG_IGN);
    rlimit old_limit{};
    ::getrlimit(RLIMIT_FSIZE, &old_limit);
    rlimit limit = old_limit;
    limit.rlim_cur = 64 * 1024;
    ::setrlimit(RLIMIT_FSIZE, &limit);
    std::string what;
    try {
      for (int i = 0; i < 8; ++i) rec.write(1, i, big);
      rec.close();
    } catch (const RawRecordingError& e) {
      what = e.what();
    }
    ::setrlimit(RLIMIT_FSIZE, &old_limit);
    std::signal(SIGXFSZ, old_handler);
    EXPECT_NE(what.find("the recording is abandoned"), std::string::npos) << what;
    EXPECT_TRUE(rec.temporaryPath().empty());
    EXPECT_THROW(rec.write(1, 1, recs[0].bytes), RawRecordingError);  // abandoned: no more writes
    EXPECT_NO_THROW(rec.close());
  }
  EXPECT_EQ(readAll(path), old_bytes);
  EXPECT_TRUE(temporaries(dir_).empty());
}

}  // namespace
}  // namespace tetrig::drivers
