// Tests for the Razer Hydra decoder/encoder (drivers/src/hydra.cpp). The golden report and the
// feature report below are written byte by byte from the published layout (docs/protocol.md).
#include "tetrig/drivers/hydra.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <random>
#include <string>
#include <vector>

namespace {

using namespace tetrig::drivers;
using tetrig::MarkerFrame;
using Bytes = std::vector<std::uint8_t>;

const Bytes kGoldenReport = {
    0xAA, 0xAA, 0xAA, 0xAA, 0xAA, 0xAA, 0xAA,  // bytes 0..6: not interpreted
    0x2A,                                      // byte 7: sequence 42
    // controller 0 (bytes 8..29)
    0x64, 0x00, 0x38, 0xFF, 0x2C, 0x01,        // position 100, -200, 300 mm
    0xFF, 0x7F, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,  // quaternion w = 32767, x = y = z = 0
    0x05,                                      // buttons
    0x00, 0x80, 0x00, 0x40,                    // joystick x = -32768, y = 16384
    0xFF,                                      // trigger 255
    0xBB, 0xBB,                                // unused
    // controller 1 (bytes 30..51)
    0xFF, 0xFF, 0x00, 0x00, 0x01, 0x00,        // position -1, 0, 1 mm
    0x00, 0x00, 0x82, 0x5A, 0x00, 0x00, 0x82, 0x5A,  // quaternion 0, 23170, 0, 23170
    0x00,                                      // buttons
    0x00, 0x00, 0x00, 0x00,                    // joystick 0, 0
    0x80,                                      // trigger 128
    0xCC, 0xCC,                                // unused
};

// A valid report with sequence `seq` (identity orientation for both controllers).
Bytes report(std::uint8_t seq, std::int16_t qw0 = 32767, std::int16_t qw1 = 32767) {
  HydraRawReport r;
  r.sequence = seq;
  r.controllers[0].quaternion[0] = qw0;
  r.controllers[1].quaternion[0] = qw1;
  r.controllers[0].position[0] = 10;
  Bytes b(kHydraReportSize);
  EXPECT_EQ(encodeHydraReport(r, b), kHydraReportSize);
  return b;
}

TEST(Hydra, GoldenReportDecodes) {
  ASSERT_EQ(kGoldenReport.size(), 52u);
  HydraDecoder dec;
  auto out = std::make_unique<MarkerFrame>();
  HydraState state;
  ASSERT_EQ(dec.decode(kGoldenReport, 1234, *out, &state), HydraStatus::kFrame);
  EXPECT_EQ(out->frame_counter, 42u);
  EXPECT_EQ(out->receive_timestamp_ns, 1234);
  EXPECT_EQ(out->device_timestamp_ns, 0);
  EXPECT_EQ(out->flags, 0u);
  ASSERT_EQ(out->marker_count, 2u);
  const auto& m0 = out->markers[0];
  EXPECT_EQ(m0.id, 0u);
  EXPECT_EQ(m0.valid, 1u);
  EXPECT_EQ(m0.has_orientation, 1u);
  EXPECT_EQ(m0.position_mm[0], 100.0f);
  EXPECT_EQ(m0.position_mm[1], -200.0f);
  EXPECT_EQ(m0.position_mm[2], 300.0f);
  EXPECT_FLOAT_EQ(m0.orientation[0], 1.0f);  // 32767/32768 normalised
  EXPECT_EQ(m0.orientation[1], 0.0f);
  EXPECT_EQ(m0.buttons, 0x05);  // byte 22 (block 0 + 14), raw
  const auto& m1 = out->markers[1];
  EXPECT_EQ(m1.id, 1u);
  EXPECT_EQ(m1.buttons, 0x00);
  EXPECT_EQ(m1.position_mm[0], -1.0f);
  EXPECT_EQ(m1.position_mm[2], 1.0f);
  EXPECT_EQ(m1.orientation[0], 0.0f);
  EXPECT_NEAR(m1.orientation[1], std::sqrt(0.5f), 1e-6f);
  EXPECT_EQ(m1.orientation[2], 0.0f);
  EXPECT_NEAR(m1.orientation[3], std::sqrt(0.5f), 1e-6f);
  EXPECT_EQ(state.frame_counter, 42u);
  EXPECT_EQ(state.controllers[0].buttons, 0x05);
  EXPECT_EQ(state.controllers[0].joystick_raw[0], -32768);
  EXPECT_EQ(state.controllers[0].joystick_raw[1], 16384);
  EXPECT_EQ(state.controllers[0].joystick[0], -1.0f);
  EXPECT_EQ(state.controllers[0].joystick[1], 0.5f);
  EXPECT_EQ(state.controllers[0].trigger_raw, 255);
  EXPECT_EQ(state.controllers[0].trigger, 1.0f);
  EXPECT_EQ(state.controllers[1].trigger_raw, 128);
  EXPECT_NEAR(state.controllers[1].trigger, 128.0f / 255.0f, 1e-7f);
  EXPECT_TRUE(state.controllers[0].pose_valid);
  EXPECT_TRUE(state.controllers[1].pose_valid);
}

TEST(Hydra, EncoderReproducesGoldenBytes) {
  HydraRawReport r;
  r.sequence = 42;
  r.controllers[0] = {{100, -200, 300}, {32767, 0, 0, 0}, 0x05, {-32768, 16384}, 255};
  r.controllers[1] = {{-1, 0, 1}, {0, 23170, 0, 23170}, 0x00, {0, 0}, 128};
  Bytes b(60, 0xEE);
  ASSERT_EQ(encodeHydraReport(r, b), 52u);
  b.resize(52);
  Bytes expected = kGoldenReport;
  for (std::size_t i = 0; i < 7; ++i) expected[i] = 0;  // the encoder writes 0 where we do not know the meaning
  expected[28] = expected[29] = expected[50] = expected[51] = 0;
  EXPECT_EQ(b, expected);
  Bytes small(51);
  EXPECT_EQ(encodeHydraReport(r, small), 0u);
}

TEST(Hydra, RoundTripRandomRawReports) {
  std::mt19937 rng(99);
  for (int i = 0; i < 200; ++i) {
    HydraRawReport in;
    in.sequence = static_cast<std::uint8_t>(rng());
    for (auto& c : in.controllers) {
      for (auto& v : c.position) v = static_cast<std::int16_t>(rng());
      for (auto& v : c.quaternion) v = static_cast<std::int16_t>(rng());
      c.buttons = static_cast<std::uint8_t>(rng());
      c.joystick[0] = static_cast<std::int16_t>(rng());
      c.joystick[1] = static_cast<std::int16_t>(rng());
      c.trigger = static_cast<std::uint8_t>(rng());
    }
    Bytes b(52);
    ASSERT_EQ(encodeHydraReport(in, b), 52u);
    HydraRawReport out;
    ASSERT_EQ(parseHydraReport(b, out), HydraStatus::kFrame);
    ASSERT_EQ(out.sequence, in.sequence);
    for (std::size_t c = 0; c < 2; ++c) {
      for (int k = 0; k < 3; ++k) ASSERT_EQ(out.controllers[c].position[k], in.controllers[c].position[k]);
      for (int k = 0; k < 4; ++k) ASSERT_EQ(out.controllers[c].quaternion[k], in.controllers[c].quaternion[k]);
      ASSERT_EQ(out.controllers[c].buttons, in.controllers[c].buttons);
      ASSERT_EQ(out.controllers[c].joystick[0], in.controllers[c].joystick[0]);
      ASSERT_EQ(out.controllers[c].joystick[1], in.controllers[c].joystick[1]);
      ASSERT_EQ(out.controllers[c].trigger, in.controllers[c].trigger);
    }
  }
}

TEST(Hydra, EveryTruncationAndOversizeIsRejected) {
  HydraDecoder dec;
  auto out = std::make_unique<MarkerFrame>();
  out->frame_counter = 0xDEAD;
  HydraState state;
  state.frame_counter = 0xBEEF;
  for (std::size_t len = 0; len < 52; ++len) {
    EXPECT_EQ(dec.decode(std::span(kGoldenReport.data(), len), 0, *out, &state), HydraStatus::kTruncated) << len;
  }
  Bytes longer = kGoldenReport;
  longer.push_back(0);
  EXPECT_EQ(dec.decode(longer, 0, *out, &state), HydraStatus::kBadLength);
  EXPECT_EQ(out->frame_counter, 0xDEADu);
  EXPECT_EQ(state.frame_counter, 0xBEEFu);
  EXPECT_EQ(dec.stats().format_errors, 53u);
  EXPECT_EQ(dec.stats().frames_decoded, 0u);
}

TEST(Hydra, ZeroOrTinyQuaternionInvalidatesThatControllerOnly) {
  HydraDecoder dec;
  auto out = std::make_unique<MarkerFrame>();
  HydraState state;
  ASSERT_EQ(dec.decode(report(1, 0, 32767), 0, *out, &state), HydraStatus::kFrame);
  EXPECT_EQ(out->markers[0].valid, 0u);
  EXPECT_EQ(out->markers[0].has_orientation, 0u);
  EXPECT_EQ(out->markers[0].position_mm[0], 0.0f);
  EXPECT_EQ(out->markers[0].orientation[0], 1.0f);
  EXPECT_EQ(out->markers[1].valid, 1u);
  EXPECT_EQ(out->rejected_count, 1u);
  EXPECT_NE(out->flags & tetrig::kFrameRejectedMarkers, 0u);
  EXPECT_FALSE(state.controllers[0].pose_valid);
  EXPECT_TRUE(state.controllers[1].pose_valid);
  // |q| = 100/32768: not a rotation.
  ASSERT_EQ(dec.decode(report(2, 100, 100), 0, *out), HydraStatus::kFrame);
  EXPECT_EQ(out->rejected_count, 2u);
  // |q| = 0.5 exactly is the accepted boundary; normalised to unit length.
  ASSERT_EQ(dec.decode(report(3, 16384, -16384), 0, *out), HydraStatus::kFrame);
  EXPECT_EQ(out->rejected_count, 0u);
  EXPECT_EQ(out->flags & tetrig::kFrameRejectedMarkers, 0u);
  EXPECT_EQ(out->markers[0].orientation[0], 1.0f);
  EXPECT_EQ(out->markers[1].orientation[0], -1.0f);
  EXPECT_EQ(out->markers[0].position_mm[0], 10.0f);
  EXPECT_EQ(dec.stats().rejected_markers, 3u);
}

TEST(Hydra, SequenceGapsDuplicatesAndWrapAround) {
  HydraDecoder dec;
  auto out = std::make_unique<MarkerFrame>();
  ASSERT_EQ(dec.decode(report(250), 0, *out), HydraStatus::kFrame);
  EXPECT_EQ(out->frame_counter, 250u);
  ASSERT_EQ(dec.decode(report(251), 0, *out), HydraStatus::kFrame);
  EXPECT_EQ(out->flags & tetrig::kFrameSequenceGap, 0u);
  ASSERT_EQ(dec.decode(report(253), 0, *out), HydraStatus::kFrame);  // 252 lost
  EXPECT_NE(out->flags & tetrig::kFrameSequenceGap, 0u);
  EXPECT_EQ(out->frame_counter, 253u);
  out->frame_counter = 0xDEAD;
  EXPECT_EQ(dec.decode(report(253), 0, *out), HydraStatus::kDuplicate);
  EXPECT_EQ(out->frame_counter, 0xDEADu);
  ASSERT_EQ(dec.decode(report(254), 0, *out), HydraStatus::kFrame);
  ASSERT_EQ(dec.decode(report(255), 0, *out), HydraStatus::kFrame);
  ASSERT_EQ(dec.decode(report(0), 0, *out), HydraStatus::kFrame);  // wrap, no loss
  EXPECT_EQ(out->frame_counter, 256u);
  EXPECT_EQ(out->flags & tetrig::kFrameSequenceGap, 0u);
  ASSERT_EQ(dec.decode(report(3), 0, *out), HydraStatus::kFrame);  // 1, 2 lost
  EXPECT_EQ(out->frame_counter, 259u);
  EXPECT_EQ(dec.stats().frames_lost, 3u);
  EXPECT_EQ(dec.stats().gap_events, 2u);
  EXPECT_EQ(dec.stats().duplicates, 1u);
  // Across a wrap with losses: 254 -> 2 is a step of 4 (255, 0, 1 lost).
  HydraDecoder d2;
  ASSERT_EQ(d2.decode(report(254), 0, *out), HydraStatus::kFrame);
  ASSERT_EQ(d2.decode(report(2), 0, *out), HydraStatus::kFrame);
  EXPECT_EQ(out->frame_counter, 258u);
  EXPECT_EQ(d2.stats().frames_lost, 3u);
  // A backward step cannot happen on a USB pipe: it is counted as a long forward gap (documented).
  ASSERT_EQ(d2.decode(report(1), 0, *out), HydraStatus::kFrame);
  EXPECT_EQ(out->frame_counter, 258u + 255u);
  EXPECT_EQ(d2.stats().frames_lost, 3u + 254u);
  // reset(): the next report starts a new stream.
  d2.reset();
  ASSERT_EQ(d2.decode(report(7), 0, *out), HydraStatus::kFrame);
  EXPECT_EQ(out->frame_counter, 7u);
  EXPECT_EQ(out->flags & tetrig::kFrameSequenceGap, 0u);
}

TEST(Hydra, MotionModeFeatureReport) {
  const auto r = hydraMotionModeFeatureReport();
  ASSERT_EQ(r.size(), 91u);
  for (std::size_t i = 0; i < r.size(); ++i) {
    std::uint8_t expected = 0;
    if (i == 6) expected = 0x01;
    if (i == 8) expected = 0x04;
    if (i == 9) expected = 0x03;
    if (i == 89) expected = 0x06;
    EXPECT_EQ(r[i], expected) << "byte " << i;
  }
  EXPECT_EQ(kHydraVendorId, 0x1532);
  EXPECT_EQ(kHydraProductId, 0x0300);
}

TEST(Hydra, PoseQuantisation) {
  const float p[3] = {12.4f, -12.6f, 40000.0f};
  const float q[4] = {2.0f, 0.0f, 0.0f, 0.0f};
  const auto c = hydraControllerFromPose(p, q);
  EXPECT_EQ(c.position[0], 12);
  EXPECT_EQ(c.position[1], -13);
  EXPECT_EQ(c.position[2], 32767);  // clamped
  EXPECT_EQ(c.quaternion[0], 32767);  // 1.0 * 32768 clamped
  EXPECT_EQ(c.quaternion[1], 0);
  const float h[4] = {0.0f, -1.0f, 0.0f, 0.0f};
  EXPECT_EQ(hydraControllerFromPose(p, h).quaternion[1], -32768);
  const float zero[4] = {0.0f, 0.0f, 0.0f, 0.0f};
  const float nanp[3] = {std::nanf(""), -1.0e9f, 0.0f};
  const auto z = hydraControllerFromPose(nanp, zero);
  EXPECT_EQ(z.quaternion[0], 32767);
  EXPECT_EQ(z.position[0], 0);
  EXPECT_EQ(z.position[1], -32768);
  // Quantise -> encode -> decode recovers the pose to within the wire resolution.
  const float pose_p[3] = {123.0f, -45.0f, 678.0f};
  const float s = std::sqrt(0.5f);
  const float pose_q[4] = {s, 0.0f, s, 0.0f};
  HydraRawReport raw;
  raw.controllers[0] = hydraControllerFromPose(pose_p, pose_q);
  raw.controllers[1] = raw.controllers[0];
  Bytes b(52);
  ASSERT_EQ(encodeHydraReport(raw, b), 52u);
  HydraDecoder dec;
  auto out = std::make_unique<MarkerFrame>();
  ASSERT_EQ(dec.decode(b, 0, *out), HydraStatus::kFrame);
  EXPECT_EQ(out->markers[0].position_mm[2], 678.0f);
  EXPECT_NEAR(out->markers[0].orientation[0], s, 1e-4f);
  EXPECT_NEAR(out->markers[0].orientation[2], s, 1e-4f);
}

TEST(Hydra, ButtonsReachTheMarkersAlsoWhenThePoseIsRejected) {
  HydraDecoder dec;
  auto out = std::make_unique<MarkerFrame>();
  // Every button byte value on each controller, one report each; controller 1 has no valid pose.
  for (int v = 0; v < 256; ++v) {
    HydraRawReport r;
    r.sequence = static_cast<std::uint8_t>(v);
    r.controllers[0].quaternion[0] = 32767;
    r.controllers[0].buttons = static_cast<std::uint8_t>(v);
    r.controllers[1].quaternion[0] = 0;  // not tracked
    r.controllers[1].buttons = static_cast<std::uint8_t>(255 - v);
    Bytes b(kHydraReportSize);
    ASSERT_EQ(encodeHydraReport(r, b), kHydraReportSize);
    out->markers[0].buttons = 0xA5;  // stale values from an older frame in the slot
    out->markers[1].buttons = 0xA5;
    ASSERT_EQ(dec.decode(b, 0, *out), HydraStatus::kFrame) << v;
    ASSERT_EQ(out->markers[0].buttons, v) << v;
    ASSERT_EQ(out->markers[1].buttons, 255 - v) << v;
    ASSERT_EQ(out->markers[1].valid, 0u);
  }
  // The raw byte sits at block offset 14: bytes 22 and 44 of the report.
  Bytes raw = report(1);
  raw[22] = 0x81;
  raw[44] = 0x40;
  HydraDecoder d2;
  ASSERT_EQ(d2.decode(raw, 0, *out), HydraStatus::kFrame);
  EXPECT_EQ(out->markers[0].buttons, 0x81);
  EXPECT_EQ(out->markers[1].buttons, 0x40);
}

TEST(Hydra, FixedSensorLabelsAndNominalRate) {
  EXPECT_STREQ(kHydraSensorLabels[0], "hydra0");
  EXPECT_STREQ(kHydraSensorLabels[1], "hydra1");
  EXPECT_EQ(kHydraNominalRateHz, 250.0);
}

TEST(Hydra, StatusNames) {
  EXPECT_STREQ(hydraStatusName(HydraStatus::kFrame), "frame");
  EXPECT_STREQ(hydraStatusName(HydraStatus::kTruncated), "truncated");
  EXPECT_STREQ(hydraStatusName(HydraStatus::kBadLength), "bad length");
  EXPECT_STREQ(hydraStatusName(HydraStatus::kDuplicate), "duplicate");
  EXPECT_STREQ(hydraStatusName(static_cast<HydraStatus>(-42)), "unknown status");
}

}  // namespace
