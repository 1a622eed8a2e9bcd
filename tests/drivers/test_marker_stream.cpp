// Tests for the tetrig marker-stream protocol (drivers/src/marker_stream*.cpp, crc32c.cpp).
// Golden frames below are written byte by byte from docs/protocol.md; their CRCs were computed
// with an independent bitwise CRC-32C (Python, from the parameters in the spec), not with the
// code under test.
#include "tetrig/drivers/marker_stream.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <memory>
#include <new>
#include <random>
#include <set>
#include <string>
#include <string_view>
#include <type_traits>
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
  for (int v = -12; v <= 2; ++v) {
    const std::string n = markerStreamStatusName(static_cast<S>(v));
    EXPECT_NE(n, "unknown status") << v;
    for (const auto& other : names) EXPECT_NE(n, other);
    names.push_back(n);
  }
  EXPECT_STREQ(markerStreamStatusName(static_cast<S>(-99)), "unknown status");
  EXPECT_STREQ(markerStreamStatusName(S::kBadCrc), "bad crc");
  EXPECT_STREQ(markerStreamStatusName(S::kDescriptor), "descriptor");
  EXPECT_STREQ(markerStreamStatusName(S::kBadDescriptor), "bad descriptor");
  EXPECT_EQ(static_cast<int>(S::kDescriptor), 2);  // a success kind (>= 0), as documented
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

// ---------------------------------------------------------------------------------------------
// Descriptor messages ("TMSD", docs/protocol.md section 2a): labels for marker ids.

// Three labels, table_id 0x00010003 (HID tag 0x0003). Written from docs/protocol.md 2a.2; the
// CRC was computed with the bitwise reference of section 2.1 (Python), not with the code under test.
const Bytes kGoldenDescriptor = {
    0x54, 0x4D, 0x53, 0x44,  // magic "TMSD"
    0x01, 0x00, 0x14, 0x00,  // version 1.0, header_size 20, reserved
    0x2F, 0x00, 0x03, 0x00,  // descriptor_length 47, entry_count 3
    0x03, 0x00, 0x01, 0x00,  // table_id 0x00010003
    0x00, 0x00, 0x00, 0x00,  // reserved
    0x00, 0x00, 0x04, 0x4C, 0x46, 0x48, 0x44,              // id 0, 4 bytes "LFHD"
    0x01, 0x00, 0x04, 0x52, 0x46, 0x48, 0x44,              // id 1, 4 bytes "RFHD"
    0x02, 0x01, 0x06, 0x68, 0xC3, 0xBC, 0x66, 0x74, 0x65,  // id 0x0102, 6 bytes "hüfte" (UTF-8)
    0x0B, 0xC1, 0x49, 0x95,  // CRC-32C 0x9549C10B
};

// Same kind of message, laid out by hand: header (header_size 20 unless given) + raw entry bytes +
// CRC, with entry_count and descriptor_length as given (0xFFFF: computed from the bytes).
Bytes rawDescriptor(const Bytes& entries, std::uint16_t count, std::uint32_t table_id = 9, std::uint8_t header_size = 20,
                    std::uint32_t length = 0xFFFF) {
  Bytes b(header_size, 0x00);
  const Bytes head = {0x54, 0x4D, 0x53, 0x44, 0x01, 0x00, header_size, 0x00};
  std::copy(head.begin(), head.end(), b.begin());
  b.insert(b.end(), entries.begin(), entries.end());
  b.resize(b.size() + 4);
  const std::uint32_t len = length == 0xFFFF ? static_cast<std::uint32_t>(b.size()) : length;
  b[8] = static_cast<std::uint8_t>(len);
  b[9] = static_cast<std::uint8_t>(len >> 8);
  b[10] = static_cast<std::uint8_t>(count);
  b[11] = static_cast<std::uint8_t>(count >> 8);
  putU32(b, 12, table_id);
  fixCrc(b);
  return b;
}
Bytes entry(std::uint16_t id, std::string_view label) {
  Bytes e(3 + label.size());
  e[0] = static_cast<std::uint8_t>(id);
  e[1] = static_cast<std::uint8_t>(id >> 8);
  e[2] = static_cast<std::uint8_t>(label.size());
  for (std::size_t i = 0; i < label.size(); ++i) e[3 + i] = static_cast<std::uint8_t>(label[i]);
  return e;
}

Bytes encodeLabels(const std::vector<MarkerLabel>& labels, std::uint32_t table_id) {
  Bytes b(kMarkerStreamMaxDescriptorSize + 16);
  const std::size_t n = encodeMarkerStreamDescriptor(labels, table_id, b);
  b.resize(n);
  return b;
}

