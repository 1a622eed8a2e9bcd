// Tests for the tetrig marker-stream protocol (drivers/src/marker_stream*.cpp, crc32c.cpp).
// Golden frames below are written byte by byte from docs/protocol.md; their CRCs were computed
// with an independent bitwise CRC-32C (Python, from the parameters in the spec), not with the
// code under test.
#include "tetrig/drivers/marker_stream.hpp"

#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <memory>
#include <new>
#include <random>
#include <string>
#include <vector>

#include "tetrig/drivers/crc32c.hpp"

#include "counting_allocator.hpp"

namespace {

using namespace tetrig::drivers;
using tetrig::MarkerFrame;
using Bytes = std::vector<std::uint8_t>;
using S = MarkerStreamStatus;

// Position format, 2 markers, counter 0x12345678, device time 1 s.
const Bytes kGoldenPosition = {
    0x54, 0x4D, 0x53, 0x46,                          // magic "TMSF"
    0x01, 0x00, 0x1C, 0x00,                          // version 1.0, header 28, format 0 (position)
    0x40, 0x00, 0x02, 0x00,                          // frame_length 64, marker_count 2
    0x78, 0x56, 0x34, 0x12,                          // frame_counter 0x12345678
    0x00, 0xCA, 0x9A, 0x3B, 0x00, 0x00, 0x00, 0x00,  // device_time_ns 1'000'000'000
    0x00, 0x00, 0x00, 0x00,                          // frame_flags 0, reserved
    0x07, 0x00, 0x01, 0x00,                          // marker id 7, valid
    0x00, 0x00, 0x80, 0x3F,                          //   x = 1.0
    0x00, 0x00, 0x20, 0xC0,                          //   y = -2.5
    0x00, 0x00, 0x7A, 0x44,                          //   z = 1000.0
    0x02, 0x01, 0x00, 0x00,                          // marker id 0x0102, not valid
    0x00, 0x00, 0x00, 0x3F,                          //   x = 0.5 (ignored)
    0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,  //   y, z = 0
    0x7D, 0x9B, 0xEF, 0x5D,                          // CRC-32C 0x5DEF9B7D
};

// Pose format, 1 marker with orientation (0, 0, 0, 2) (not unit: the decoder normalises it).
const Bytes kGoldenPose = {
    0x54, 0x4D, 0x53, 0x46,                          // magic
    0x01, 0x00, 0x1C, 0x01,                          // version 1.0, header 28, format 1 (pose)
    0x40, 0x00, 0x01, 0x00,                          // frame_length 64, marker_count 1
    0x05, 0x00, 0x00, 0x00,                          // frame_counter 5
    0xE8, 0x03, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,  // device_time_ns 1000
    0x00, 0x00, 0x00, 0x00,                          // flags, reserved
    0x2A, 0x00, 0x03, 0x00,                          // id 42, valid | has_orientation
    0x00, 0x00, 0xC8, 0x42,                          //   x = 100
    0x00, 0x00, 0x48, 0xC3,                          //   y = -200
    0x00, 0x00, 0x00, 0x00,                          //   z = 0
    0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,  //   qw = 0, qx = 0
    0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x40,  //   qy = 0, qz = 2
    0x32, 0x80, 0x40, 0x26,                          // CRC-32C 0x26408032
};

void putU32(Bytes& b, std::size_t at, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) b[at + static_cast<std::size_t>(i)] = static_cast<std::uint8_t>(v >> (8 * i));
}
// Recomputes the trailing CRC after a test edits a frame on purpose.
void fixCrc(Bytes& b) {
  const std::size_t body = b.size() - 4;
  putU32(b, body, crc32c(std::span<const std::uint8_t>(b.data(), body)));
}

std::unique_ptr<MarkerFrame> sentinelFrame() {
  auto f = std::make_unique<MarkerFrame>();
  f->frame_counter = 0xDEAD;
  f->marker_count = 99;
  return f;
}
void expectUntouched(const MarkerFrame& f) {
  EXPECT_EQ(f.frame_counter, 0xDEADu);
  EXPECT_EQ(f.marker_count, 99u);
}

// A frame with `n` markers, counter `counter`, position-format payload, correct CRC.
Bytes makeFrame(std::uint32_t counter, std::size_t n = 1, std::uint16_t flags = 0,
                MarkerRecordFormat format = MarkerRecordFormat::kPosition) {
  auto f = std::make_unique<MarkerFrame>();
  f->frame_counter = counter;
  f->device_timestamp_ns = 1234;
  f->marker_count = static_cast<std::uint16_t>(n);
  for (std::size_t i = 0; i < n; ++i) {
    f->markers[i].id = static_cast<std::uint16_t>(i);
    f->markers[i].valid = 1;
    f->markers[i].position_mm[0] = static_cast<float>(i);
  }
  Bytes b(kMarkerStreamMaxFrameSize);
  MarkerStreamEncodeOptions o;
  o.frame_flags = flags;
  o.record_format = format;
  b.resize(encodeMarkerStreamFrame(*f, o, b));
  return b;
}

// ---------------------------------------------------------------------------------------------

TEST(Crc32c, KnownCheckValues) {
  const std::string check = "123456789";
  EXPECT_EQ(crc32c(std::span(reinterpret_cast<const std::uint8_t*>(check.data()), check.size())), kCrc32cCheck);
  EXPECT_EQ(kCrc32cCheck, 0xE3069283u);
  // RFC 3720 (iSCSI) appendix B.4 test vectors.
  Bytes zeros(32, 0x00), ones(32, 0xFF), inc(32), dec(32);
  for (std::size_t i = 0; i < 32; ++i) {
    inc[i] = static_cast<std::uint8_t>(i);
    dec[i] = static_cast<std::uint8_t>(31 - i);
  }
  EXPECT_EQ(crc32c(zeros), 0x8A9136AAu);
  EXPECT_EQ(crc32c(ones), 0x62A8AB43u);
  EXPECT_EQ(crc32c(inc), 0x46DD794Eu);
  EXPECT_EQ(crc32c(dec), 0x113FDB5Cu);
  EXPECT_EQ(crc32c({}), 0u);
}

