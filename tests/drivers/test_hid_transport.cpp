// HidTransport through the real hidapi (hidraw backend) on a umockdev-emulated hidraw device.
// Timing under umockdev means nothing: the only time bounds are generous ("within 1 s" for a
// replug, a few seconds for a whole exchange) and exist to turn a hang into a failure.
#include <tetrig/drivers/hid_transport.hpp>

#include "transport_test_util.hpp"
#include "umockdev_devices.hpp"

#include <gtest/gtest.h>

#include <chrono>
#include <cerrno>
#include <mutex>
#include <thread>
#include <vector>

namespace {

using namespace std::chrono_literals;
using tetrig::devices::HidTransport;
using tetrig::devices::HidTransportConfig;
using tetrig::devices::ReceivedReport;
using tetrig::devices::TransportEvent;
using tetrig::devices::TransportStatus;

using tetrig::testing::waitFor;
using Recorder = tetrig::testing::TransportRecorder;

std::vector<std::uint8_t> numberedReport(std::size_t size, std::uint32_t n) {
  std::vector<std::uint8_t> r(size);
  for (std::size_t i = 0; i < size; ++i) r[i] = static_cast<std::uint8_t>((n * 7u + i * 13u) & 0xff);
  r[0] = static_cast<std::uint8_t>(n & 0xff);
  r[1] = static_cast<std::uint8_t>(n >> 8);
  return r;
}

class HidTransportTest : public ::testing::Test {
 protected:
  void SetUp() override {
    ASSERT_TRUE(tetrig::testing::inMockEnvironment()) << tetrig::testing::mockEnvironmentHelp();
    testbed_ = std::make_unique<tetrig::testing::Testbed>();
  }
  void TearDown() override {
    transport_.reset();
    device_.reset();
    testbed_.reset();
  }
  tetrig::testing::MockHidDevice& makeDevice(tetrig::testing::MockHidSpec spec = {}) {
    device_ = std::make_unique<tetrig::testing::MockHidDevice>(*testbed_, spec);
    return *device_;
  }
  HidTransportConfig baseConfig() const {
    HidTransportConfig c;
    c.vendor_id = 0x1209;
    c.product_id = 0x7e70;
    c.report_size = 64;
    c.read_timeout_ms = 20;
    c.reconnect_poll_ms = 20;
    return c;
  }
  std::unique_ptr<tetrig::testing::Testbed> testbed_;
  std::unique_ptr<tetrig::testing::MockHidDevice> device_;
  Recorder rec;  // outlives transport_ (its sinks point here)
  std::unique_ptr<HidTransport> transport_;
};

TEST_F(HidTransportTest, EnumeratesByVidPidWithStringsFromEnumeration) {
  tetrig::testing::MockHidSpec spec;
  spec.manufacturer = "Acme Mocap";
  spec.product = "Marker Box";
  spec.serial = "SN-4711";
  makeDevice(spec).plug();

  const auto found = tetrig::devices::enumerateHid(0x1209, 0x7e70);
  ASSERT_EQ(found.size(), 1u);
  EXPECT_EQ(found[0].path, "/dev/hidraw0");
  EXPECT_EQ(found[0].vendor_id, 0x1209);
  EXPECT_EQ(found[0].product_id, 0x7e70);
  EXPECT_EQ(found[0].manufacturer, "Acme Mocap");
  EXPECT_EQ(found[0].product, "Marker Box");
  EXPECT_EQ(found[0].serial, "SN-4711");
  EXPECT_EQ(found[0].interface_number, 0);
  EXPECT_TRUE(tetrig::devices::enumerateHid(0x1209, 0x7e71).empty()) << "other product id must not match";
  EXPECT_EQ(tetrig::devices::enumerateHid(0, 0).size(), 1u) << "0/0 lists every device";

  device_->unplug();
  EXPECT_TRUE(tetrig::devices::enumerateHid(0x1209, 0x7e70).empty()) << "unplugged device still listed";
}

TEST_F(HidTransportTest, ReceivesInjectedReportsWholeAndInOrder) {
  auto& dev = makeDevice();
  dev.plug();
  transport_ = std::make_unique<HidTransport>(baseConfig());
  ASSERT_TRUE(transport_->start(rec.sink(), rec.status()));
  ASSERT_TRUE(waitFor([&] { return transport_->connected(); }, 2s)) << "device never opened:" << rec.log();
  EXPECT_EQ(transport_->currentDevice().serial, "TT0001");

  constexpr std::uint32_t kReports = 200;
  for (std::uint32_t i = 0; i < kReports; ++i) {
    ASSERT_TRUE(dev.inject(numberedReport(64, i)));
    if (i % 10 == 9) {
      std::this_thread::sleep_for(2ms);  // a steady stream, not one burst
    }
  }
  ASSERT_TRUE(waitFor([&] { return rec.reportCount() >= kReports; }, 5s)) << "got " << rec.reportCount();
  std::lock_guard lock(rec.mutex);
  ASSERT_EQ(rec.reports.size(), kReports);
  for (std::uint32_t i = 0; i < kReports; ++i) {
    ASSERT_EQ(rec.reports[i], numberedReport(64, i)) << "report " << i;
    if (i > 0) {
      EXPECT_GE(rec.stamps[i], rec.stamps[i - 1]);
    }
  }
  const auto stats = transport_->stats();
  EXPECT_EQ(stats.reports, kReports);
  EXPECT_EQ(stats.bytes, kReports * 64u);
  EXPECT_EQ(stats.opens, 1u);
  EXPECT_EQ(stats.disconnects, 0u);
}

TEST_F(HidTransportTest, SendsStartCommandOnOpenAndQueuedOutputReports) {
  auto& dev = makeDevice();
  dev.plug();
  auto config = baseConfig();
  const std::vector<std::uint8_t> start = {0x00, 'T', 'G', 'S', 1, 0x78, 0x00};  // report id 0 + payload
  config.open_output_reports = {start};
  transport_ = std::make_unique<HidTransport>(config);
  ASSERT_TRUE(transport_->start(rec.sink(), rec.status()));
  EXPECT_EQ(dev.readOutput(start.size(), 2000), start) << "start command did not reach the device";

  const std::vector<std::uint8_t> rate = {0x00, 'T', 'G', 'R', 0xF0, 0x00};
  ASSERT_TRUE(transport_->sendOutputReport(rate));
  EXPECT_EQ(dev.readOutput(rate.size(), 2000), rate);
  ASSERT_TRUE(waitFor([&] { return transport_->stats().reports_sent >= 2; }, 2s));
  EXPECT_EQ(transport_->stats().write_errors, 0u);

  const std::vector<std::uint8_t> too_big(HidTransport::kMaxCommandBytes + 1, 0);
  EXPECT_FALSE(transport_->sendOutputReport(too_big));
  EXPECT_FALSE(transport_->sendOutputReport({}));
  EXPECT_EQ(transport_->stats().commands_dropped, 2u);
}

TEST_F(HidTransportTest, FeatureReportReachesDeviceAndFailureIsReported) {
  auto& dev = makeDevice();
  dev.plug();
  std::vector<std::uint8_t> feature(91);
  for (std::size_t i = 0; i < feature.size(); ++i) feature[i] = static_cast<std::uint8_t>(i * 3 + 1);
  feature[0] = 0x00;  // report id
  auto config = baseConfig();
  config.open_feature_reports = {feature};
  transport_ = std::make_unique<HidTransport>(config);
  ASSERT_TRUE(transport_->start(rec.sink(), rec.status()));
  ASSERT_TRUE(waitFor([&] { return dev.featureReports().size() >= 1; }, 2s)) << "no HIDIOCSFEATURE seen";
  EXPECT_EQ(dev.featureReports()[0], feature);

  dev.setFeatureErrno(EIO);  // (hidapi retries EPIPE itself)
  ASSERT_TRUE(transport_->sendFeatureReport(feature));
  ASSERT_TRUE(waitFor([&] { return rec.count(TransportEvent::kFeatureError) == 1; }, 2s));
  EXPECT_EQ(transport_->stats().write_errors, 1u);
  EXPECT_EQ(dev.featureReports().size(), 1u);
  EXPECT_TRUE(transport_->connected()) << "a failed feature report is not an unplug";
}

TEST_F(HidTransportTest, UnplugIsReportedAndReplugResumesWithinOneSecond) {
  auto& dev = makeDevice();
  dev.plug();
  auto config = baseConfig();
  const std::vector<std::uint8_t> start = {0x00, 'T', 'G', 'S', 1};
  config.open_output_reports = {start};
  transport_ = std::make_unique<HidTransport>(config);
  ASSERT_TRUE(transport_->start(rec.sink(), rec.status()));
  ASSERT_EQ(dev.readOutput(start.size(), 2000), start);
  for (std::uint32_t i = 0; i < 20; ++i) ASSERT_TRUE(dev.inject(numberedReport(64, i)));
  ASSERT_TRUE(waitFor([&] { return rec.reportCount() == 20; }, 3s));

  dev.unplug();
  ASSERT_TRUE(waitFor([&] { return !transport_->connected(); }, 2s)) << "unplug not detected";
  EXPECT_EQ(rec.count(TransportEvent::kDisconnected), 1);
  EXPECT_EQ(transport_->stats().disconnects, 1u);
  std::this_thread::sleep_for(50ms);  // a few reconnect polls find nothing
  EXPECT_FALSE(transport_->connected());

  const auto replug_time = std::chrono::steady_clock::now();
  dev.plug();
  ASSERT_TRUE(waitFor([&] { return transport_->connected(); }, 1s)) << "replug not picked up within 1 s";
  EXPECT_EQ(dev.readOutput(start.size(), 1000), start) << "start command not re-sent after replug";
  for (std::uint32_t i = 100; i < 120; ++i) ASSERT_TRUE(dev.inject(numberedReport(64, i)));
  ASSERT_TRUE(waitFor([&] { return rec.reportCount() == 40; }, 2s)) << "stream did not resume";
  EXPECT_LT(std::chrono::steady_clock::now() - replug_time, 3s);
  {
    std::lock_guard lock(rec.mutex);
    EXPECT_EQ(rec.reports[20], numberedReport(64, 100));
    EXPECT_EQ(rec.reports[39], numberedReport(64, 119));
  }
  EXPECT_EQ(transport_->stats().opens, 2u);
  EXPECT_EQ(rec.count(TransportEvent::kOpened), 2);
}

TEST_F(HidTransportTest, WaitsForAbsentDeviceThenOpensIt) {
  auto& dev = makeDevice();
  transport_ = std::make_unique<HidTransport>(baseConfig());
  ASSERT_TRUE(transport_->start(rec.sink(), rec.status()));
  ASSERT_TRUE(waitFor([&] { return rec.count(TransportEvent::kNotFound) == 1; }, 2s));
  std::this_thread::sleep_for(60ms);
  EXPECT_EQ(rec.count(TransportEvent::kNotFound), 1) << "'not found' must be reported once, not every poll";
  dev.plug();
  ASSERT_TRUE(waitFor([&] { return transport_->connected(); }, 1s));
  ASSERT_TRUE(dev.inject(numberedReport(64, 5)));
  ASSERT_TRUE(waitFor([&] { return rec.reportCount() == 1; }, 2s));
}

TEST_F(HidTransportTest, StopJoinsTheDriverThreadAndIsIdempotent) {
  auto& dev = makeDevice();
  dev.plug();
  transport_ = std::make_unique<HidTransport>(baseConfig());
  ASSERT_TRUE(transport_->start(rec.sink(), rec.status()));
  EXPECT_FALSE(transport_->start(rec.sink(), rec.status())) << "second start must be refused";
  ASSERT_TRUE(waitFor([&] { return transport_->connected(); }, 2s));
  transport_->stop();
  EXPECT_FALSE(transport_->running());
  EXPECT_FALSE(transport_->connected());
  EXPECT_EQ(rec.count(TransportEvent::kStopped), 1);
  transport_->stop();
  EXPECT_EQ(rec.count(TransportEvent::kStopped), 1);
  EXPECT_FALSE(transport_->sendOutputReport(std::vector<std::uint8_t>{0, 1})) << "send after stop must fail";
  // Restart on the same object works.
  ASSERT_TRUE(transport_->start(rec.sink(), rec.status()));
  ASSERT_TRUE(waitFor([&] { return transport_->connected(); }, 2s));
}

}  // namespace