// A decoder that has accepted the golden descriptor (the "previous table" the rejections must keep).
void expectGoldenTable(const MarkerLabelTable& t) {
  ASSERT_EQ(t.count, 3u);
  EXPECT_EQ(t.label(0), "LFHD");
  EXPECT_EQ(t.label(1), "RFHD");
  EXPECT_EQ(t.label(0x0102), "h\xC3\xBC" "fte");
  EXPECT_EQ(t.table_id, 0x00010003u);
}

static_assert(std::is_trivially_copyable_v<MarkerLabelTable>);

TEST(MarkerStreamDescriptor, GoldenBytesDecodeIntoTheTableAndLeaveTheFrameAlone) {
  ASSERT_EQ(kGoldenDescriptor.size(), 47u);
  MarkerStreamDecoder dec;
  EXPECT_EQ(dec.labels().generation, 0u);
  EXPECT_EQ(dec.labels().count, 0u);
  auto out = sentinelFrame();
  ASSERT_EQ(dec.decodeFrame(kGoldenDescriptor, 5, *out), S::kDescriptor);
  expectUntouched(*out);
  expectGoldenTable(dec.labels());
  EXPECT_EQ(dec.labels().generation, 1u);
  EXPECT_EQ(dec.labels().label(2), "");       // not named
  EXPECT_EQ(dec.labels().label(0xFFFF), "");
  EXPECT_EQ(dec.labels().find(0x0101), nullptr);
  ASSERT_NE(dec.labels().find(1), nullptr);
  EXPECT_EQ(dec.labels().find(1)->id, 1u);
  EXPECT_EQ(dec.stats().descriptors_accepted, 1u);
  EXPECT_EQ(dec.stats().frames_decoded, 0u);
  // The stateless form gives the same table.
  MarkerLabelTable t;
  ASSERT_EQ(decodeMarkerStreamDescriptor(kGoldenDescriptor, t), S::kDescriptor);
  expectGoldenTable(t);
}

TEST(MarkerStreamDescriptor, EncoderReproducesGoldenBytes) {
  const std::vector<MarkerLabel> labels = {{0, "LFHD"}, {1, "RFHD"}, {0x0102, "h\xC3\xBC" "fte"}};
  EXPECT_EQ(markerStreamDescriptorSize(labels), 47u);
  Bytes out(100, 0xEE);
  ASSERT_EQ(encodeMarkerStreamDescriptor(labels, 0x00010003, out), 47u);
  out.resize(47);
  EXPECT_EQ(out, kGoldenDescriptor);
  Bytes small(46);
  EXPECT_EQ(encodeMarkerStreamDescriptor(labels, 0x00010003, small), 0u);
  const std::string long_label(kMarkerLabelMaxLength + 1, 'x');
  const std::vector<MarkerLabel> too_long = {{0, long_label}};
  EXPECT_EQ(encodeMarkerStreamDescriptor(too_long, 1, out), 0u);
  std::vector<MarkerLabel> too_many(kMarkerStreamMaxMarkers + 1, MarkerLabel{0, "a"});
  Bytes big(kMarkerStreamMaxDescriptorSize);
  EXPECT_EQ(encodeMarkerStreamDescriptor(too_many, 1, big), 0u);
}

// Random valid labels: printable ASCII plus 2-, 3- and 4-byte UTF-8 sequences, 1..31 bytes.
std::string randomLabel(std::mt19937& rng, std::size_t max_len) {
  static const char* pieces[] = {"\xC3\xA4", "\xE2\x82\xAC", "\xF0\x9F\x98\x80", "\xC2\xA0", "\xEF\xBF\xBD"};
  std::string s;
  const std::size_t want = 1 + rng() % max_len;
  while (s.size() < want) {
    if (rng() % 4 == 0) {
      const std::string p = pieces[rng() % 5];
      if (s.size() + p.size() > max_len) break;
      s += p;
    } else {
      s.push_back(static_cast<char>(0x20 + rng() % 95));
    }
  }
  if (s.empty()) s = "m";
  return s;
}