TEST(Crc32c, PiecewiseEqualsWhole) {
  Bytes data(1000);
  std::mt19937 rng(7);
  for (auto& b : data) b = static_cast<std::uint8_t>(rng());
  const std::uint32_t whole = crc32c(data);
  for (std::size_t cut : {0u, 1u, 7u, 8u, 9u, 500u, 999u, 1000u}) {
    const std::span<const std::uint8_t> all(data);
    EXPECT_EQ(crc32c(all.subspan(cut), crc32c(all.first(cut))), whole) << "cut " << cut;
  }
}

TEST(MarkerStream, GoldenPositionFrameDecodes) {
  MarkerStreamDecoder dec;
  auto out = std::make_unique<MarkerFrame>();
  ASSERT_EQ(dec.decodeFrame(kGoldenPosition, 555, *out), S::kFrame);
  EXPECT_EQ(out->frame_counter, 0x12345678u);
  EXPECT_EQ(out->device_timestamp_ns, 1000000000);
  EXPECT_EQ(out->receive_timestamp_ns, 555);
  EXPECT_EQ(out->flags, 0u);
  EXPECT_EQ(out->marker_count, 2u);
  EXPECT_EQ(out->rejected_count, 0u);
  const auto& m0 = out->markers[0];
  EXPECT_EQ(m0.id, 7u);
  EXPECT_EQ(m0.valid, 1u);
  EXPECT_EQ(m0.position_mm[0], 1.0f);
  EXPECT_EQ(m0.position_mm[1], -2.5f);
  EXPECT_EQ(m0.position_mm[2], 1000.0f);
  EXPECT_EQ(m0.has_orientation, 0u);
  const auto& m1 = out->markers[1];
  EXPECT_EQ(m1.id, 0x0102u);
  EXPECT_EQ(m1.valid, 0u);
  EXPECT_EQ(m1.position_mm[0], 0.0f);  // invalid markers carry no position
  EXPECT_EQ(dec.stats().frames_decoded, 1u);
}

TEST(MarkerStream, GoldenPoseFrameDecodesWithNormalisedQuaternion) {
  MarkerStreamDecoder dec;
  auto out = std::make_unique<MarkerFrame>();
  ASSERT_EQ(dec.decodeFrame(kGoldenPose, 0, *out), S::kFrame);
  EXPECT_EQ(out->frame_counter, 5u);
  EXPECT_EQ(out->device_timestamp_ns, 1000);
  ASSERT_EQ(out->marker_count, 1u);
  const auto& m = out->markers[0];
  EXPECT_EQ(m.id, 42u);
  EXPECT_EQ(m.valid, 1u);
  EXPECT_EQ(m.has_orientation, 1u);
  EXPECT_EQ(m.position_mm[0], 100.0f);
  EXPECT_EQ(m.position_mm[1], -200.0f);
  EXPECT_EQ(m.orientation[0], 0.0f);
  EXPECT_EQ(m.orientation[3], 1.0f);
}

TEST(MarkerStream, EncoderReproducesGoldenBytes) {
  auto f = std::make_unique<MarkerFrame>();
  f->frame_counter = 0x12345678;
  f->device_timestamp_ns = 1000000000;
  f->marker_count = 2;
  f->markers[0].id = 7;
  f->markers[0].valid = 1;
  f->markers[0].position_mm[0] = 1.0f;
  f->markers[0].position_mm[1] = -2.5f;
  f->markers[0].position_mm[2] = 1000.0f;
  f->markers[1].id = 0x0102;
  f->markers[1].valid = 0;
  f->markers[1].position_mm[0] = 0.5f;
  Bytes out(200, 0xEE);
  ASSERT_EQ(encodeMarkerStreamFrame(*f, {}, out), kGoldenPosition.size());
  out.resize(kGoldenPosition.size());
  EXPECT_EQ(out, kGoldenPosition);

  auto g = std::make_unique<MarkerFrame>();
  g->frame_counter = 5;
  g->device_timestamp_ns = 1000;
  g->marker_count = 1;
  g->markers[0] = {};
  g->markers[0].id = 42;
  g->markers[0].valid = 1;
  g->markers[0].has_orientation = 1;
  g->markers[0].position_mm[0] = 100.0f;
  g->markers[0].position_mm[1] = -200.0f;
  const float q[4] = {0.0f, 0.0f, 0.0f, 2.0f};
  std::memcpy(g->markers[0].orientation, q, sizeof q);
  MarkerStreamEncodeOptions o;
  o.record_format = MarkerRecordFormat::kPose;
  Bytes out2(200);
  ASSERT_EQ(encodeMarkerStreamFrame(*g, o, out2), kGoldenPose.size());
  out2.resize(kGoldenPose.size());
  EXPECT_EQ(out2, kGoldenPose);
  // Too small an output buffer: nothing written.
  Bytes small(kGoldenPose.size() - 1);
  EXPECT_EQ(encodeMarkerStreamFrame(*g, o, small), 0u);
}

