// UsbTransport through the real libusb (Linux usbfs backend) on a umockdev virtual device whose
// SUBMITURB/REAPURB/DISCARDURB ioctls are served by tests/drivers/umockdev_devices.cpp.
// libusb busy-polls the emulated usbfs node, so time bounds here are only hang guards.
#include <tetrig/drivers/usb_transport.hpp>

#include "transport_test_util.hpp"
#include "umockdev_devices.hpp"

#include <gtest/gtest.h>

#include <cerrno>
#include <chrono>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace {

using namespace std::chrono_literals;
using tetrig::devices::ReceivedReport;
using tetrig::devices::TransportEvent;
using tetrig::devices::TransportStatus;
using tetrig::devices::UsbTransport;
using tetrig::devices::UsbTransportConfig;

using tetrig::testing::waitFor;
using Recorder = tetrig::testing::TransportRecorder;

std::vector<std::uint8_t> frameBytes(std::uint32_t n, std::size_t size = 100) {
  std::vector<std::uint8_t> f(size);
  for (std::size_t i = 0; i < size; ++i) f[i] = static_cast<std::uint8_t>((n * 31u + i) & 0xff);
  f[0] = static_cast<std::uint8_t>(n);
  f[1] = static_cast<std::uint8_t>(n >> 8);
  return f;
}

class UsbTransportTest : public ::testing::Test {
 protected:
  void SetUp() override {
    ASSERT_TRUE(tetrig::testing::inMockEnvironment()) << tetrig::testing::mockEnvironmentHelp();
    testbed_ = std::make_unique<tetrig::testing::Testbed>();
    device_ = std::make_unique<tetrig::testing::MockUsbDevice>(*testbed_, tetrig::testing::MockUsbSpec{});
  }
  void TearDown() override {
    if (transport_) transport_->stop();
    transport_.reset();
    device_.reset();
    testbed_.reset();
  }
  static UsbTransportConfig baseConfig() {
    UsbTransportConfig c;
    c.vendor_id = 0x1209;
    c.product_id = 0x7e71;
    c.interface_number = 0;
    c.endpoint_in = 0x81;
    c.transfer_size = 512;
    c.transfers_in_flight = 4;
    c.transfer_timeout_ms = 0;
    c.reconnect_poll_ms = 20;
    return c;
  }
  void startTransport(const UsbTransportConfig& config) {
    transport_ = std::make_unique<UsbTransport>(config);
    ASSERT_TRUE(transport_->start(rec.sink(), rec.status())) << rec.log();
  }
  std::unique_ptr<tetrig::testing::Testbed> testbed_;
  std::unique_ptr<tetrig::testing::MockUsbDevice> device_;
  Recorder rec;  // outlives transport_
  std::unique_ptr<UsbTransport> transport_;
};

TEST_F(UsbTransportTest, StreamsBulkFramesWithFourTransfersInFlight) {
  device_->plug();
  startTransport(baseConfig());
  ASSERT_TRUE(waitFor([&] { return device_->urbsPending() == 4; }, 2s)) << "never saw 4 URBs in flight" << rec.log();
  EXPECT_TRUE(transport_->connected());

  constexpr std::uint32_t kFrames = 300;
  for (std::uint32_t i = 0; i < kFrames; ++i) {
    device_->pushIn(frameBytes(i));
    if (i % 20 == 19) std::this_thread::sleep_for(1ms);
  }
  ASSERT_TRUE(waitFor([&] { return rec.reportCount() >= kFrames; }, 5s)) << "got " << rec.reportCount() << rec.log();
  {
    std::lock_guard lock(rec.mutex);
    ASSERT_EQ(rec.reports.size(), kFrames);
    for (std::uint32_t i = 0; i < kFrames; ++i) ASSERT_EQ(rec.reports[i], frameBytes(i)) << "frame " << i;
  }
  // Resubmitted from the callback: all four are back in flight, never more.
  ASSERT_TRUE(waitFor([&] { return device_->urbsPending() == 4; }, 2s));
  EXPECT_EQ(device_->maxUrbsPending(), 4);
  EXPECT_EQ(device_->lastInUrbType(), 3) << "expected USBDEVFS_URB_TYPE_BULK";
  EXPECT_GE(device_->urbsSubmitted(), static_cast<int>(kFrames) + 4);
  const auto stats = transport_->stats();
  EXPECT_EQ(stats.reports, kFrames);
  EXPECT_EQ(stats.bytes, kFrames * 100u);
  EXPECT_EQ(stats.read_errors, 0u);
  EXPECT_EQ(stats.timeouts, 0u);
}