TEST(MarkerStreamDescriptor, RoundTripRandomTablesUpToTheLargest) {
  std::mt19937 rng(41);
  for (int round = 0; round < 40; ++round) {
    const std::size_t count = round == 0 ? kMarkerStreamMaxMarkers : round == 1 ? 0 : rng() % 257;
    std::vector<std::string> texts;
    std::set<std::string> seen;
    while (texts.size() < count) {
      std::string t;
      if (round == 0) {  // 256 labels of exactly 31 bytes: the largest descriptor a v1.0 sender writes
        const std::size_t i = texts.size();
        t.assign(kMarkerLabelMaxLength - 2, 'A');
        t.push_back(static_cast<char>('a' + i % 26));
        t.push_back(static_cast<char>('a' + (i / 26) % 26));
      } else {
        t = randomLabel(rng, kMarkerLabelMaxLength);
      }
      if (seen.insert(t).second) texts.push_back(t);
    }
    std::vector<MarkerLabel> labels;
    auto id = static_cast<std::uint32_t>(rng() % 50);
    for (std::size_t i = 0; i < count; ++i) {
      labels.push_back({static_cast<std::uint16_t>(id), texts[i]});
      id += static_cast<std::uint32_t>(1 + rng() % 200);
    }
    ASSERT_LE(labels.empty() ? 0u : labels.back().id, 0xFFFFu);
    const Bytes b = encodeLabels(labels, static_cast<std::uint32_t>(round));
    ASSERT_EQ(b.size(), markerStreamDescriptorSize(labels));
    if (round == 0) {
      EXPECT_EQ(b.size(), kMarkerStreamMaxDescriptorSize - 44);  // header 20, not 64
    }
    MarkerLabelTable t;
    ASSERT_EQ(decodeMarkerStreamDescriptor(b, t), S::kDescriptor) << "round " << round;
    ASSERT_EQ(t.count, count);
    EXPECT_EQ(t.table_id, static_cast<std::uint32_t>(round));
    EXPECT_EQ(t.generation, 1u);
    for (const auto& l : labels) {
      ASSERT_TRUE(isValidMarkerLabel(l.label)) << l.label;
      ASSERT_EQ(t.label(l.id), l.label) << "round " << round << " id " << l.id;
    }
    // Ids between the named ones are unnamed.
    for (std::size_t i = 0; i + 1 < labels.size(); ++i) {
      if (labels[i + 1].id - labels[i].id > 1) {
        ASSERT_EQ(t.label(static_cast<std::uint16_t>(labels[i].id + 1)), "");
      }
    }
    EXPECT_EQ(markerStreamPeekFrameLength(b), b.size());
  }
}

TEST(MarkerStreamDescriptor, EveryTruncationIsReportedAndKeepsThePreviousTable) {
  MarkerStreamDecoder dec;
  auto out = sentinelFrame();
  ASSERT_EQ(dec.decodeFrame(kGoldenDescriptor, 0, *out), S::kDescriptor);
  std::vector<MarkerLabel> other = {{5, "other"}};
  const Bytes b = encodeLabels(other, 77);
  for (std::size_t len = 0; len < b.size(); ++len) {
    ASSERT_EQ(dec.decodeFrame(std::span(b.data(), len), 0, *out), S::kTruncated) << "length " << len;
  }
  expectUntouched(*out);
  expectGoldenTable(dec.labels());
  EXPECT_EQ(dec.labels().generation, 1u);
  // Four of those (lengths 0..3) cannot be told apart from a frame; the rest carry the descriptor magic.
  EXPECT_EQ(dec.stats().descriptors_rejected, b.size() - 4);
  EXPECT_EQ(dec.stats().format_errors, b.size());
  ASSERT_EQ(dec.decodeFrame(b, 0, *out), S::kDescriptor);
  EXPECT_EQ(dec.labels().label(5), "other");
  EXPECT_EQ(dec.labels().label(0), "");
  EXPECT_EQ(dec.labels().generation, 2u);
}

TEST(MarkerStreamDescriptor, EverySingleBitFlipIsCaught) {
  for (std::size_t byte = 0; byte < kGoldenDescriptor.size(); ++byte) {
    for (int bit = 0; bit < 8; ++bit) {
      Bytes b = kGoldenDescriptor;
      b[byte] = static_cast<std::uint8_t>(b[byte] ^ (1u << bit));
      MarkerStreamDecoder dec;
      auto out = sentinelFrame();
      const S st = dec.decodeFrame(b, 0, *out);
      ASSERT_NE(st, S::kDescriptor) << "byte " << byte << " bit " << bit;
      ASSERT_NE(st, S::kFrame) << "byte " << byte << " bit " << bit;  // "TMSD" -> "TMSF" is one bit away
      if (byte >= 12 || byte == 5 || byte == 7) {
        ASSERT_EQ(st, S::kBadCrc) << "byte " << byte << " bit " << bit;
      }
      EXPECT_EQ(dec.labels().generation, 0u);
      EXPECT_EQ(dec.labels().count, 0u);
      expectUntouched(*out);
    }
  }
}