TEST(MarkerStream, RoundTripRandomFramesBothFormats) {
  std::mt19937 rng(1234);
  std::uniform_real_distribution<float> pos(-5000.0f, 5000.0f);
  std::uniform_real_distribution<float> qd(-1.0f, 1.0f);
  for (auto format : {MarkerRecordFormat::kPosition, MarkerRecordFormat::kPose}) {
    MarkerStreamDecoder dec;
    for (std::uint32_t c = 0; c < 20; ++c) {
      auto in = std::make_unique<MarkerFrame>();
      in->frame_counter = 100 + c;
      in->device_timestamp_ns = static_cast<std::int64_t>(c) * 8333333 - 5;
      in->marker_count = static_cast<std::uint16_t>(c == 0 ? 256 : 41);
      for (std::size_t i = 0; i < in->marker_count; ++i) {
        auto& m = in->markers[i];
        m.id = static_cast<std::uint16_t>(rng());
        m.valid = (rng() % 5) != 0 ? 1 : 0;
        for (float& p : m.position_mm) p = pos(rng);
        float n = 0.0f;
        for (float& q : m.orientation) {
          q = qd(rng);
          n += q * q;
        }
        n = std::sqrt(n);
        for (float& q : m.orientation) q /= n;
        m.has_orientation = m.valid;
      }
      MarkerStreamEncodeOptions o;
      o.record_format = format;
      Bytes bytes(kMarkerStreamMaxFrameSize);
      bytes.resize(encodeMarkerStreamFrame(*in, o, bytes));
      ASSERT_EQ(bytes.size(), markerStreamFrameSize(in->marker_count, format));
      auto out = std::make_unique<MarkerFrame>();
      ASSERT_EQ(dec.decodeFrame(bytes, 9, *out), S::kFrame);
      EXPECT_EQ(out->frame_counter, in->frame_counter);
      EXPECT_EQ(out->device_timestamp_ns, in->device_timestamp_ns);
      ASSERT_EQ(out->marker_count, in->marker_count);
      for (std::size_t i = 0; i < in->marker_count; ++i) {
        const auto& a = in->markers[i];
        const auto& b = out->markers[i];
        ASSERT_EQ(b.id, a.id);
        ASSERT_EQ(b.valid, a.valid);
        if (a.valid == 0) continue;
        for (int k = 0; k < 3; ++k) ASSERT_EQ(b.position_mm[k], a.position_mm[k]);  // bit-exact
        if (format == MarkerRecordFormat::kPose) {
          ASSERT_EQ(b.has_orientation, 1u);
          for (int k = 0; k < 4; ++k) ASSERT_NEAR(b.orientation[k], a.orientation[k], 1e-6f);
        } else {
          ASSERT_EQ(b.has_orientation, 0u);
        }
      }
    }
    EXPECT_EQ(dec.stats().frames_decoded, 20u);
    EXPECT_EQ(dec.stats().frames_lost, 0u);
  }
}

TEST(MarkerStream, EveryTruncationIsReportedAndLeavesOutputAlone) {
  for (const Bytes* golden : {&kGoldenPosition, &kGoldenPose}) {
    MarkerStreamDecoder dec;
    auto out = sentinelFrame();
    for (std::size_t len = 0; len < golden->size(); ++len) {
      const std::span<const std::uint8_t> cut(golden->data(), len);
      EXPECT_EQ(dec.decodeFrame(cut, 0, *out), S::kTruncated) << "length " << len;
      MarkerStreamHeader h;
      EXPECT_EQ(validateMarkerStreamFrame(cut, h), S::kTruncated) << "length " << len;
    }
    expectUntouched(*out);
    EXPECT_EQ(dec.stats().format_errors, golden->size());
    EXPECT_EQ(dec.stats().frames_decoded, 0u);
  }
  // A 41-marker frame, too.
  const Bytes big = makeFrame(3, 41);
  MarkerStreamDecoder dec;
  auto out = sentinelFrame();
  for (std::size_t len = 0; len < big.size(); ++len) {
    ASSERT_EQ(dec.decodeFrame(std::span(big.data(), len), 0, *out), S::kTruncated) << len;
  }
  ASSERT_EQ(dec.decodeFrame(big, 0, *out), S::kFrame);
}

TEST(MarkerStream, BadMagicIsRejected) {
  for (std::size_t i = 0; i < 4; ++i) {
    Bytes b = kGoldenPosition;
    b[i] ^= 0x20;
    fixCrc(b);
    MarkerStreamDecoder dec;
    auto out = sentinelFrame();
    EXPECT_EQ(dec.decodeFrame(b, 0, *out), S::kBadMagic) << "byte " << i;
    expectUntouched(*out);
    EXPECT_EQ(dec.stats().format_errors, 1u);
  }
}

TEST(MarkerStream, CorruptedBytesNeverDecode) {
  // Flip every bit of the frame in turn: nothing may decode, and a flip inside the records or
  // the CRC itself must be reported as a CRC error.
  for (std::size_t byte = 0; byte < kGoldenPosition.size(); ++byte) {
    for (int bit = 0; bit < 8; ++bit) {
      Bytes b = kGoldenPosition;
      b[byte] = static_cast<std::uint8_t>(b[byte] ^ (1u << bit));
      MarkerStreamDecoder dec;
      auto out = sentinelFrame();
      const S st = dec.decodeFrame(b, 0, *out);
      ASSERT_NE(st, S::kFrame) << "byte " << byte << " bit " << bit;
      if (byte >= 24) {
        ASSERT_EQ(st, S::kBadCrc) << "byte " << byte << " bit " << bit;
        ASSERT_EQ(dec.stats().crc_errors, 1u);
      }
      expectUntouched(*out);
    }
  }
}

TEST(MarkerStream, UnknownMajorVersionIsRejectedWithoutParsingFurther) {
  Bytes b = kGoldenPosition;
  b[4] = 2;
  fixCrc(b);
  MarkerStreamDecoder dec;
  auto out = sentinelFrame();
  EXPECT_EQ(dec.decodeFrame(b, 0, *out), S::kUnsupportedVersion);
  // A v2 frame may be laid out entirely differently: even 5 bytes are enough to say so.
  const Bytes v2_short = {0x54, 0x4D, 0x53, 0x46, 0x02};
  EXPECT_EQ(dec.decodeFrame(v2_short, 0, *out), S::kUnsupportedVersion);
  const Bytes v0 = {0x54, 0x4D, 0x53, 0x46, 0x00, 0x00};
  EXPECT_EQ(dec.decodeFrame(v0, 0, *out), S::kUnsupportedVersion);
  expectUntouched(*out);
  EXPECT_EQ(dec.stats().version_errors, 3u);
  EXPECT_EQ(markerStreamPeekFrameLength(b), 0u);
}

TEST(MarkerStream, NewerMinorVersionWithLongerHeaderIsAccepted) {
  // v1.1 sender: header_size 32 (4 extra header bytes a v1.0 decoder skips), same records.
  Bytes b(kGoldenPosition.begin(), kGoldenPosition.begin() + 28);
  b[5] = 1;     // minor
  b[6] = 32;    // header_size
  b[8] = 68;    // frame_length = 32 + 2 * 16 + 4
  b.insert(b.end(), {0xAB, 0xCD, 0xEF, 0x01});  // unknown extension field
  b.insert(b.end(), kGoldenPosition.begin() + 28, kGoldenPosition.end() - 4);
  b.resize(b.size() + 4);
  fixCrc(b);
  ASSERT_EQ(b.size(), 68u);
  MarkerStreamDecoder dec;
  auto out = std::make_unique<MarkerFrame>();
  ASSERT_EQ(dec.decodeFrame(b, 0, *out), S::kFrame);
  EXPECT_EQ(out->markers[0].id, 7u);
  EXPECT_EQ(out->markers[0].position_mm[2], 1000.0f);
  EXPECT_EQ(markerStreamPeekFrameLength(b), 68u);
}