TEST_F(UsbTransportTest, InterruptEndpointUsesTheSameAsyncPath) {
  device_->plug();
  auto config = baseConfig();
  config.endpoint_type = tetrig::devices::UsbEndpointType::kInterrupt;
  config.transfers_in_flight = 2;
  config.transfer_size = 64;
  startTransport(config);
  ASSERT_TRUE(waitFor([&] { return device_->urbsPending() == 2; }, 2s)) << rec.log();
  for (std::uint32_t i = 0; i < 20; ++i) device_->pushIn(frameBytes(i, 64));
  ASSERT_TRUE(waitFor([&] { return rec.reportCount() == 20; }, 3s)) << rec.log();
  EXPECT_EQ(device_->maxUrbsPending(), 2);
  EXPECT_EQ(device_->lastInUrbType(), 1) << "expected USBDEVFS_URB_TYPE_INTERRUPT";
  std::lock_guard lock(rec.mutex);
  EXPECT_EQ(rec.reports[19], frameBytes(19, 64));
}

TEST_F(UsbTransportTest, SendsStartCommandOnBulkOutBeforeStreaming) {
  device_->plug();
  auto config = baseConfig();
  config.open_out_data = {'T', 'G', 'S', 0x01, 0x78, 0x00};
  startTransport(config);
  ASSERT_TRUE(waitFor([&] { return device_->outTransfers().size() == 1; }, 2s)) << rec.log();
  EXPECT_EQ(device_->outTransfers()[0], config.open_out_data);
  ASSERT_TRUE(waitFor([&] { return transport_->stats().reports_sent == 1; }, 2s)) << rec.log();
  EXPECT_EQ(transport_->stats().write_errors, 0u);
  ASSERT_TRUE(waitFor([&] { return device_->urbsPending() == 4; }, 2s)) << "IN transfers after the start command";
}

TEST_F(UsbTransportTest, TimedOutTransfersAreCountedAndResubmitted) {
  device_->plug();
  auto config = baseConfig();
  config.transfer_timeout_ms = 30;
  startTransport(config);
  ASSERT_TRUE(waitFor([&] { return transport_->stats().timeouts >= 8; }, 3s)) << rec.log();
  EXPECT_GE(device_->urbsDiscarded(), 8) << "libusb cancels a timed-out URB with DISCARDURB";
  EXPECT_TRUE(transport_->connected()) << "timeouts are not an unplug";
  EXPECT_EQ(transport_->stats().disconnects, 0u);
  // Still streaming afterwards.
  device_->pushIn(frameBytes(7));
  ASSERT_TRUE(waitFor([&] { return rec.reportCount() == 1; }, 2s));
  std::lock_guard lock(rec.mutex);
  EXPECT_EQ(rec.reports[0], frameBytes(7));
}

TEST_F(UsbTransportTest, StopCancelsAndReapsEveryTransfer) {
  device_->plug();
  startTransport(baseConfig());
  ASSERT_TRUE(waitFor([&] { return device_->urbsPending() == 4; }, 2s)) << rec.log();
  transport_->stop();
  EXPECT_FALSE(transport_->running());
  EXPECT_EQ(transport_->transfersInFlight(), 0);
  EXPECT_EQ(device_->urbsPending(), 0) << "a URB was left submitted";
  EXPECT_EQ(device_->urbsDiscarded(), 4);
  EXPECT_EQ(device_->urbsReapedAfterDiscard(), 4) << "every cancelled URB must be reaped before freeing";
  EXPECT_EQ(rec.count(TransportEvent::kStopped), 1);
  transport_->stop();  // idempotent
  EXPECT_EQ(rec.count(TransportEvent::kStopped), 1);
}