TEST(MarkerStreamDescriptor, BadEntriesRejectTheWholeDescriptorAndKeepThePreviousTable) {
  struct Case {
    const char* what;
    Bytes bytes;
  };
  const std::string l31(31, 'q');
  auto cat = [](std::initializer_list<Bytes> parts) {
    Bytes b;
    for (const auto& p : parts) b.insert(b.end(), p.begin(), p.end());
    return b;
  };
  const Case cases[] = {
      {"duplicate id", rawDescriptor(cat({entry(1, "A"), entry(1, "B")}), 2)},
      {"descending ids", rawDescriptor(cat({entry(2, "A"), entry(1, "B")}), 2)},
      {"duplicate label", rawDescriptor(cat({entry(1, "LFHD"), entry(2, "LFHD")}), 2)},
      {"empty label", rawDescriptor(cat({entry(1, "ABC"), entry(2, "")}), 2)},
      {"label of 32 bytes", rawDescriptor(cat({entry(1, l31 + "q"), entry(2, "B")}), 2)},
      {"NUL in label", rawDescriptor(cat({entry(1, std::string_view("A\0B", 3))}), 1)},
      {"control character", rawDescriptor(cat({entry(1, "A\x1F")}), 1)},
      {"DEL", rawDescriptor(cat({entry(1, "A\x7F")}), 1)},
      {"C1 control U+0085", rawDescriptor(cat({entry(1, "A\xC2\x85")}), 1)},
      {"lone continuation byte", rawDescriptor(cat({entry(1, "A\x80")}), 1)},
      {"overlong '/'", rawDescriptor(cat({entry(1, "\xC0\xAF")}), 1)},
      {"overlong 3-byte", rawDescriptor(cat({entry(1, "\xE0\x80\xAF")}), 1)},
      {"surrogate", rawDescriptor(cat({entry(1, "\xED\xA0\x80")}), 1)},
      {"above U+10FFFF", rawDescriptor(cat({entry(1, "\xF4\x90\x80\x80")}), 1)},
      {"byte F5", rawDescriptor(cat({entry(1, "\xF5\x80\x80\x80")}), 1)},
      {"UTF-8 cut by the label end", rawDescriptor(cat({entry(1, "ab\xE2\x82")}), 1)},
      {"entries shorter than the message", rawDescriptor(cat({entry(1, "A"), Bytes{0x00}}), 1)},
      {"count larger than the entries", rawDescriptor(cat({entry(1, "ABCDEFGH"), entry(2, "C")}), 3)},
      {"entry runs past the end", rawDescriptor(cat({entry(1, "A"), Bytes{0x02, 0x00, 0x05, 'x'}}), 2)},
  };
  for (const auto& c : cases) {
    MarkerStreamDecoder dec;
    auto out = sentinelFrame();
    ASSERT_EQ(dec.decodeFrame(kGoldenDescriptor, 0, *out), S::kDescriptor);
    const S st = dec.decodeFrame(c.bytes, 0, *out);
    EXPECT_EQ(st, S::kBadDescriptor) << c.what << ": " << markerStreamStatusName(st);
    expectGoldenTable(dec.labels());
    EXPECT_EQ(dec.labels().generation, 1u) << c.what;
    EXPECT_EQ(dec.stats().descriptors_rejected, 1u) << c.what;
    EXPECT_EQ(dec.stats().descriptors_accepted, 1u) << c.what;
    expectUntouched(*out);
    MarkerLabelTable fresh;
    EXPECT_EQ(decodeMarkerStreamDescriptor(c.bytes, fresh), S::kBadDescriptor) << c.what;
    EXPECT_EQ(fresh.generation, 0u);
  }
  // The same layout with valid contents is accepted (the cases fail for the stated reason only).
  const Bytes good = rawDescriptor(cat({entry(1, "A"), entry(2, "B\xC2\xA0" "C"), entry(0xFFFF, l31)}), 3);
  MarkerLabelTable t;
  ASSERT_EQ(decodeMarkerStreamDescriptor(good, t), S::kDescriptor);
  EXPECT_EQ(t.label(0xFFFF), l31);
  EXPECT_EQ(t.label(2), "B\xC2\xA0" "C");
}

TEST(MarkerStreamDescriptor, LabelRules) {
  for (std::string_view ok : {"A", "LFHD", "meinard:LFHD", "h\xC3\xBC" "fte", "\xE6\x97\xA5\xE6\x9C\xAC",
                              "\xF0\x9F\x98\x80", "~ !", "0123456789012345678901234567890"}) {
    EXPECT_TRUE(isValidMarkerLabel(ok)) << ok;
  }
  for (std::string_view bad : {std::string_view(""), std::string_view("01234567890123456789012345678901"),
                               std::string_view("\0", 1), std::string_view("\t"), std::string_view("a\nb"),
                               std::string_view("\x7F"), std::string_view("\xC2\x9F"), std::string_view("\xC1\xBF"),
                               std::string_view("\xFF"), std::string_view("\xE2\x82"), std::string_view("\xF0\x8F\xBF\xBF")}) {
    EXPECT_FALSE(isValidMarkerLabel(bad)) << "length " << bad.size();
  }
}