TEST(MarkerStream, BadHeaderFieldsAndLengths) {
  struct Case {
    std::size_t offset;
    std::uint8_t value;
    S expected;
  };
  const Case cases[] = {
      {6, 24, S::kBadHeader},   // header_size below 28
      {6, 30, S::kBadHeader},   // not a multiple of 4
      {6, 68, S::kBadHeader},   // above 64
      {7, 2, S::kBadHeader},    // unknown record format
      {8, 65, S::kBadLength},   // frame_length disagrees with count
      {10, 3, S::kBadLength},   // marker_count 3 but frame_length for 2
      {7, 1, S::kBadLength},    // pose format: frame_length should be 96
  };
  for (const auto& c : cases) {
    Bytes b = kGoldenPosition;
    b[c.offset] = c.value;
    fixCrc(b);
    MarkerStreamDecoder dec;
    auto out = sentinelFrame();
    EXPECT_EQ(dec.decodeFrame(b, 0, *out), c.expected) << "offset " << c.offset << " value " << int(c.value);
    expectUntouched(*out);
  }
  // marker_count above 256.
  Bytes b = kGoldenPosition;
  b[10] = 0x01;
  b[11] = 0x01;
  fixCrc(b);
  MarkerStreamDecoder dec;
  auto out = sentinelFrame();
  EXPECT_EQ(dec.decodeFrame(b, 0, *out), S::kBadHeader);
  // Trailing bytes after a whole frame.
  Bytes longer = kGoldenPosition;
  longer.push_back(0);
  EXPECT_EQ(dec.decodeFrame(longer, 0, *out), S::kBadLength);
  expectUntouched(*out);
  EXPECT_EQ(dec.stats().format_errors, 2u);
}

TEST(MarkerStream, SequenceGapsDuplicatesAndOutOfOrder) {
  MarkerStreamDecoder dec;
  auto out = std::make_unique<MarkerFrame>();
  ASSERT_EQ(dec.decodeFrame(makeFrame(10), 0, *out), S::kFrame);
  EXPECT_EQ(out->flags & tetrig::kFrameSequenceGap, 0u);
  ASSERT_EQ(dec.decodeFrame(makeFrame(11), 0, *out), S::kFrame);
  EXPECT_EQ(out->flags & tetrig::kFrameSequenceGap, 0u);
  ASSERT_EQ(dec.decodeFrame(makeFrame(14), 0, *out), S::kFrame);  // 12, 13 lost
  EXPECT_NE(out->flags & tetrig::kFrameSequenceGap, 0u);
  EXPECT_EQ(out->frame_counter, 14u);
  EXPECT_EQ(dec.stats().frames_lost, 2u);
  EXPECT_EQ(dec.stats().gap_events, 1u);

  out->frame_counter = 0xDEAD;
  EXPECT_EQ(dec.decodeFrame(makeFrame(14), 0, *out), S::kDuplicate);
  EXPECT_EQ(dec.decodeFrame(makeFrame(13), 0, *out), S::kOutOfOrder);
  EXPECT_EQ(dec.decodeFrame(makeFrame(2), 0, *out), S::kOutOfOrder);
  EXPECT_EQ(out->frame_counter, 0xDEADu);
  EXPECT_EQ(dec.stats().duplicates, 1u);
  EXPECT_EQ(dec.stats().out_of_order, 2u);

  ASSERT_EQ(dec.decodeFrame(makeFrame(15), 0, *out), S::kFrame);
  EXPECT_EQ(out->flags & tetrig::kFrameSequenceGap, 0u);
  EXPECT_EQ(out->frame_counter, 15u);
  EXPECT_EQ(dec.stats().frames_decoded, 4u);
  EXPECT_EQ(dec.stats().frames_lost, 2u);
  ASSERT_EQ(dec.decodeFrame(makeFrame(17), 0, *out), S::kFrame);  // exactly one lost
  EXPECT_NE(out->flags & tetrig::kFrameSequenceGap, 0u);
  EXPECT_EQ(dec.stats().frames_lost, 3u);
  EXPECT_EQ(dec.stats().gap_events, 2u);
}

TEST(MarkerStream, CounterWrapsAt32BitsAndStaysMonotonic) {
  MarkerStreamDecoder dec;
  auto out = std::make_unique<MarkerFrame>();
  ASSERT_EQ(dec.decodeFrame(makeFrame(0xFFFFFFFEu), 0, *out), S::kFrame);
  EXPECT_EQ(out->frame_counter, 0xFFFFFFFEull);
  ASSERT_EQ(dec.decodeFrame(makeFrame(0xFFFFFFFFu), 0, *out), S::kFrame);
  ASSERT_EQ(dec.decodeFrame(makeFrame(0u), 0, *out), S::kFrame);
  EXPECT_EQ(out->frame_counter, 0x100000000ull);
  EXPECT_EQ(out->flags & tetrig::kFrameSequenceGap, 0u);
  ASSERT_EQ(dec.decodeFrame(makeFrame(3u), 0, *out), S::kFrame);  // 1, 2 lost across the wrap
  EXPECT_EQ(out->frame_counter, 0x100000003ull);
  EXPECT_NE(out->flags & tetrig::kFrameSequenceGap, 0u);
  EXPECT_EQ(dec.stats().frames_lost, 2u);
  EXPECT_EQ(dec.decodeFrame(makeFrame(0xFFFFFFFFu), 0, *out), S::kOutOfOrder);  // behind, across the wrap
}