TEST_F(UsbTransportTest, SurpriseUnplugIsReportedAndReplugResumes) {
  device_->plug();
  startTransport(baseConfig());
  ASSERT_TRUE(waitFor([&] { return device_->urbsPending() == 4; }, 2s)) << rec.log();
  for (std::uint32_t i = 0; i < 10; ++i) device_->pushIn(frameBytes(i));
  ASSERT_TRUE(waitFor([&] { return rec.reportCount() == 10; }, 2s));

  device_->unplug();
  ASSERT_TRUE(waitFor([&] { return !transport_->connected(); }, 2s)) << "unplug not detected" << rec.log();
  EXPECT_EQ(rec.count(TransportEvent::kDisconnected), 1) << rec.log();
  EXPECT_EQ(transport_->stats().disconnects, 1u);
  EXPECT_EQ(transport_->transfersInFlight(), 0) << "transfers must be reaped before the handle closes";

  device_->plug();
  ASSERT_TRUE(waitFor([&] { return transport_->connected(); }, 1s)) << "replug not picked up within 1 s" << rec.log();
  ASSERT_TRUE(waitFor([&] { return device_->urbsPending() == 4; }, 1s));
  for (std::uint32_t i = 100; i < 110; ++i) device_->pushIn(frameBytes(i));
  ASSERT_TRUE(waitFor([&] { return rec.reportCount() == 20; }, 2s)) << "stream did not resume" << rec.log();
  std::lock_guard lock(rec.mutex);
  EXPECT_EQ(rec.reports[10], frameBytes(100));
  EXPECT_EQ(rec.reports[19], frameBytes(109));
}

TEST_F(UsbTransportTest, HotplugArrivalOpensTheDeviceWithoutPolling) {
  auto config = baseConfig();
  config.reconnect_poll_ms = 60'000;  // only the hotplug callback can open it in time
  startTransport(config);
  ASSERT_TRUE(transport_->hotplugActive()) << "libusb reports no hotplug support under umockdev";
  ASSERT_TRUE(waitFor([&] { return rec.count(TransportEvent::kNotFound) == 1; }, 2s)) << rec.log();
  device_->plug();
  ASSERT_TRUE(waitFor([&] { return transport_->connected(); }, 1s)) << "hotplug arrival not acted on" << rec.log();
  EXPECT_GE(transport_->stats().hotplug_arrivals, 1u);
  ASSERT_TRUE(waitFor([&] { return device_->urbsPending() == 4; }, 1s));
  device_->pushIn(frameBytes(1));
  ASSERT_TRUE(waitFor([&] { return rec.reportCount() == 1; }, 2s));
}

TEST_F(UsbTransportTest, TransferErrorsAreReportedAndRepeatedOnesReopenTheDevice) {
  device_->plug();
  auto config = baseConfig();
  config.max_consecutive_errors = 4;
  startTransport(config);
  ASSERT_TRUE(waitFor([&] { return device_->urbsPending() == 4; }, 2s)) << rec.log();
  // Isolated errors: reported, counted, resubmitted; the data behind them still arrives.
  device_->pushInError(-EPROTO);
  device_->pushInError(-EPIPE);
  device_->pushIn(frameBytes(1));
  ASSERT_TRUE(waitFor([&] { return rec.reportCount() == 1; }, 2s)) << rec.log();
  EXPECT_EQ(transport_->stats().read_errors, 2u);
  EXPECT_EQ(rec.count(TransportEvent::kReadError), 2);
  EXPECT_EQ(transport_->stats().disconnects, 0u);
  // A run of errors means the device is unusable: cancel, reap, close, open again.
  for (int i = 0; i < 4; ++i) device_->pushInError(-EPROTO);
  ASSERT_TRUE(waitFor([&] { return transport_->stats().opens == 2; }, 2s)) << rec.log();
  EXPECT_EQ(transport_->stats().disconnects, 1u);
  ASSERT_TRUE(waitFor([&] { return device_->urbsPending() == 4; }, 2s));
  device_->pushIn(frameBytes(2));
  ASSERT_TRUE(waitFor([&] { return rec.reportCount() == 2; }, 2s));
}

TEST_F(UsbTransportTest, AbsentDeviceIsReportedOnceAndStopIsClean) {
  // No device with this id ever appears: the transport keeps waiting, reports once, stops cleanly.
  auto config = baseConfig();
  config.product_id = 0x0bad;
  device_->plug();
  startTransport(config);
  ASSERT_TRUE(waitFor([&] { return rec.count(TransportEvent::kNotFound) == 1; }, 2s)) << rec.log();
  std::this_thread::sleep_for(60ms);
  EXPECT_EQ(rec.count(TransportEvent::kNotFound), 1);
  EXPECT_FALSE(transport_->connected());
  transport_->stop();
  EXPECT_EQ(rec.count(TransportEvent::kStopped), 1);
}

}  // namespace

// ------------------------------------------------------------------------------------------------
// UsbMarkerStreamSource: whole frames per bulk transfer, decoded into the mailbox.