TEST(MarkerStreamDescriptor, HeaderVersionAndLengthChecks) {
  const Bytes entries = entry(1, "A");
  MarkerLabelTable t;
  EXPECT_EQ(decodeMarkerStreamDescriptor(rawDescriptor(entries, 1, 9, 16), t), S::kBadHeader);  // header < 20
  EXPECT_EQ(decodeMarkerStreamDescriptor(rawDescriptor(entries, 1, 9, 22), t), S::kBadHeader);  // not a multiple of 4
  EXPECT_EQ(decodeMarkerStreamDescriptor(rawDescriptor(entries, 1, 9, 68), t), S::kBadHeader);  // > 64
  EXPECT_EQ(decodeMarkerStreamDescriptor(rawDescriptor(entries, 257), t), S::kBadHeader);      // > 256 entries
  // descriptor_length outside what entry_count allows (4..34 bytes per entry), or not the message size.
  EXPECT_EQ(decodeMarkerStreamDescriptor(rawDescriptor(entries, 2), t), S::kBadLength);
  EXPECT_EQ(decodeMarkerStreamDescriptor(rawDescriptor(entries, 0), t), S::kBadLength);
  // descriptor_length plausible but larger than the bytes given: truncated.
  EXPECT_EQ(decodeMarkerStreamDescriptor(rawDescriptor(entries, 1, 9, 20, 29), t), S::kTruncated);
  Bytes longer = rawDescriptor(entries, 1);
  longer.push_back(0);
  EXPECT_EQ(decodeMarkerStreamDescriptor(longer, t), S::kBadLength);
  // Unknown major version: nothing after byte 4 is looked at.
  Bytes v2 = kGoldenDescriptor;
  v2[4] = 2;
  MarkerStreamDecoder dec;
  auto out = sentinelFrame();
  EXPECT_EQ(dec.decodeFrame(v2, 0, *out), S::kUnsupportedVersion);
  EXPECT_EQ(dec.decodeFrame(std::span(v2.data(), 5), 0, *out), S::kUnsupportedVersion);
  EXPECT_EQ(dec.stats().version_errors, 2u);
  EXPECT_EQ(dec.stats().descriptors_rejected, 2u);
  EXPECT_EQ(markerStreamPeekFrameLength(v2), 0u);
  EXPECT_EQ(t.generation, 0u);
  // A newer minor version with a longer header (an extension field a v1.0 decoder skips).
  Bytes v11 = rawDescriptor(entries, 1, 9, 24);
  v11[5] = 1;
  v11[20] = 0xAB;  // the unknown field
  fixCrc(v11);
  ASSERT_EQ(dec.decodeFrame(v11, 0, *out), S::kDescriptor);
  EXPECT_EQ(dec.labels().label(1), "A");
  EXPECT_EQ(markerStreamPeekFrameLength(v11), v11.size());
  // An empty table is a valid descriptor ("no labels").
  const Bytes empty = rawDescriptor({}, 0);
  ASSERT_EQ(empty.size(), 24u);
  ASSERT_EQ(dec.decodeFrame(empty, 0, *out), S::kDescriptor);
  EXPECT_EQ(dec.labels().count, 0u);
  EXPECT_EQ(dec.labels().label(1), "");
  expectUntouched(*out);
}

TEST(MarkerStreamDescriptor, GenerationChangesOnlyWithTheLabels) {
  MarkerStreamDecoder dec;
  auto out = sentinelFrame();
  const std::vector<MarkerLabel> a = {{0, "A"}, {3, "B"}};
  const std::vector<MarkerLabel> b = {{0, "A"}, {3, "C"}};
  const std::vector<MarkerLabel> c = {{0, "A"}, {4, "B"}};
  ASSERT_EQ(dec.decodeFrame(encodeLabels(a, 1), 0, *out), S::kDescriptor);
  EXPECT_EQ(dec.labels().generation, 1u);
  ASSERT_EQ(dec.decodeFrame(encodeLabels(a, 1), 0, *out), S::kDescriptor);  // repeat (GET_DESCRIPTOR)
  EXPECT_EQ(dec.labels().generation, 1u);
  ASSERT_EQ(dec.decodeFrame(encodeLabels(a, 2), 0, *out), S::kDescriptor);  // new table_id, same labels
  EXPECT_EQ(dec.labels().generation, 1u);
  EXPECT_EQ(dec.labels().table_id, 2u);
  ASSERT_EQ(dec.decodeFrame(encodeLabels(b, 2), 0, *out), S::kDescriptor);  // a label changed
  EXPECT_EQ(dec.labels().generation, 2u);
  EXPECT_EQ(dec.labels().label(3), "C");
  ASSERT_EQ(dec.decodeFrame(encodeLabels(c, 2), 0, *out), S::kDescriptor);  // an id changed
  EXPECT_EQ(dec.labels().generation, 3u);
  EXPECT_EQ(dec.labels().label(3), "");
  EXPECT_EQ(dec.labels().label(4), "B");
  ASSERT_EQ(dec.decodeFrame(encodeLabels({}, 2), 0, *out), S::kDescriptor);  // fewer entries
  EXPECT_EQ(dec.labels().generation, 4u);
  EXPECT_EQ(dec.stats().descriptors_accepted, 6u);
  // reset() keeps the table; clearLabels() empties it.
  ASSERT_EQ(dec.decodeFrame(encodeLabels(a, 3), 0, *out), S::kDescriptor);
  dec.reset();
  EXPECT_EQ(dec.labels().label(3), "B");
  dec.clearLabels();
  EXPECT_EQ(dec.labels().count, 0u);
  EXPECT_EQ(dec.labels().label(3), "");
  // A first descriptor that is empty still counts as "named" (generation 1).
  MarkerStreamDecoder fresh;
  ASSERT_EQ(fresh.decodeFrame(encodeLabels({}, 0), 0, *out), S::kDescriptor);
  EXPECT_EQ(fresh.labels().generation, 1u);
  expectUntouched(*out);
}