TEST(MarkerStream, StreamStartFlagResynchronises) {
  MarkerStreamDecoder dec;
  auto out = std::make_unique<MarkerFrame>();
  ASSERT_EQ(dec.decodeFrame(makeFrame(100), 0, *out), S::kFrame);
  // The device was stopped and started again: its counter restarts at 0.
  ASSERT_EQ(dec.decodeFrame(makeFrame(0, 1, kStreamFlagStreamStart), 0, *out), S::kFrame);
  EXPECT_EQ(out->frame_counter, 101u);  // the 64-bit counter stays monotonic
  EXPECT_EQ(out->flags & tetrig::kFrameSequenceGap, 0u);
  ASSERT_EQ(dec.decodeFrame(makeFrame(1), 0, *out), S::kFrame);
  EXPECT_EQ(out->frame_counter, 102u);
  EXPECT_EQ(dec.stats().resyncs, 1u);
  EXPECT_EQ(dec.stats().frames_lost, 0u);
}

TEST(MarkerStream, SilentDeviceRestartResynchronisesAfterConsecutiveOutOfOrder) {
  MarkerStreamDecoderOptions opt;
  opt.resync_after_out_of_order = 4;
  MarkerStreamDecoder dec(opt);
  auto out = std::make_unique<MarkerFrame>();
  ASSERT_EQ(dec.decodeFrame(makeFrame(5000), 0, *out), S::kFrame);
  for (std::uint32_t c = 0; c < 3; ++c) {
    EXPECT_EQ(dec.decodeFrame(makeFrame(c), 0, *out), S::kOutOfOrder) << c;
  }
  ASSERT_EQ(dec.decodeFrame(makeFrame(3), 0, *out), S::kFrame);
  EXPECT_EQ(out->frame_counter, 5001u);
  EXPECT_NE(out->flags & tetrig::kFrameSequenceGap, 0u);
  ASSERT_EQ(dec.decodeFrame(makeFrame(4), 0, *out), S::kFrame);
  EXPECT_EQ(out->frame_counter, 5002u);
  EXPECT_EQ(dec.stats().resyncs, 1u);
  // One stray old frame does not trigger a resync: the count restarts after every good frame.
  EXPECT_EQ(dec.decodeFrame(makeFrame(1), 0, *out), S::kOutOfOrder);
  ASSERT_EQ(dec.decodeFrame(makeFrame(5), 0, *out), S::kFrame);
  EXPECT_EQ(dec.decodeFrame(makeFrame(1), 0, *out), S::kOutOfOrder);
  EXPECT_EQ(dec.decodeFrame(makeFrame(2), 0, *out), S::kOutOfOrder);
  EXPECT_EQ(dec.decodeFrame(makeFrame(3), 0, *out), S::kOutOfOrder);
}

TEST(MarkerStream, NonFiniteAndAbsurdCoordinatesAreRejectedAndCounted) {
  const float inf = std::numeric_limits<float>::infinity();
  const float nan = std::numeric_limits<float>::quiet_NaN();
  auto in = std::make_unique<MarkerFrame>();
  in->frame_counter = 1;
  const float values[][3] = {
      {1.0f, 2.0f, 3.0f},              // 0 ok
      {nan, 0.0f, 0.0f},               // 1 NaN
      {0.0f, inf, 0.0f},               // 2 +inf
      {0.0f, 0.0f, -inf},              // 3 -inf
      {1.0e6f, 0.0f, 0.0f},            // 4 absurd (1 km)
      {0.0f, -100000.5f, 0.0f},        // 5 just beyond 100 m
      {100000.0f, -100000.0f, 0.0f},   // 6 exactly at the limit: ok
      {std::numeric_limits<float>::denorm_min(), -0.0f, 0.0f},  // 7 ok
      {nan, nan, nan},                 // 8 NaN but flagged invalid by the device: not "rejected"
  };
  in->marker_count = 9;
  for (std::uint16_t i = 0; i < in->marker_count; ++i) {
    in->markers[i].id = static_cast<std::uint16_t>(i + 100);
    in->markers[i].valid = i == 8 ? 0 : 1;
    std::memcpy(in->markers[i].position_mm, values[i], sizeof values[i]);
  }
  Bytes b(kMarkerStreamMaxFrameSize);
  b.resize(encodeMarkerStreamFrame(*in, {}, b));
  MarkerStreamDecoder dec;
  auto out = std::make_unique<MarkerFrame>();
  ASSERT_EQ(dec.decodeFrame(b, 0, *out), S::kFrame);
  EXPECT_EQ(out->rejected_count, 5u);
  EXPECT_NE(out->flags & tetrig::kFrameRejectedMarkers, 0u);
  EXPECT_EQ(dec.stats().rejected_markers, 5u);
  const int expect_valid[] = {1, 0, 0, 0, 0, 0, 1, 1, 0};
  for (std::size_t i = 0; i < 9; ++i) {
    const auto& m = out->markers[i];
    EXPECT_EQ(m.id, i + 100);
    EXPECT_EQ(m.valid, expect_valid[i]) << "marker " << i;
    for (float p : m.position_mm) EXPECT_TRUE(std::isfinite(p)) << "marker " << i;
  }
  EXPECT_EQ(out->markers[6].position_mm[0], 100000.0f);
  // A tighter limit from the options.
  MarkerStreamDecoderOptions opt;
  opt.max_abs_coordinate_mm = 2.5f;
  MarkerStreamDecoder strict(opt);
  ASSERT_EQ(strict.decodeFrame(b, 0, *out), S::kFrame);
  EXPECT_EQ(out->markers[0].valid, 0u);  // z = 3 > 2.5
  EXPECT_EQ(out->markers[7].valid, 1u);
  EXPECT_EQ(out->rejected_count, 7u);
  // A clean frame carries no rejection flag.
  ASSERT_EQ(dec.decodeFrame(makeFrame(2, 5), 0, *out), S::kFrame);
  EXPECT_EQ(out->flags & tetrig::kFrameRejectedMarkers, 0u);
  EXPECT_EQ(out->rejected_count, 0u);
}