#include <tetrig/drivers/device_sources.hpp>

namespace {

namespace drv = tetrig::drivers;

std::vector<std::uint8_t> encodedFrame(std::uint64_t counter, int markers) {
  tetrig::MarkerFrame f;
  f.frame_counter = counter;
  f.marker_count = static_cast<std::uint16_t>(markers);
  for (int i = 0; i < markers; ++i) {
    auto& m = f.markers[static_cast<std::size_t>(i)];
    m.id = static_cast<std::uint16_t>(100 + i);
    m.valid = (i % 5 != 4) ? 1 : 0;
    m.position_mm[0] = static_cast<float>(i);
    m.position_mm[1] = static_cast<float>(counter);
    m.position_mm[2] = 1000.0f;
  }
  std::vector<std::uint8_t> bytes(drv::kMarkerStreamMaxFrameSize);
  bytes.resize(drv::encodeMarkerStreamFrame(f, {}, bytes));
  return bytes;
}

TEST_F(UsbTransportTest, MarkerStreamSourceSendsStartAndPublishesWholeFrames) {
  device_->plug();
  auto mailbox = std::make_unique<tetrig::FrameMailbox>();
  tetrig::devices::UsbMarkerStreamSourceConfig config;
  config.usb = baseConfig();
  config.rate_hz = 200;
  tetrig::devices::UsbMarkerStreamSource source(config, *mailbox);
  ASSERT_TRUE(source.start(rec.status()));
  ASSERT_TRUE(waitFor([&] { return device_->urbsPending() == 4; }, 2s)) << rec.log();

  // START, GET_DESCRIPTOR and SET_RATE went out as vendor control requests before streaming
  // (setup packet: bmRequestType, bRequest, wValue LE, wIndex LE, wLength LE).
  const auto control = device_->controlRequests();
  ASSERT_EQ(control.size(), 3u);
  const auto start = drv::markerStreamControlSetup(drv::MarkerStreamCommand::kStart, 0, 0);
  const auto rate = drv::markerStreamControlSetup(drv::MarkerStreamCommand::kSetRate, 200, 0);
  ASSERT_EQ(control[0].size(), 8u);
  // docs/protocol.md 3.3: bmRequestType 0x41, bRequest = opcode (START 0x01, GET_DESCRIPTOR
  // 0x05, SET_RATE 0x03), wValue = param, wIndex = interface, wLength 0.
  EXPECT_EQ(control[0], (std::vector<std::uint8_t>{0x41, 0x01, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00}));
  EXPECT_EQ(control[1], (std::vector<std::uint8_t>{0x41, 0x05, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00}));
  EXPECT_EQ(control[2], (std::vector<std::uint8_t>{0x41, 0x03, 200, 0x00, 0x00, 0x00, 0x00, 0x00}));
  EXPECT_EQ(control[0][1], start.request);
  EXPECT_EQ(control[2][1], rate.request);

  constexpr int kFrames = 50;
  for (int i = 1; i <= kFrames; ++i) device_->pushIn(encodedFrame(static_cast<std::uint64_t>(i), 40));
  ASSERT_TRUE(waitFor([&] { return source.stats().frames_published == kFrames; }, 5s))
      << source.stats().frames_published << " published" << rec.log();
  tetrig::MarkerFrame got;
  ASSERT_TRUE(mailbox->tryTakeLatest(got));
  EXPECT_EQ(got.frame_counter, static_cast<std::uint64_t>(kFrames));
  ASSERT_EQ(got.marker_count, 40);
  EXPECT_EQ(got.markers[7].id, 107);
  EXPECT_FLOAT_EQ(got.markers[7].position_mm[1], static_cast<float>(kFrames));
  EXPECT_EQ(got.markers[4].valid, 0);
  EXPECT_EQ(got.markers[5].valid, 1);

  // A corrupted frame is counted as a decode error; the stream goes on.
  auto bad = encodedFrame(kFrames + 1, 40);
  bad[40] ^= 0xFF;
  device_->pushIn(bad);
  device_->pushIn(encodedFrame(kFrames + 2, 40));
  ASSERT_TRUE(waitFor([&] { return source.stats().frames_published == kFrames + 1; }, 2s));
  EXPECT_EQ(source.stats().decode_errors, 1u);
  EXPECT_EQ(source.stats().last_error, static_cast<int>(drv::MarkerStreamStatus::kBadCrc));
  ASSERT_TRUE(mailbox->tryTakeLatest(got));
  EXPECT_EQ(got.frame_counter, static_cast<std::uint64_t>(kFrames + 2));
  source.stop();
  EXPECT_EQ(device_->urbsPending(), 0);
}

}  // namespace