TEST(MarkerStreamDescriptor, DescriptorsBetweenFramesLeaveTheSequenceAlone) {
  MarkerStreamDecoder dec;
  auto out = std::make_unique<MarkerFrame>();
  ASSERT_EQ(dec.decodeFrame(makeFrame(10, 2), 0, *out), S::kFrame);
  ASSERT_EQ(dec.decodeFrame(kGoldenDescriptor, 0, *out), S::kDescriptor);
  EXPECT_EQ(out->frame_counter, 10u);
  ASSERT_EQ(dec.decodeFrame(makeFrame(11, 2), 0, *out), S::kFrame);
  EXPECT_EQ(out->flags & tetrig::kFrameSequenceGap, 0u);
  EXPECT_EQ(out->frame_counter, 11u);
  EXPECT_EQ(dec.stats().frames_decoded, 2u);
  EXPECT_EQ(dec.stats().frames_lost, 0u);
  EXPECT_EQ(dec.stats().duplicates, 0u);
  expectGoldenTable(dec.labels());
}

TEST(MarkerStreamDescriptor, PeekCutsAStreamOfFramesAndDescriptors) {
  const Bytes f1 = makeFrame(1, 3);
  const Bytes f2 = makeFrame(2, 41);
  Bytes stream = f1;
  stream.insert(stream.end(), kGoldenDescriptor.begin(), kGoldenDescriptor.end());
  stream.insert(stream.end(), f2.begin(), f2.end());
  MarkerStreamDecoder dec;
  auto out = std::make_unique<MarkerFrame>();
  std::vector<S> got;
  for (std::size_t pos = 0; pos < stream.size();) {
    const std::size_t len = markerStreamPeekFrameLength(std::span(stream).subspan(pos));
    ASSERT_GT(len, 0u) << "at " << pos;
    got.push_back(dec.decodeFrame(std::span(stream).subspan(pos, len), 0, *out));
    pos += len;
  }
  EXPECT_EQ(got, (std::vector<S>{S::kFrame, S::kDescriptor, S::kFrame}));
  EXPECT_EQ(markerStreamPeekFrameLength(std::span(kGoldenDescriptor.data(), 12)), 47u);
  EXPECT_EQ(markerStreamPeekFrameLength(std::span(kGoldenDescriptor.data(), 11)), 0u);
  Bytes tiny = kGoldenDescriptor;
  tiny[8] = 23;  // below header + CRC
  tiny[9] = 0;
  EXPECT_EQ(markerStreamPeekFrameLength(tiny), 0u);
  tiny[8] = 0x45;  // 8773 > kMarkerStreamMaxDescriptorSize
  tiny[9] = 0x22;
  EXPECT_EQ(markerStreamPeekFrameLength(tiny), 0u);
  tiny[8] = 0x44;  // 8772: the largest
  EXPECT_EQ(markerStreamPeekFrameLength(tiny), 8772u);
}

TEST(MarkerStreamDescriptorHid, GoldenReportCarriesTheDescriptorWithItsTableIdAsTag) {
  // docs/protocol.md 3.2: tag = table_id & 0xFFFF = 0x0003, one fragment of 47 bytes.
  Bytes report = {0x01, 0x03, 0x00, 0x00, 0x01, 0x2F};
  report.insert(report.end(), kGoldenDescriptor.begin(), kGoldenDescriptor.end());
  report.resize(64, 0x00);
  Bytes enc(64);
  ASSERT_EQ(encodeMarkerStreamFragment(kGoldenDescriptor, 0, enc), 64u);
  EXPECT_EQ(enc, report);
  MarkerStreamDecoder dec;
  auto out = sentinelFrame();
  ASSERT_EQ(dec.decodeHidReport(report, 0, *out), S::kDescriptor);
  expectGoldenTable(dec.labels());
  expectUntouched(*out);
  // A tag that does not match the table_id is a bad fragment; the table is kept.
  MarkerStreamDecoder other;
  report[1] = 0x04;
  EXPECT_EQ(other.decodeHidReport(report, 0, *out), S::kBadFragment);
  EXPECT_EQ(other.labels().generation, 0u);
  EXPECT_EQ(other.stats().descriptors_rejected, 1u);
}