TEST(MarkerStream, BadQuaternionsRejectTheMarker) {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float quats[][4] = {
      {0.5f, 0.5f, 0.5f, 0.5f},   // ok
      {0.0f, 0.0f, 0.0f, 0.0f},   // zero
      {nan, 0.0f, 0.0f, 1.0f},    // NaN
      {0.1f, 0.0f, 0.0f, 0.0f},   // far from unit
      {0.0f, 3.0f, 0.0f, 0.0f},   // far from unit
      {0.0f, std::numeric_limits<float>::infinity(), 0.0f, 0.0f},
  };
  auto in = std::make_unique<MarkerFrame>();
  in->marker_count = 6;
  for (std::size_t i = 0; i < 6; ++i) {
    in->markers[i].valid = 1;
    in->markers[i].has_orientation = 1;
    std::memcpy(in->markers[i].orientation, quats[i], sizeof quats[i]);
  }
  MarkerStreamEncodeOptions o;
  o.record_format = MarkerRecordFormat::kPose;
  Bytes b(kMarkerStreamMaxFrameSize);
  b.resize(encodeMarkerStreamFrame(*in, o, b));
  MarkerStreamDecoder dec;
  auto out = std::make_unique<MarkerFrame>();
  ASSERT_EQ(dec.decodeFrame(b, 0, *out), S::kFrame);
  EXPECT_EQ(out->rejected_count, 5u);
  EXPECT_EQ(out->markers[0].valid, 1u);
  EXPECT_EQ(out->markers[0].has_orientation, 1u);
  for (std::size_t i = 1; i < 6; ++i) {
    EXPECT_EQ(out->markers[i].valid, 0u) << i;
    EXPECT_EQ(out->markers[i].has_orientation, 0u) << i;
    EXPECT_EQ(out->markers[i].orientation[0], 1.0f) << i;
  }
}

TEST(MarkerStream, DeviceOverflowFlagMapsToTruncatedMarkers) {
  MarkerStreamDecoder dec;
  auto out = std::make_unique<MarkerFrame>();
  ASSERT_EQ(dec.decodeFrame(makeFrame(1, 3, kStreamFlagDeviceOverflow), 0, *out), S::kFrame);
  EXPECT_NE(out->flags & tetrig::kFrameTruncatedMarkers, 0u);
  ASSERT_EQ(dec.decodeFrame(makeFrame(2, 3), 0, *out), S::kFrame);
  EXPECT_EQ(out->flags & tetrig::kFrameTruncatedMarkers, 0u);
}

// ---------------------------------------------------------------------------------------------
// HID fragments.

// The golden position frame (64 bytes) as two hand-built reports: 58 + 6 payload bytes.
std::vector<Bytes> goldenReports() {
  Bytes r0 = {0x01, 0x78, 0x56, 0x00, 0x02, 0x3A};  // id, tag 0x5678, index 0, count 2, len 58
  r0.insert(r0.end(), kGoldenPosition.begin(), kGoldenPosition.begin() + 58);
  Bytes r1 = {0x01, 0x78, 0x56, 0x01, 0x02, 0x06};  // index 1, len 6
  r1.insert(r1.end(), kGoldenPosition.begin() + 58, kGoldenPosition.end());
  r1.resize(64, 0x00);
  return {r0, r1};
}

std::vector<Bytes> fragmentsOf(const Bytes& frame) {
  std::vector<Bytes> out;
  const std::size_t n = markerStreamFragmentCount(frame.size());
  for (std::size_t i = 0; i < n; ++i) {
    Bytes r(kMarkerStreamHidReportSize);
    EXPECT_EQ(encodeMarkerStreamFragment(frame, i, r), kMarkerStreamHidReportSize);
    out.push_back(r);
  }
  return out;
}

TEST(MarkerStreamHid, GoldenReportsReassembleAndMatchTheEncoder) {
  const auto reports = goldenReports();
  ASSERT_EQ(reports[0].size(), 64u);
  MarkerStreamDecoder dec;
  auto out = std::make_unique<MarkerFrame>();
  EXPECT_EQ(dec.decodeHidReport(reports[0], 0, *out), S::kNeedMore);
  ASSERT_EQ(dec.decodeHidReport(reports[1], 77, *out), S::kFrame);
  EXPECT_EQ(out->frame_counter, 0x12345678u);
  EXPECT_EQ(out->receive_timestamp_ns, 77);
  EXPECT_EQ(out->markers[0].position_mm[2], 1000.0f);
  // The encoder writes the same bytes (with zero padding).
  const auto enc = fragmentsOf(kGoldenPosition);
  ASSERT_EQ(enc.size(), 2u);
  EXPECT_EQ(enc[0], reports[0]);
  EXPECT_EQ(enc[1], reports[1]);
}

TEST(MarkerStreamHid, FortyOneMarkerFrameRoundTrip) {
  const Bytes frame = makeFrame(7, 41);
  ASSERT_EQ(frame.size(), 28u + 41u * 16u + 4u);
  const auto reports = fragmentsOf(frame);
  ASSERT_EQ(reports.size(), (frame.size() + 57) / 58);
  MarkerStreamDecoder dec;
  auto out = std::make_unique<MarkerFrame>();
  for (std::size_t i = 0; i + 1 < reports.size(); ++i) ASSERT_EQ(dec.decodeHidReport(reports[i], 0, *out), S::kNeedMore);
  ASSERT_EQ(dec.decodeHidReport(reports.back(), 0, *out), S::kFrame);
  EXPECT_EQ(out->marker_count, 41u);
  EXPECT_EQ(out->markers[40].position_mm[0], 40.0f);
  EXPECT_EQ(dec.reassembler().stats().frames, 1u);
}

TEST(MarkerStreamHid, LostFragmentDropsOnlyThatFrame) {
  const auto a = fragmentsOf(makeFrame(1, 41));
  const auto b = fragmentsOf(makeFrame(2, 41));
  MarkerStreamDecoder dec;
  auto out = sentinelFrame();
  ASSERT_EQ(dec.decodeHidReport(a[0], 0, *out), S::kNeedMore);
  ASSERT_EQ(dec.decodeHidReport(a[1], 0, *out), S::kNeedMore);
  // a[2] lost.
  EXPECT_EQ(dec.decodeHidReport(a[3], 0, *out), S::kFragmentLost);
  for (std::size_t i = 4; i < a.size(); ++i) EXPECT_EQ(dec.decodeHidReport(a[i], 0, *out), S::kFragmentLost) << i;
  expectUntouched(*out);
  // The next frame is complete.
  for (std::size_t i = 0; i + 1 < b.size(); ++i) ASSERT_EQ(dec.decodeHidReport(b[i], 0, *out), S::kNeedMore);
  ASSERT_EQ(dec.decodeHidReport(b.back(), 0, *out), S::kFrame);
  EXPECT_EQ(out->frame_counter, 2u);
  EXPECT_EQ(dec.reassembler().stats().partial_frames_dropped, 1u);
  EXPECT_EQ(dec.reassembler().stats().orphan_fragments, a.size() - 4);
}