// ------------------------------------------------------------------------------------------------
// Device sources over HID: transport + decoder + mailbox, fed by the protocol's own encoders.

#include <tetrig/drivers/device_sources.hpp>

namespace {

using tetrig::FrameMailbox;
using tetrig::MarkerFrame;
namespace drv = tetrig::drivers;

MarkerFrame makeFrame(std::uint64_t counter, int markers) {
  MarkerFrame f;
  f.frame_counter = counter;
  f.device_timestamp_ns = static_cast<std::int64_t>(counter) * 1'000'000;
  f.marker_count = static_cast<std::uint16_t>(markers);
  for (int i = 0; i < markers; ++i) {
    auto& m = f.markers[static_cast<std::size_t>(i)];
    m.id = static_cast<std::uint16_t>(i);
    m.valid = 1;
    m.position_mm[0] = static_cast<float>(counter) + 10.0f * static_cast<float>(i);
    m.position_mm[1] = -1.5f * static_cast<float>(i);
    m.position_mm[2] = 0.25f * static_cast<float>(counter);
  }
  return f;
}

// The 64-byte HID reports carrying `frame` (report id 0x01 + fragment header + payload).
std::vector<std::vector<std::uint8_t>> fragments(const MarkerFrame& frame) {
  std::vector<std::uint8_t> bytes(drv::kMarkerStreamMaxFrameSize);
  const std::size_t n = drv::encodeMarkerStreamFrame(frame, {}, bytes);
  bytes.resize(n);
  std::vector<std::vector<std::uint8_t>> out;
  for (std::size_t i = 0; i < drv::markerStreamFragmentCount(n); ++i) {
    std::vector<std::uint8_t> report(drv::kMarkerStreamHidReportSize);
    if (drv::encodeMarkerStreamFragment(bytes, i, report) != report.size()) return {};
    out.push_back(report);
  }
  return out;
}

class HidSourceTest : public HidTransportTest {
 protected:
  void TearDown() override {
    hydra_control_.reset();  // the shared-usb interface goes first
    HidTransportTest::TearDown();
  }
  // A Razer Hydra plugged in: motion reports on interface 0 (hidraw0, the fixture's device) and the
  // mode-switch feature report on interface 1 (hidraw10) of the same USB device.
  struct Hydra {
    tetrig::testing::MockHidDevice& motion;
    tetrig::testing::MockHidDevice& control;
  };
  Hydra plugHydra(const std::string& serial) {
    tetrig::testing::MockHidSpec motion;
    motion.vendor_id = drv::kHydraVendorId;
    motion.product_id = drv::kHydraProductId;
    motion.manufacturer = "Razer";
    motion.product = "Razer Hydra";
    motion.serial = serial;
    motion.input_report_size = drv::kHydraReportSize;
    motion.hidraw_index = 0;
    motion.interface_number = 0;
    tetrig::testing::MockHidSpec control = motion;
    control.hidraw_index = 10;
    control.interface_number = 1;
    control.shares_usb_device = true;
    auto& dev0 = makeDevice(motion);
    dev0.plug();
    hydra_control_ = std::make_unique<tetrig::testing::MockHidDevice>(*testbed_, control);
    hydra_control_->plug();
    return {dev0, *hydra_control_};
  }
  std::unique_ptr<FrameMailbox> mailbox_ = std::make_unique<FrameMailbox>();
  std::unique_ptr<tetrig::testing::MockHidDevice> hydra_control_;
};

TEST_F(HidSourceTest, MarkerStreamSourcePublishesReassembledFramesAndSurvivesReplug) {
  auto& dev = makeDevice();
  dev.plug();
  tetrig::devices::HidMarkerStreamSourceConfig config;
  config.hid = baseConfig();
  config.rate_hz = 120;
  tetrig::devices::HidMarkerStreamSource source(config, *mailbox_);
  ASSERT_TRUE(source.start());

  // START, GET_DESCRIPTOR, then SET_RATE arrive as 64-byte output reports 0x02.
  const auto commands = dev.readOutput(192, 2000);
  ASSERT_EQ(commands.size(), 192u);
  drv::MarkerStreamCommand command{};
  std::uint16_t param = 0;
  ASSERT_TRUE(drv::decodeMarkerStreamCommandReport(std::span(commands).first(64), command, param));
  // docs/protocol.md 3.3: [0] = 0x02, [1] = opcode, [2..3] = param LE, rest 0.
  EXPECT_EQ(commands[0], 0x02);
  EXPECT_EQ(commands[1], 0x01);  // START, position records
  EXPECT_EQ(commands[2], 0x00);
  EXPECT_EQ(commands[64 + 0], 0x02);
  EXPECT_EQ(commands[64 + 1], 0x05);  // GET_DESCRIPTOR, right after START
  EXPECT_EQ(commands[128 + 1], 0x03);  // SET_RATE
  EXPECT_EQ(commands[128 + 2], 120);
  EXPECT_EQ(commands[128 + 3], 0);
  EXPECT_EQ(command, drv::MarkerStreamCommand::kStart);
  ASSERT_TRUE(drv::decodeMarkerStreamCommandReport(std::span(commands).subspan(128, 64), command, param));
  EXPECT_EQ(command, drv::MarkerStreamCommand::kSetRate);
  EXPECT_EQ(param, 120);

  constexpr int kFrames = 30;
  for (int i = 1; i <= kFrames; ++i) {
    const auto reports = fragments(makeFrame(static_cast<std::uint64_t>(i), 10));  // 192 bytes: 4 reports
    ASSERT_EQ(reports.size(), 4u);
    for (const auto& r : reports) ASSERT_TRUE(dev.inject(r));
  }
  ASSERT_TRUE(waitFor([&] { return source.stats().frames_published == kFrames; }, 5s))
      << "published " << source.stats().frames_published << ", decode errors " << source.stats().decode_errors;
  MarkerFrame got;
  ASSERT_TRUE(mailbox_->tryTakeLatest(got));
  EXPECT_EQ(got.frame_counter, static_cast<std::uint64_t>(kFrames));
  ASSERT_EQ(got.marker_count, 10);
  EXPECT_FLOAT_EQ(got.markers[3].position_mm[0], kFrames + 30.0f);
  EXPECT_FLOAT_EQ(got.markers[3].position_mm[1], -4.5f);
  EXPECT_EQ(got.markers[9].id, 9);
  EXPECT_EQ(source.stats().decode_errors, 0u);
  EXPECT_GT(got.receive_timestamp_ns, 0);

  // A report that is not a fragment is counted, not fatal.
  std::vector<std::uint8_t> junk(64, 0xEE);
  ASSERT_TRUE(dev.inject(junk));
  ASSERT_TRUE(waitFor([&] { return source.stats().decode_errors == 1; }, 2s));
  EXPECT_EQ(source.stats().last_error, static_cast<int>(drv::MarkerStreamStatus::kBadReport));

  // Unplug in the middle of a frame: the half frame must not be completed after the replug.
  const auto half = fragments(makeFrame(kFrames + 1, 10));
  ASSERT_TRUE(dev.inject(half[0]));
  ASSERT_TRUE(dev.inject(half[1]));
  ASSERT_TRUE(waitFor([&] { return source.transport().stats().reports >= 4u * kFrames + 3; }, 2s));
  dev.unplug();
  ASSERT_TRUE(waitFor([&] { return !source.transport().connected(); }, 2s));
  dev.plug();
  ASSERT_TRUE(waitFor([&] { return source.transport().connected(); }, 1s)) << "no resume within 1 s";
  EXPECT_EQ(dev.readOutput(192, 2000).size(), 192u) << "START/GET_DESCRIPTOR/SET_RATE not re-sent after replug";
  // The rest of the interrupted frame, then a whole new one.
  ASSERT_TRUE(dev.inject(half[2]));
  ASSERT_TRUE(dev.inject(half[3]));
  for (const auto& r : fragments(makeFrame(kFrames + 2, 10))) ASSERT_TRUE(dev.inject(r));
  ASSERT_TRUE(waitFor([&] { return source.transport().stats().reports >= 4u * kFrames + 3 + 6; }, 2s));
  ASSERT_TRUE(waitFor([&] { return source.stats().frames_published >= kFrames + 1; }, 2s));
  EXPECT_EQ(source.stats().frames_published, static_cast<std::uint64_t>(kFrames + 1))
      << "the frame cut by the unplug was completed with bytes from after the replug";
  ASSERT_TRUE(mailbox_->tryTakeLatest(got));
  EXPECT_EQ(got.frame_counter, static_cast<std::uint64_t>(kFrames + 2));
  source.stop();
}

TEST_F(HidSourceTest, HydraSourceSwitchesMotionModeOnInterfaceOneAndDecodesBothSensors) {
  const Hydra hydra = plugHydra("HY1");
  auto& dev0 = hydra.motion;
  auto& dev1 = hydra.control;

  tetrig::devices::HydraSourceConfig config;
  config.hid.read_timeout_ms = 20;
  config.hid.reconnect_poll_ms = 20;
  tetrig::devices::HydraSource source(config, *mailbox_);
  ASSERT_TRUE(source.start(rec.status()));
  ASSERT_TRUE(waitFor([&] { return dev1.featureReports().size() == 1; }, 2s)) << rec.log();
  const auto feature = dev1.featureReports()[0];
  ASSERT_EQ(feature.size(), 91u);
  EXPECT_EQ(feature[0], 0x00);  // report id
  EXPECT_EQ(feature[6], 0x01);
  EXPECT_EQ(feature[8], 0x04);
  EXPECT_EQ(feature[9], 0x03);
  EXPECT_EQ(feature[89], 0x06);
  EXPECT_TRUE(dev0.featureReports().empty()) << "mode switch went to the motion interface";
  EXPECT_EQ(source.transport().currentDevice().interface_number, 0);

  const float p0[3] = {100.0f, -20.0f, 300.0f}, q0[4] = {1.0f, 0.0f, 0.0f, 0.0f};
  const float p1[3] = {-50.0f, 75.0f, 410.0f}, q1[4] = {0.70710678f, 0.0f, 0.70710678f, 0.0f};
  for (std::uint8_t seq = 1; seq <= 20; ++seq) {
    drv::HydraRawReport raw;
    raw.sequence = seq;
    raw.controllers[0] = drv::hydraControllerFromPose(p0, q0);
    raw.controllers[1] = drv::hydraControllerFromPose(p1, q1);
    raw.controllers[0].position[0] = static_cast<std::int16_t>(100 + seq);
    std::vector<std::uint8_t> report(drv::kHydraReportSize);
    ASSERT_EQ(drv::encodeHydraReport(raw, report), drv::kHydraReportSize);
    ASSERT_TRUE(dev0.inject(report));
  }
  ASSERT_TRUE(waitFor([&] { return source.stats().frames_published == 20; }, 3s))
      << source.stats().frames_published << " published, " << source.stats().decode_errors << " errors";
  MarkerFrame got;
  ASSERT_TRUE(mailbox_->tryTakeLatest(got));
  ASSERT_EQ(got.marker_count, 2);
  EXPECT_FLOAT_EQ(got.markers[0].position_mm[0], 120.0f);
  EXPECT_FLOAT_EQ(got.markers[1].position_mm[2], 410.0f);
  EXPECT_EQ(got.markers[1].has_orientation, 1);
  EXPECT_NEAR(got.markers[1].orientation[0], 0.70710678f, 1e-3f);
  EXPECT_NEAR(got.markers[1].orientation[2], 0.70710678f, 1e-3f);
  EXPECT_EQ(source.stats().decode_errors, 0u);
  EXPECT_EQ(source.stats().frames_lost, 0u);
  source.stop();
  dev1.unplug();  // the shared-usb interface goes first
}

}  // namespace