std::vector<MarkerLabel> viconLabels(std::vector<std::string>& storage, std::size_t n) {
  storage.clear();
  for (std::size_t i = 0; i < n; ++i) storage.push_back("meinard:M" + std::to_string(i));
  std::vector<MarkerLabel> out;
  for (std::size_t i = 0; i < n; ++i) out.push_back({static_cast<std::uint16_t>(i), storage[i]});
  return out;
}

TEST(MarkerStreamDescriptorHid, FragmentedDescriptorLostOrReorderedFragmentsKeepTheTable) {
  std::vector<std::string> s41;
  const Bytes d41 = encodeLabels(viconLabels(s41, 41), 0x00120034);
  const auto reports = fragmentsOf(d41);
  ASSERT_GT(reports.size(), 5u);
  for (const auto& r : reports) {
    ASSERT_EQ(r[1], 0x34);  // tag = table_id low 16 bits
    ASSERT_EQ(r[2], 0x00);
  }
  const auto frame = fragmentsOf(makeFrame(5, 41));
  MarkerStreamDecoder dec;
  auto out = sentinelFrame();
  ASSERT_EQ(dec.decodeHidReport(fragmentsOf(kGoldenDescriptor)[0], 0, *out), S::kDescriptor);
  // Lost fragment: the descriptor is dropped, the old table stays, the stream recovers.
  for (std::size_t i = 0; i < reports.size(); ++i) {
    if (i == 2) continue;
    const S st = dec.decodeHidReport(reports[i], 0, *out);
    ASSERT_NE(st, S::kDescriptor) << i;
  }
  expectGoldenTable(dec.labels());
  // Swapped fragments: dropped as well.
  for (std::size_t i = 0; i < reports.size(); ++i) {
    const std::size_t j = i == 3 ? 4 : i == 4 ? 3 : i;
    ASSERT_NE(dec.decodeHidReport(reports[j], 0, *out), S::kDescriptor) << i;
  }
  expectGoldenTable(dec.labels());
  expectUntouched(*out);
  // A frame, then the whole descriptor, then a frame: both kinds share the reassembler.
  for (std::size_t i = 0; i + 1 < frame.size(); ++i) ASSERT_EQ(dec.decodeHidReport(frame[i], 0, *out), S::kNeedMore);
  ASSERT_EQ(dec.decodeHidReport(frame.back(), 0, *out), S::kFrame);
  for (std::size_t i = 0; i + 1 < reports.size(); ++i) ASSERT_EQ(dec.decodeHidReport(reports[i], 0, *out), S::kNeedMore);
  ASSERT_EQ(dec.decodeHidReport(reports.back(), 0, *out), S::kDescriptor);
  EXPECT_EQ(out->frame_counter, 5u);
  EXPECT_EQ(dec.labels().count, 41u);
  EXPECT_EQ(dec.labels().label(40), "meinard:M40");
  EXPECT_EQ(dec.labels().generation, 2u);
  EXPECT_EQ(dec.reassembler().stats().partial_frames_dropped, 2u);
  // A descriptor cut by a frame's first fragment is abandoned; the frame completes.
  const auto frame2 = fragmentsOf(makeFrame(6, 41));
  ASSERT_EQ(dec.decodeHidReport(reports[0], 0, *out), S::kNeedMore);
  for (std::size_t i = 0; i + 1 < frame2.size(); ++i) ASSERT_EQ(dec.decodeHidReport(frame2[i], 0, *out), S::kNeedMore);
  ASSERT_EQ(dec.decodeHidReport(frame2.back(), 0, *out), S::kFrame);
  EXPECT_EQ(out->frame_counter, 6u);
}