TEST(MarkerStreamHid, ReorderedOrRepeatedFragmentsDropTheFrame) {
  const auto a = fragmentsOf(makeFrame(1, 41));
  {
    MarkerStreamDecoder dec;
    auto out = sentinelFrame();
    ASSERT_EQ(dec.decodeHidReport(a[0], 0, *out), S::kNeedMore);
    EXPECT_EQ(dec.decodeHidReport(a[2], 0, *out), S::kFragmentLost);  // swapped
    EXPECT_EQ(dec.decodeHidReport(a[1], 0, *out), S::kFragmentLost);
    for (std::size_t i = 3; i < a.size(); ++i) EXPECT_NE(dec.decodeHidReport(a[i], 0, *out), S::kFrame);
    expectUntouched(*out);
  }
  {
    MarkerStreamDecoder dec;
    auto out = sentinelFrame();
    ASSERT_EQ(dec.decodeHidReport(a[0], 0, *out), S::kNeedMore);
    ASSERT_EQ(dec.decodeHidReport(a[1], 0, *out), S::kNeedMore);
    EXPECT_EQ(dec.decodeHidReport(a[1], 0, *out), S::kFragmentLost);  // repeated
    expectUntouched(*out);
  }
}

TEST(MarkerStreamHid, NewFrameStartAbandonsPartialFrame) {
  const auto a = fragmentsOf(makeFrame(1, 41));
  const auto b = fragmentsOf(makeFrame(2, 41));
  MarkerStreamDecoder dec;
  auto out = std::make_unique<MarkerFrame>();
  ASSERT_EQ(dec.decodeHidReport(a[0], 0, *out), S::kNeedMore);
  ASSERT_EQ(dec.decodeHidReport(a[1], 0, *out), S::kNeedMore);
  for (std::size_t i = 0; i + 1 < b.size(); ++i) ASSERT_EQ(dec.decodeHidReport(b[i], 0, *out), S::kNeedMore);
  ASSERT_EQ(dec.decodeHidReport(b.back(), 0, *out), S::kFrame);
  EXPECT_EQ(out->frame_counter, 2u);
  EXPECT_EQ(dec.reassembler().stats().partial_frames_dropped, 1u);
  // Fragments of two frames interleaved (different tags): neither completes.
  const auto c = fragmentsOf(makeFrame(3, 41));
  const auto d = fragmentsOf(makeFrame(4, 41));
  ASSERT_EQ(dec.decodeHidReport(c[0], 0, *out), S::kNeedMore);
  EXPECT_EQ(dec.decodeHidReport(d[1], 0, *out), S::kFragmentLost);
}

TEST(MarkerStreamHid, OtherReportIdsAreIgnoredWithoutBreakingAFrame) {
  const auto reports = goldenReports();
  MarkerStreamDecoder dec;
  auto out = std::make_unique<MarkerFrame>();
  ASSERT_EQ(dec.decodeHidReport(reports[0], 0, *out), S::kNeedMore);
  Bytes other(64, 0);
  other[0] = 0x05;
  EXPECT_EQ(dec.decodeHidReport(other, 0, *out), S::kBadReport);
  ASSERT_EQ(dec.decodeHidReport(reports[1], 0, *out), S::kFrame);
  EXPECT_EQ(dec.stats().fragment_errors, 1u);
}

TEST(MarkerStreamHid, MalformedFragmentHeaders) {
  const auto reports = goldenReports();
  struct Case {
    std::size_t offset;
    std::uint8_t value;
    S expected;
  };
  const Case cases[] = {
      {5, 0, S::kBadFragment},    // payload length 0
      {5, 59, S::kBadFragment},   // more than 58
      {5, 57, S::kBadFragment},   // a non-last fragment must be full
      {4, 0, S::kBadFragment},    // count 0
      {3, 2, S::kBadFragment},    // index >= count
      {4, 200, S::kBadFragment},  // more fragments than the largest frame needs
  };
  for (const auto& c : cases) {
    Bytes r = reports[0];
    r[c.offset] = c.value;
    MarkerStreamReassembler ra;
    EXPECT_EQ(ra.push(r), c.expected) << "offset " << c.offset << " value " << int(c.value);
    EXPECT_EQ(ra.stats().bad_reports, 1u);
  }
  // Every truncated report length.
  for (std::size_t len = 0; len < 64; ++len) {
    MarkerStreamReassembler ra;
    const S st = ra.push(std::span(reports[0].data(), len));
    EXPECT_EQ(st, S::kTruncated) << len;
  }
  MarkerStreamReassembler ra;
  ASSERT_EQ(ra.push(reports[0]), S::kNeedMore);
  EXPECT_EQ(ra.push(std::span(reports[1].data(), 11)), S::kTruncated);  // 6 + 6 needed
  EXPECT_EQ(ra.stats().partial_frames_dropped, 1u);
  ASSERT_EQ(ra.push(reports[0]), S::kNeedMore);
  ASSERT_EQ(ra.push(std::span(reports[1].data(), 12)), S::kFrame);
  EXPECT_EQ(ra.frame().size(), 64u);
  EXPECT_TRUE(std::equal(ra.frame().begin(), ra.frame().end(), kGoldenPosition.begin()));
}

TEST(MarkerStreamHid, TagMustMatchTheFrameCounter) {
  auto reports = goldenReports();
  reports[0][1] = 0x79;  // tag 0x5679 in both fragments, frame counter low bits 0x5678
  reports[1][1] = 0x79;
  MarkerStreamDecoder dec;
  auto out = sentinelFrame();
  ASSERT_EQ(dec.decodeHidReport(reports[0], 0, *out), S::kNeedMore);
  EXPECT_EQ(dec.decodeHidReport(reports[1], 0, *out), S::kBadFragment);
  expectUntouched(*out);
}