// ------------------------------------------------------------------------------------------------
// The USB marker stream in the MarkerSource shape: the device answers START / GET_DESCRIPTOR with
// its descriptor as one bulk transfer, then streams frames.

#include <tetrig/drivers/device_marker_sources.hpp>

namespace {

std::vector<std::uint8_t> descriptorBytes(const std::vector<std::string>& names, std::uint16_t first_id,
                                          std::uint32_t table_id) {
  std::vector<drv::MarkerLabel> labels;
  for (std::size_t i = 0; i < names.size(); ++i) labels.push_back({static_cast<std::uint16_t>(first_id + i), names[i]});
  std::vector<std::uint8_t> bytes(drv::kMarkerStreamMaxDescriptorSize);
  bytes.resize(drv::encodeMarkerStreamDescriptor(labels, table_id, bytes));
  return bytes;
}

TEST_F(UsbTransportTest, MarkerSourceAdapterLearnsLabelsOverBulkIncludingTheLargestDescriptor) {
  device_->plug();
  auto mailbox = std::make_unique<tetrig::FrameMailbox>();
  tetrig::devices::UsbMarkerStreamSourceConfig config;
  config.usb = baseConfig();
  const auto source = tetrig::devices::makeUsbMarkerStreamSource(config);
  EXPECT_NE(source->describe().find("1209:7e71"), std::string::npos) << source->describe();
  EXPECT_EQ(source->nominalRateHz(), 0.0);
  ASSERT_TRUE(source->start(*mailbox));
  ASSERT_TRUE(waitFor([&] { return device_->urbsPending() == 4; }, 2s)) << source->lastError();
  const auto control = device_->controlRequests();
  ASSERT_EQ(control.size(), 2u) << "START and GET_DESCRIPTOR (no rate configured)";
  EXPECT_EQ(control[0][1], 0x01);
  EXPECT_EQ(control[1], (std::vector<std::uint8_t>{0x41, 0x05, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00}));

  // The device's answer: the descriptor as one bulk transfer (ids 100.. like encodedFrame's).
  std::vector<std::string> names;
  for (int i = 0; i < 40; ++i) names.push_back("marker " + std::to_string(i));
  device_->pushIn(descriptorBytes(names, 100, 1));
  std::vector<std::string> labels;
  ASSERT_TRUE(source->waitForLabels(3s, labels)) << source->lastError();
  ASSERT_EQ(labels.size(), 140u);
  EXPECT_EQ(labels[99], "");
  EXPECT_EQ(labels[100], "marker 0");
  EXPECT_EQ(labels[139], "marker 39");

  for (int i = 1; i <= 10; ++i) device_->pushIn(encodedFrame(static_cast<std::uint64_t>(i), 40));
  ASSERT_TRUE(waitFor([&] { return source->stats().frames_published == 10; }, 3s)) << source->lastError();
  tetrig::MarkerFrame got;
  ASSERT_TRUE(mailbox->tryTakeLatest(got));
  EXPECT_EQ(labels[got.markers[7].id], "marker 7");

  // The largest descriptor a v1.0 sender writes (256 labels of 31 bytes, 8728 bytes) is longer
  // than the largest frame (8260): it must still fit one IN transfer.
  std::vector<std::string> big;
  for (int i = 0; i < 256; ++i) {
    std::string t = std::to_string(i);
    t.resize(drv::kMarkerLabelMaxLength, '.');
    big.push_back(t);
  }
  const auto big_bytes = descriptorBytes(big, 0, 2);
  ASSERT_GT(big_bytes.size(), drv::kMarkerStreamMaxFrameSize);
  device_->pushIn(big_bytes);
  ASSERT_TRUE(waitFor(
      [&] {
        std::vector<std::string> now;
        return source->waitForLabels(10ms, now) && now.size() == 256 && now[255] == big[255];
      },
      3s))
      << "decode errors " << source->stats().decode_errors;
  EXPECT_EQ(source->stats().decode_errors, 0u);
  EXPECT_TRUE(source->stats().connected);
  source->stop();
  EXPECT_EQ(device_->urbsPending(), 0);
}

}  // namespace
