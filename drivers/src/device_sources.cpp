// Device sources: transport + decoder + latest-frame mailbox, and the marker-stream label table
// handed from the driver thread to the control thread (see device_sources.hpp).
#include <tetrig/drivers/device_sources.hpp>

#include <algorithm>
#include <utility>

namespace tetrig::devices {

namespace {

constexpr auto kRelaxed = std::memory_order_relaxed;

std::vector<std::uint8_t> commandReport(drivers::MarkerStreamCommand command, std::uint16_t param) {
  std::vector<std::uint8_t> report(drivers::kMarkerStreamHidReportSize, 0);
  (void)drivers::encodeMarkerStreamCommandReport(command, param, report);
  return report;
}

UsbControlRequest controlRequest(drivers::MarkerStreamCommand command, std::uint16_t param, int interface_number) {
  const drivers::UsbControlSetup setup =
      drivers::markerStreamControlSetup(command, param, static_cast<std::uint16_t>(std::max(interface_number, 0)));
  UsbControlRequest r;
  r.request_type = setup.request_type;
  r.request = setup.request;
  r.value = setup.value;
  r.index = setup.index;
  r.data.assign(setup.length, 0);
  return r;
}

HidTransportConfig prepareHidMarkerStream(const HidMarkerStreamSourceConfig& c) {
  HidTransportConfig hid = c.hid;
  hid.report_size = drivers::kMarkerStreamHidReportSize;
  hid.open_output_reports.push_back(
      commandReport(drivers::MarkerStreamCommand::kStart, static_cast<std::uint16_t>(c.record_format)));
  // Right after START: a host that (re)connects mid-stream learns the labels at once.
  hid.open_output_reports.push_back(commandReport(drivers::MarkerStreamCommand::kGetDescriptor, 0));
  if (c.rate_hz > 0) hid.open_output_reports.push_back(commandReport(drivers::MarkerStreamCommand::kSetRate, c.rate_hz));
  return hid;
}

HidTransportConfig prepareHydra(const HydraSourceConfig& c) {
  HidTransportConfig hid = c.hid;
  if (hid.vendor_id == 0) hid.vendor_id = drivers::kHydraVendorId;
  if (hid.product_id == 0) hid.product_id = drivers::kHydraProductId;
  if (hid.interface_number < 0) hid.interface_number = drivers::kHydraMotionInterface;
  if (hid.feature_interface_number < 0) hid.feature_interface_number = drivers::kHydraControlInterface;
  hid.report_size = drivers::kHydraReportSize;
  if (hid.open_feature_reports.empty()) {
    const auto mode = drivers::hydraMotionModeFeatureReport();
    hid.open_feature_reports.emplace_back(mode.begin(), mode.end());
  }
  return hid;
}

UsbTransportConfig prepareUsbMarkerStream(const UsbMarkerStreamSourceConfig& c) {
  UsbTransportConfig usb = c.usb;
  usb.transfer_size = std::max(usb.transfer_size, drivers::kMarkerStreamMaxMessageSize);  // frames and descriptors
  usb.open_control_requests.push_back(controlRequest(
      drivers::MarkerStreamCommand::kStart, static_cast<std::uint16_t>(c.record_format), usb.interface_number));
  usb.open_control_requests.push_back(
      controlRequest(drivers::MarkerStreamCommand::kGetDescriptor, 0, usb.interface_number));
  if (c.rate_hz > 0) {
    usb.open_control_requests.push_back(
        controlRequest(drivers::MarkerStreamCommand::kSetRate, c.rate_hz, usb.interface_number));
  }
  return usb;
}

// Wraps the caller's status sink: after every open the decoder forgets its partial state.
template <class Decoder>
StatusSink resettingStatus(Decoder& decoder, StatusSink& user) {
  return [&decoder, &user](const TransportStatus& s) {
    if (s.event == TransportEvent::kOpened) decoder.reset();  // driver thread, like the sink
    if (user) user(s);
  };
}

void countMarkerStreamError(detail::AtomicSourceStats& stats, drivers::MarkerStreamStatus status) noexcept {
  stats.decode_errors.fetch_add(1, kRelaxed);
  stats.last_error.store(static_cast<int>(status), kRelaxed);
}

void mirrorDecoderStats(detail::AtomicSourceStats& stats, std::uint64_t lost, std::uint64_t duplicates,
                        std::uint64_t rejected) noexcept {
  stats.frames_lost.store(lost, kRelaxed);
  stats.duplicates.store(duplicates, kRelaxed);
  stats.rejected_markers.store(rejected, kRelaxed);
}

void mirrorMarkerStreamStats(detail::AtomicSourceStats& stats, const drivers::MarkerStreamStats& d) noexcept {
  mirrorDecoderStats(stats, d.frames_lost, d.duplicates, d.rejected_markers);
  stats.descriptors_accepted.store(d.descriptors_accepted, kRelaxed);
  stats.descriptors_rejected.store(d.descriptors_rejected, kRelaxed);
}

// What a marker-stream source does with one decoder verdict (driver thread, no allocation; the
// label lock is taken only for a descriptor).
void handleMarkerStreamStatus(drivers::MarkerStreamStatus status, FrameMailbox& mailbox,
                              const drivers::MarkerStreamDecoder& decoder, detail::AtomicSourceStats& stats,
                              detail::LabelStore& labels) noexcept {
  switch (status) {
    case drivers::MarkerStreamStatus::kFrame:
      mailbox.commit();
      stats.frames_published.fetch_add(1, kRelaxed);
      break;
    case drivers::MarkerStreamStatus::kDescriptor: labels.publish(decoder.labels()); break;
    case drivers::MarkerStreamStatus::kNeedMore: break;
    default: countMarkerStreamError(stats, status); break;
  }
  mirrorMarkerStreamStats(stats, decoder.stats());
}

}  // namespace

namespace detail {
DeviceSourceStats AtomicSourceStats::snapshot() const noexcept {
  DeviceSourceStats s;
  s.frames_published = frames_published.load(kRelaxed);
  s.decode_errors = decode_errors.load(kRelaxed);
  s.frames_lost = frames_lost.load(kRelaxed);
  s.duplicates = duplicates.load(kRelaxed);
  s.rejected_markers = rejected_markers.load(kRelaxed);
  s.descriptors_accepted = descriptors_accepted.load(kRelaxed);
  s.descriptors_rejected = descriptors_rejected.load(kRelaxed);
  s.last_error = last_error.load(kRelaxed);
  return s;
}

void LabelStore::publish(const drivers::MarkerLabelTable& table) noexcept {
  {
    std::lock_guard lock(mutex_);
    table_ = table;
    generation_.store(table.generation, std::memory_order_release);
  }
  changed_.notify_all();
}

bool LabelStore::wait(std::chrono::milliseconds timeout, std::vector<std::string>& labels) {
  std::unique_lock lock(mutex_);
  if (!changed_.wait_for(lock, timeout, [this] { return table_.generation != 0; })) return false;
  labels.clear();
  if (table_.count == 0) return true;
  labels.resize(static_cast<std::size_t>(table_.entries[table_.count - 1u].id) + 1u);  // ids ascend
  for (std::size_t i = 0; i < table_.count; ++i) labels[table_.entries[i].id] = std::string(table_.entries[i].label());
  return true;
}
}  // namespace detail

// ---------------------------------------------------------------- HID marker stream

HidMarkerStreamSource::HidMarkerStreamSource(HidMarkerStreamSourceConfig config, FrameMailbox& mailbox)
    : mailbox_(mailbox), transport_(prepareHidMarkerStream(config)), decoder_(config.decoder) {}

HidMarkerStreamSource::~HidMarkerStreamSource() { stop(); }

bool HidMarkerStreamSource::start(StatusSink status) {
  if (transport_.running()) return false;
  user_status_ = std::move(status);
  return transport_.start([this](const ReceivedReport& r) { onReport(r); }, resettingStatus(decoder_, user_status_));
}

void HidMarkerStreamSource::stop() { transport_.stop(); }

void HidMarkerStreamSource::onReport(const ReceivedReport& report) noexcept {
  const auto status = decoder_.decodeHidReport(report.bytes, report.receive_ns, mailbox_.producerSlot());
  handleMarkerStreamStatus(status, mailbox_, decoder_, stats_, labels_);
}

DeviceSourceStats HidMarkerStreamSource::stats() const noexcept {
  DeviceSourceStats s = stats_.snapshot();
  s.connected = transport_.connected();
  s.transport = transport_.stats();
  s.mailbox = mailbox_.stats();
  return s;
}

bool HidMarkerStreamSource::waitForLabels(std::chrono::milliseconds timeout, std::vector<std::string>& labels) {
  return labels_.wait(timeout, labels);
}

// ---------------------------------------------------------------- Hydra

HydraSource::HydraSource(HydraSourceConfig config, FrameMailbox& mailbox)
    : mailbox_(mailbox), transport_(prepareHydra(config)) {}

HydraSource::~HydraSource() { stop(); }

bool HydraSource::start(StatusSink status) {
  if (transport_.running()) return false;
  user_status_ = std::move(status);
  return transport_.start([this](const ReceivedReport& r) { onReport(r); }, resettingStatus(decoder_, user_status_));
}

void HydraSource::stop() { transport_.stop(); }

void HydraSource::onReport(const ReceivedReport& report) noexcept {
  const auto status = decoder_.decode(report.bytes, report.receive_ns, mailbox_.producerSlot());
  if (status == drivers::HydraStatus::kFrame) {
    mailbox_.commit();
    stats_.frames_published.fetch_add(1, kRelaxed);
  } else {
    stats_.decode_errors.fetch_add(1, kRelaxed);
    stats_.last_error.store(static_cast<int>(status), kRelaxed);
  }
  const auto& d = decoder_.stats();
  mirrorDecoderStats(stats_, d.frames_lost, d.duplicates, d.rejected_markers);
}

DeviceSourceStats HydraSource::stats() const noexcept {
  DeviceSourceStats s = stats_.snapshot();
  s.connected = transport_.connected();
  s.transport = transport_.stats();
  s.mailbox = mailbox_.stats();
  return s;
}

// ---------------------------------------------------------------- USB marker stream

UsbMarkerStreamSource::UsbMarkerStreamSource(UsbMarkerStreamSourceConfig config, FrameMailbox& mailbox)
    : mailbox_(mailbox), transport_(prepareUsbMarkerStream(config)), decoder_(config.decoder) {}

UsbMarkerStreamSource::~UsbMarkerStreamSource() { stop(); }

bool UsbMarkerStreamSource::start(StatusSink status) {
  if (transport_.running()) return false;
  user_status_ = std::move(status);
  return transport_.start([this](const ReceivedReport& r) { onTransfer(r); }, resettingStatus(decoder_, user_status_));
}

void UsbMarkerStreamSource::stop() { transport_.stop(); }

void UsbMarkerStreamSource::onTransfer(const ReceivedReport& report) noexcept {
  const auto status = decoder_.decodeFrame(report.bytes, report.receive_ns, mailbox_.producerSlot());
  handleMarkerStreamStatus(status, mailbox_, decoder_, stats_, labels_);
}

DeviceSourceStats UsbMarkerStreamSource::stats() const noexcept {
  DeviceSourceStats s = stats_.snapshot();
  s.connected = transport_.connected();
  s.transport = transport_.stats();
  s.mailbox = mailbox_.stats();
  return s;
}

bool UsbMarkerStreamSource::waitForLabels(std::chrono::milliseconds timeout, std::vector<std::string>& labels) {
  return labels_.wait(timeout, labels);
}

}  // namespace tetrig::devices