TEST(MarkerStreamHid, CorruptPayloadIsCaughtByTheFrameCrc) {
  auto reports = goldenReports();
  reports[0][40] ^= 0x01;
  MarkerStreamDecoder dec;
  auto out = sentinelFrame();
  ASSERT_EQ(dec.decodeHidReport(reports[0], 0, *out), S::kNeedMore);
  EXPECT_EQ(dec.decodeHidReport(reports[1], 0, *out), S::kBadCrc);
  expectUntouched(*out);
}

TEST(MarkerStream, DecodingDoesNotAllocate) {
  const Bytes frame = makeFrame(1, 41);
  std::vector<Bytes> reports;
  std::vector<Bytes> frames;
  for (std::uint32_t c = 2; c < 50; ++c) {
    frames.push_back(makeFrame(c, 41));
    for (auto& r : fragmentsOf(makeFrame(c + 1000, 41))) reports.push_back(r);
  }
  MarkerStreamDecoder dec;
  MarkerStreamDecoder hid;
  auto out = std::make_unique<MarkerFrame>();
  const std::uint64_t before = ::tetrig::test::allocationCount();
  for (const auto& f : frames) EXPECT_EQ(dec.decodeFrame(f, 0, *out), S::kFrame);
  int decoded = 0;
  for (const auto& r : reports) decoded += hid.decodeHidReport(r, 0, *out) == S::kFrame ? 1 : 0;
  EXPECT_EQ(::tetrig::test::allocationCount(), before);
  EXPECT_EQ(decoded, 48);
}

// ---------------------------------------------------------------------------------------------
// Control and info.

TEST(MarkerStreamControl, CommandReportLayout) {
  Bytes r(64, 0xEE);
  ASSERT_EQ(encodeMarkerStreamCommandReport(MarkerStreamCommand::kSetRate, 240, r), 64u);
  Bytes expected(64, 0x00);
  expected[0] = 0x02;  // output report id
  expected[1] = 0x03;  // SET_RATE
  expected[2] = 0xF0;  // 240 Hz, LE
  expected[3] = 0x00;
  EXPECT_EQ(r, expected);
  MarkerStreamCommand cmd{};
  std::uint16_t param = 0;
  ASSERT_TRUE(decodeMarkerStreamCommandReport(r, cmd, param));
  EXPECT_EQ(cmd, MarkerStreamCommand::kSetRate);
  EXPECT_EQ(param, 240u);
  r[1] = 0x09;
  EXPECT_FALSE(decodeMarkerStreamCommandReport(r, cmd, param));
  r[1] = 0x01;
  r[0] = 0x01;
  EXPECT_FALSE(decodeMarkerStreamCommandReport(r, cmd, param));
  EXPECT_FALSE(decodeMarkerStreamCommandReport(std::span(expected.data(), 3), cmd, param));
  Bytes small(63);
  EXPECT_EQ(encodeMarkerStreamCommandReport(MarkerStreamCommand::kStart, 0, small), 0u);
}

TEST(MarkerStreamControl, UsbControlSetups) {
  const auto start = markerStreamControlSetup(MarkerStreamCommand::kStart, 1, 2);
  EXPECT_EQ(start.request_type, 0x41);
  EXPECT_EQ(start.request, 0x01);
  EXPECT_EQ(start.value, 1u);
  EXPECT_EQ(start.index, 2u);
  EXPECT_EQ(start.length, 0u);
  const auto info = markerStreamControlSetup(MarkerStreamCommand::kGetInfo, 0, 0);
  EXPECT_EQ(info.request_type, 0xC1);
  EXPECT_EQ(info.request, 0x04);
  EXPECT_EQ(info.length, 16u);
}

TEST(MarkerStreamControl, InfoBlockLayout) {
  MarkerStreamDeviceInfo in;
  in.streaming = 1;
  in.record_format = MarkerRecordFormat::kPose;
  in.max_markers = 64;
  in.rate_hz = 120;
  in.min_rate_hz = 30;
  in.max_rate_hz = 1000;
  Bytes b(16, 0xEE);
  ASSERT_EQ(encodeMarkerStreamInfo(in, b), 16u);
  const Bytes expected = {0x01, 0x00, 0x01, 0x01, 0x40, 0x00, 0x78, 0x00,
                          0x1E, 0x00, 0xE8, 0x03, 0x00, 0x00, 0x00, 0x00};
  EXPECT_EQ(b, expected);
  MarkerStreamDeviceInfo out;
  ASSERT_TRUE(decodeMarkerStreamInfo(b, out));
  EXPECT_EQ(out.max_rate_hz, 1000u);
  EXPECT_EQ(out.record_format, MarkerRecordFormat::kPose);
  b[3] = 7;
  EXPECT_FALSE(decodeMarkerStreamInfo(b, out));
  EXPECT_FALSE(decodeMarkerStreamInfo(std::span(expected.data(), 15), out));
}

TEST(MarkerStream, StatusNamesAreDistinct) {
  std::vector<std::string> names;
  for (int v = -11; v <= 1; ++v) {
    const std::string n = markerStreamStatusName(static_cast<S>(v));
    EXPECT_NE(n, "unknown status") << v;
    for (const auto& other : names) EXPECT_NE(n, other);
    names.push_back(n);
  }
  EXPECT_STREQ(markerStreamStatusName(static_cast<S>(-99)), "unknown status");
  EXPECT_STREQ(markerStreamStatusName(S::kBadCrc), "bad crc");
}

TEST(MarkerStream, PeekFrameLengthForByteStreams) {
  EXPECT_EQ(markerStreamPeekFrameLength(kGoldenPosition), 64u);
  EXPECT_EQ(markerStreamPeekFrameLength(std::span(kGoldenPosition.data(), 12)), 64u);
  EXPECT_EQ(markerStreamPeekFrameLength(std::span(kGoldenPosition.data(), 11)), 0u);
  Bytes bad = kGoldenPosition;
  bad[0] = 0;
  EXPECT_EQ(markerStreamPeekFrameLength(bad), 0u);
  bad = kGoldenPosition;
  bad[8] = 0xFF;
  bad[9] = 0xFF;  // 65535 > max frame size
  EXPECT_EQ(markerStreamPeekFrameLength(bad), 0u);
}

}  // namespace