// ------------------------------------------------------------------------------------------------
// The device sources in the MarkerSource shape (device_marker_sources.hpp): labels from a device
// that answers START / GET_DESCRIPTOR with its descriptor, then streams frames; the Hydra's fixed
// sensor names and buttons.

#include <tetrig/drivers/device_marker_sources.hpp>

#include <string>

namespace {

// The 41 marker names of a Vicon full-body set (as in the HDM05 clips), prefixed like HDM05's.
std::vector<std::string> viconNames() {
  const char* names[] = {"LFHD", "RFHD", "LBHD", "RBHD", "C7",   "T10",  "CLAV", "STRN", "RBAK", "LSHO", "LUPA",
                         "LELB", "LFRM", "LWRA", "LWRB", "LFIN", "RSHO", "RUPA", "RELB", "RFRM", "RWRA", "RWRB",
                         "RFIN", "LFWT", "RFWT", "LBWT", "RBWT", "LTHI", "LKNE", "LSHN", "LANK", "LHEE", "LTOE",
                         "LMT5", "RTHI", "RKNE", "RSHN", "RANK", "RHEE", "RTOE", "RMT5"};
  std::vector<std::string> out;
  for (const char* n : names) out.push_back(std::string("meinard:") + n);
  return out;
}

// Encodes (id, label) pairs as a descriptor message with `table_id`.
std::vector<std::uint8_t> descriptorBytes(const std::vector<std::pair<std::uint16_t, std::string>>& table,
                                          std::uint32_t table_id) {
  std::vector<drv::MarkerLabel> labels;
  for (const auto& [id, text] : table) labels.push_back({id, text});
  std::vector<std::uint8_t> bytes(drv::kMarkerStreamMaxDescriptorSize);
  bytes.resize(drv::encodeMarkerStreamDescriptor(labels, table_id, bytes));
  return bytes;
}

std::vector<std::vector<std::uint8_t>> messageReports(const std::vector<std::uint8_t>& message) {
  std::vector<std::vector<std::uint8_t>> out;
  for (std::size_t i = 0; i < drv::markerStreamFragmentCount(message.size()); ++i) {
    std::vector<std::uint8_t> report(drv::kMarkerStreamHidReportSize);
    if (drv::encodeMarkerStreamFragment(message, i, report) != report.size()) return {};
    out.push_back(report);
  }
  return out;
}

// Plays the device side of the control exchange: reads `n` command reports the host wrote and
// answers every START and GET_DESCRIPTOR with the descriptor (docs/protocol.md 2a.1). Returns the
// opcodes seen, in order.
std::vector<int> answerCommands(tetrig::testing::MockHidDevice& dev, std::size_t n,
                                const std::vector<std::uint8_t>& descriptor) {
  std::vector<int> seen;
  const auto bytes = dev.readOutput(n * drv::kMarkerStreamHidReportSize, 2000);
  for (std::size_t k = 0; k + drv::kMarkerStreamHidReportSize <= bytes.size(); k += drv::kMarkerStreamHidReportSize) {
    drv::MarkerStreamCommand command{};
    std::uint16_t param = 0;
    if (!drv::decodeMarkerStreamCommandReport(std::span(bytes).subspan(k, drv::kMarkerStreamHidReportSize), command,
                                              param)) {
      seen.push_back(-1);
      continue;
    }
    seen.push_back(static_cast<int>(command));
    if (command == drv::MarkerStreamCommand::kStart || command == drv::MarkerStreamCommand::kGetDescriptor) {
      for (const auto& r : messageReports(descriptor)) dev.inject(r);
    }
  }
  return seen;
}

TEST_F(HidSourceTest, MarkerSourceAdapterLearnsLabelsFromTheDescriptorAndStreams) {
  auto& dev = makeDevice();
  dev.plug();
  tetrig::devices::HidMarkerStreamSourceConfig config;
  config.hid = baseConfig();
  config.rate_hz = 120;
  const auto source = tetrig::devices::makeHidMarkerStreamSource(config);
  EXPECT_NE(source->describe().find("1209:7e70"), std::string::npos) << source->describe();
  EXPECT_EQ(source->nominalRateHz(), 120.0);
  EXPECT_FALSE(source->finished());
  std::vector<std::string> labels;
  EXPECT_FALSE(source->waitForLabels(0ms, labels)) << "labels before start";
  ASSERT_TRUE(source->start(*mailbox_));
  EXPECT_FALSE(source->start(*mailbox_)) << "second start must be refused";
  EXPECT_NE(source->lastError().find("already running"), std::string::npos) << source->lastError();

  // The device: 41 labelled markers; it answers START and GET_DESCRIPTOR with the descriptor.
  const auto names = viconNames();
  std::vector<std::pair<std::uint16_t, std::string>> table;
  for (std::size_t i = 0; i < names.size(); ++i) table.emplace_back(static_cast<std::uint16_t>(i), names[i]);
  const auto descriptor = descriptorBytes(table, 1);
  ASSERT_GT(messageReports(descriptor).size(), 5u) << "the descriptor should need several HID reports";
  const auto seen = answerCommands(dev, 3, descriptor);
  EXPECT_EQ(seen, (std::vector<int>{0x01, 0x05, 0x03})) << "START, GET_DESCRIPTOR, SET_RATE";

  ASSERT_TRUE(source->waitForLabels(3s, labels)) << "no labels; last error: " << source->lastError();
  EXPECT_EQ(labels, names);

  constexpr int kFrames = 20;
  for (int i = 1; i <= kFrames; ++i) {
    for (const auto& r : fragments(makeFrame(static_cast<std::uint64_t>(i), 41))) ASSERT_TRUE(dev.inject(r));
  }
  ASSERT_TRUE(waitFor([&] { return source->stats().frames_published == kFrames; }, 5s))
      << source->stats().frames_published << " published, " << source->stats().decode_errors << " errors";
  MarkerFrame got;
  ASSERT_TRUE(mailbox_->tryTakeLatest(got));
  EXPECT_EQ(got.frame_counter, static_cast<std::uint64_t>(kFrames));
  ASSERT_EQ(got.marker_count, 41);
  EXPECT_EQ(labels[got.markers[40].id], "meinard:RMT5");
  EXPECT_FLOAT_EQ(got.markers[40].position_mm[0], kFrames + 400.0f);
  auto stats = source->stats();
  EXPECT_TRUE(stats.connected);
  EXPECT_EQ(stats.decode_errors, 0u);
  EXPECT_EQ(stats.frames_lost, 0u);
  EXPECT_EQ(stats.late_frames, 0u);

  // The labels change mid-stream (ids 0, 2, 5): the new table replaces the old one.
  for (const auto& r : messageReports(descriptorBytes({{0, "head"}, {2, "chest"}, {5, "hips"}}, 2))) {
    ASSERT_TRUE(dev.inject(r));
  }
  const std::vector<std::string> changed = {"head", "", "chest", "", "", "hips"};
  ASSERT_TRUE(waitFor(
      [&] {
        std::vector<std::string> now;
        return source->waitForLabels(10ms, now) && now == changed;
      },
      3s));
  // A corrupted descriptor is rejected whole: the labels stay, the error is counted.
  auto bad = descriptorBytes({{0, "x"}}, 3);
  bad[bad.size() - 6] ^= 0x01;
  for (const auto& r : messageReports(bad)) ASSERT_TRUE(dev.inject(r));
  ASSERT_TRUE(waitFor([&] { return source->stats().decode_errors == 1; }, 2s));
  ASSERT_TRUE(source->waitForLabels(0ms, labels));
  EXPECT_EQ(labels, changed);

  // Unplug: reported as the last trouble; on replug START and GET_DESCRIPTOR are sent again and
  // the device's new answer is learnt.
  dev.unplug();
  ASSERT_TRUE(waitFor([&] { return !source->stats().connected; }, 2s));
  // "disconnected ...", or already the next poll's "not found: no matching HID device".
  const std::string trouble = source->lastError();
  EXPECT_TRUE(trouble.rfind("disconnected /dev/hidraw", 0) == 0 || trouble.rfind("not found", 0) == 0) << trouble;
  dev.plug();
  ASSERT_TRUE(waitFor([&] { return source->stats().connected; }, 1s)) << "no resume within 1 s";
  EXPECT_EQ(answerCommands(dev, 3, descriptor), (std::vector<int>{0x01, 0x05, 0x03}));
  ASSERT_TRUE(waitFor(
      [&] {
        std::vector<std::string> now;
        return source->waitForLabels(10ms, now) && now == names;
      },
      3s))
      << "labels not re-learnt after the replug";
  source->stop();
  EXPECT_FALSE(source->stats().connected);
  EXPECT_EQ(source->stats().frames_published, static_cast<std::uint64_t>(kFrames));
}

TEST_F(HidSourceTest, MarkerSourceAdapterTimesOutWhenTheDeviceNeverNamesItsMarkers) {
  auto& dev = makeDevice();
  dev.plug();
  tetrig::devices::HidMarkerStreamSourceConfig config;
  config.hid = baseConfig();
  const auto source = tetrig::devices::makeHidMarkerStreamSource(config);
  EXPECT_EQ(source->nominalRateHz(), 0.0) << "no rate configured";
  ASSERT_TRUE(source->start(*mailbox_));
  EXPECT_EQ(dev.readOutput(128, 2000).size(), 128u) << "START and GET_DESCRIPTOR, no SET_RATE";
  for (const auto& r : fragments(makeFrame(1, 3))) ASSERT_TRUE(dev.inject(r));
  ASSERT_TRUE(waitFor([&] { return source->stats().frames_published == 1; }, 2s));
  std::vector<std::string> labels = {"stale"};
  EXPECT_FALSE(source->waitForLabels(100ms, labels)) << "frames alone do not name markers";
  EXPECT_EQ(labels, std::vector<std::string>{"stale"}) << "labels touched on timeout";
  source->stop();
}

TEST_F(HidSourceTest, HydraAdapterNamesItsSensorsAndCarriesButtons) {
  const Hydra hydra = plugHydra("HY2");
  auto& dev0 = hydra.motion;
  auto& dev1 = hydra.control;

  tetrig::devices::HydraSourceConfig config;
  config.hid.read_timeout_ms = 20;
  config.hid.reconnect_poll_ms = 20;
  const auto source = tetrig::devices::makeHydraSource(config);
  EXPECT_EQ(source->nominalRateHz(), 250.0);
  EXPECT_NE(source->describe().find("1532:0300"), std::string::npos) << source->describe();
  std::vector<std::string> labels;
  ASSERT_TRUE(source->waitForLabels(0ms, labels)) << "fixed labels need no device";
  EXPECT_EQ(labels, (std::vector<std::string>{"hydra0", "hydra1"}));
  ASSERT_TRUE(source->start(*mailbox_));
  ASSERT_TRUE(waitFor([&] { return dev1.featureReports().size() == 1; }, 2s)) << source->lastError();

  const float p[3] = {10.0f, 20.0f, 30.0f}, q[4] = {1.0f, 0.0f, 0.0f, 0.0f};
  for (std::uint8_t seq = 1; seq <= 8; ++seq) {
    drv::HydraRawReport raw;
    raw.sequence = seq;
    raw.controllers[0] = drv::hydraControllerFromPose(p, q);
    raw.controllers[1] = drv::hydraControllerFromPose(p, q);
    raw.controllers[0].buttons = static_cast<std::uint8_t>(1u << (seq - 1));  // one bit per report
    raw.controllers[1].buttons = static_cast<std::uint8_t>(0xF0 | seq);
    std::vector<std::uint8_t> report(drv::kHydraReportSize);
    ASSERT_EQ(drv::encodeHydraReport(raw, report), drv::kHydraReportSize);
    ASSERT_TRUE(dev0.inject(report));
  }
  ASSERT_TRUE(waitFor([&] { return source->stats().frames_published == 8; }, 3s))
      << source->stats().frames_published << " published; " << source->lastError();
  MarkerFrame got;
  ASSERT_TRUE(mailbox_->tryTakeLatest(got));
  ASSERT_EQ(got.marker_count, 2);
  EXPECT_EQ(got.markers[0].id, 0);
  EXPECT_EQ(got.markers[1].id, 1);
  EXPECT_EQ(got.markers[0].buttons, 0x80);
  EXPECT_EQ(got.markers[1].buttons, 0xF8);
  EXPECT_FLOAT_EQ(got.markers[1].position_mm[2], 30.0f);
  EXPECT_TRUE(source->stats().connected);
  EXPECT_EQ(source->stats().decode_errors, 0u);
  EXPECT_FALSE(source->finished());
  source->stop();
  dev1.unplug();  // the shared-usb interface goes first
}

}  // namespace