TEST(MarkerStreamDescriptorHid, LargestDescriptorNeedsAllFragments) {
  std::vector<std::string> texts;
  std::vector<MarkerLabel> labels;
  for (std::size_t i = 0; i < kMarkerStreamMaxMarkers; ++i) {
    std::string t = std::to_string(i);
    t.insert(t.begin(), 'L');
    t.resize(kMarkerLabelMaxLength, '_');
    texts.push_back(t);
  }
  for (std::size_t i = 0; i < kMarkerStreamMaxMarkers; ++i) {
    labels.push_back({static_cast<std::uint16_t>(i * 250), texts[i]});
  }
  // With a 64-byte header (a v1.x sender) this is kMarkerStreamMaxDescriptorSize exactly.
  Bytes entries;
  for (const auto& l : labels) {
    const Bytes e = entry(l.id, l.label);
    entries.insert(entries.end(), e.begin(), e.end());
  }
  Bytes big = rawDescriptor(entries, static_cast<std::uint16_t>(labels.size()), 0xBEEF, 64);
  big[5] = 7;  // minor 7
  fixCrc(big);
  ASSERT_EQ(big.size(), kMarkerStreamMaxDescriptorSize);
  const auto reports = fragmentsOf(big);
  ASSERT_EQ(reports.size(), kMarkerStreamMaxFragments);
  EXPECT_EQ(kMarkerStreamMaxFragments, 152u);
  MarkerStreamDecoder dec;
  auto out = sentinelFrame();
  for (std::size_t i = 0; i + 1 < reports.size(); ++i) ASSERT_EQ(dec.decodeHidReport(reports[i], 0, *out), S::kNeedMore);
  ASSERT_EQ(dec.decodeHidReport(reports.back(), 0, *out), S::kDescriptor);
  EXPECT_EQ(dec.labels().count, 256u);
  EXPECT_EQ(dec.labels().label(255 * 250), texts[255]);
  EXPECT_EQ(dec.labels().table_id, 0xBEEFu);
  // One byte more than the largest message cannot be fragmented.
  Bytes too_big(kMarkerStreamMaxMessageSize + 1, 0);
  std::copy(big.begin(), big.begin() + 16, too_big.begin());
  Bytes r(64);
  EXPECT_EQ(markerStreamFragmentCount(too_big.size()), 0u);
  EXPECT_EQ(encodeMarkerStreamFragment(too_big, 0, r), 0u);
}

TEST(MarkerStreamDescriptor, DecodingDescriptorsDoesNotAllocate) {
  std::vector<std::string> s41;
  const Bytes d41 = encodeLabels(viconLabels(s41, 41), 1);
  const Bytes d40 = encodeLabels(viconLabels(s41, 40), 2);
  const auto r41 = fragmentsOf(d41);
  const auto r40 = fragmentsOf(d40);
  Bytes bad = d41;
  bad[30] ^= 1;
  MarkerStreamDecoder dec;
  MarkerStreamDecoder hid;
  auto out = std::make_unique<MarkerFrame>();
  const std::uint64_t before = ::tetrig::test::allocationCount();
  int accepted = 0;
  for (int k = 0; k < 20; ++k) {
    accepted += dec.decodeFrame(k % 2 == 0 ? d41 : d40, 0, *out) == S::kDescriptor ? 1 : 0;
    EXPECT_EQ(dec.decodeFrame(bad, 0, *out), S::kBadCrc);
    for (const auto& r : (k % 2 == 0 ? r41 : r40)) accepted += hid.decodeHidReport(r, 0, *out) == S::kDescriptor ? 1 : 0;
  }
  const std::string_view l = dec.labels().label(39);
  EXPECT_EQ(::tetrig::test::allocationCount(), before);
  EXPECT_EQ(accepted, 40);
  EXPECT_EQ(l, "meinard:M39");
  EXPECT_EQ(dec.labels().generation, 20u);
}

TEST(MarkerStreamControl, GetDescriptorCommand) {
  Bytes r(64, 0xEE);
  ASSERT_EQ(encodeMarkerStreamCommandReport(MarkerStreamCommand::kGetDescriptor, 0, r), 64u);
  Bytes expected(64, 0x00);
  expected[0] = 0x02;
  expected[1] = 0x05;  // GET_DESCRIPTOR
  EXPECT_EQ(r, expected);
  MarkerStreamCommand cmd{};
  std::uint16_t param = 1;
  ASSERT_TRUE(decodeMarkerStreamCommandReport(r, cmd, param));
  EXPECT_EQ(cmd, MarkerStreamCommand::kGetDescriptor);
  EXPECT_EQ(param, 0u);
  r[1] = 0x06;
  EXPECT_FALSE(decodeMarkerStreamCommandReport(r, cmd, param));
  const auto setup = markerStreamControlSetup(MarkerStreamCommand::kGetDescriptor, 0, 3);
  EXPECT_EQ(setup.request_type, 0x41);  // OUT: the descriptor comes on the bulk IN pipe
  EXPECT_EQ(setup.request, 0x05);
  EXPECT_EQ(setup.value, 0u);
  EXPECT_EQ(setup.index, 3u);
  EXPECT_EQ(setup.length, 0u);
}

}  // namespace
