// Adapters from the device sources (device_sources.hpp: HID / USB marker stream, Razer Hydra) to
// the one source shape tetrig::drivers::MarkerSource (see device_marker_sources.hpp): the device
// source is built in start(mailbox), transport trouble is kept for lastError(), labels come from
// the marker-stream descriptor or the Hydra's fixed sensor names.
#include <tetrig/drivers/device_marker_sources.hpp>

#include <cstdio>
#include <mutex>
#include <string>
#include <utility>

namespace tetrig::devices {

namespace {

// Transport events that mean trouble (the rest: opened, report sent, hotplug arrival, stopped).
bool isTroubleEvent(TransportEvent event) noexcept {
  switch (event) {
    case TransportEvent::kOpenFailed:
    case TransportEvent::kNotFound:
    case TransportEvent::kDisconnected:
    case TransportEvent::kReadError:
    case TransportEvent::kTimeout:
    case TransportEvent::kWriteError:
    case TransportEvent::kFeatureError:
      return true;
    case TransportEvent::kOpened:
    case TransportEvent::kReportSent:
    case TransportEvent::kHotplugArrived:
    case TransportEvent::kStopped:
      return false;
  }
  return false;
}

std::string vidPid(std::uint16_t vendor_id, std::uint16_t product_id) {
  char buf[16];
  std::snprintf(buf, sizeof(buf), "%04x:%04x", vendor_id, product_id);
  return buf;
}

// (Appends piecewise: GCC 12's -Wrestrict misfires on "literal" + std::string temporaries.)
void appendRate(std::string& text, std::uint16_t rate_hz) {
  if (rate_hz == 0) {
    text.append(", device rate");
    return;
  }
  text.append(", ");
  text.append(std::to_string(rate_hz));
  text.append(" Hz requested");
}

drivers::MarkerSourceStats toMarkerSourceStats(const DeviceSourceStats& d) noexcept {
  drivers::MarkerSourceStats s;
  s.frames_published = d.frames_published;
  s.frames_lost = d.frames_lost;
  s.decode_errors = d.decode_errors;
  s.late_frames = 0;  // live devices are not paced
  s.rejected_markers = d.rejected_markers;
  s.connected = d.connected;
  return s;
}

// The last trouble a transport reported (written on the driver thread, read on any thread).
class TroubleLog {
 public:
  void note(const TransportStatus& s) {
    if (!isTroubleEvent(s.event)) return;
    std::string text(transportEventName(s.event));
    if (!s.device.empty()) {
      text.push_back(' ');
      text.append(s.device);
    }
    text.append(": ");
    text.append(s.detail);
    std::lock_guard lock(mutex_);
    last_ = std::move(text);
  }
  void set(std::string text) {
    std::lock_guard lock(mutex_);
    last_ = std::move(text);
  }
  std::string get() const {
    std::lock_guard lock(mutex_);
    return last_;
  }

 private:
  mutable std::mutex mutex_;
  std::string last_;
};

// Common part: the device source of type `Source` (built from `Config` and the mailbox in
// start()), its lifetime, stats and trouble log. `source_mutex_` guards the pointer against a
// stats() call from another thread while start() replaces it; the driver thread never takes it.
template <class Source, class Config>
class DeviceAdapter : public drivers::MarkerSource {
 public:
  DeviceAdapter(Config config, std::string description, double rate_hz)
      : config_(std::move(config)), description_(std::move(description)), rate_hz_(rate_hz) {}
  ~DeviceAdapter() override { DeviceAdapter::stop(); }
  DeviceAdapter(const DeviceAdapter&) = delete;
  DeviceAdapter& operator=(const DeviceAdapter&) = delete;

  std::string describe() const override { return description_; }
  double nominalRateHz() const override { return rate_hz_; }

  bool start(FrameMailbox& mailbox) override {
    std::lock_guard lock(source_mutex_);
    if (source_ != nullptr && running_) {
      log_.set("start: the source is already running");
      return false;
    }
    source_.reset();  // one from an earlier start(): stopped already
    source_ = std::make_unique<Source>(config_, mailbox);
    if (!source_->start([this](const TransportStatus& s) { log_.note(s); })) {
      if (log_.get().empty()) log_.set("start: the transport could not be started");
      return false;
    }
    running_ = true;
    return true;
  }

  void stop() override {
    std::lock_guard lock(source_mutex_);
    if (source_ != nullptr) source_->stop();
    running_ = false;
  }

  bool finished() const noexcept override { return false; }

  drivers::MarkerSourceStats stats() const noexcept override {
    std::lock_guard lock(source_mutex_);
    return source_ != nullptr ? toMarkerSourceStats(source_->stats()) : drivers::MarkerSourceStats{};
  }

  std::string lastError() const override { return log_.get(); }

 protected:
  // The running device source, or nullptr before the first start(). Control thread (start() and
  // stop() run there too, so the object cannot go away under the caller).
  Source* current() {
    std::lock_guard lock(source_mutex_);
    return source_.get();
  }

 private:
  const Config config_;
  const std::string description_;
  const double rate_hz_;
  TroubleLog log_;  // before source_: the driver thread's status sink writes it until source_ is gone
  mutable std::mutex source_mutex_;
  std::unique_ptr<Source> source_;  // guarded by source_mutex_
  bool running_ = false;            // guarded by source_mutex_
};

// Marker streams: labels from the device's descriptor.
template <class Source, class Config>
class MarkerStreamAdapter final : public DeviceAdapter<Source, Config> {
 public:
  using DeviceAdapter<Source, Config>::DeviceAdapter;
  bool waitForLabels(std::chrono::milliseconds timeout, std::vector<std::string>& labels) override {
    Source* source = this->current();
    return source != nullptr && source->waitForLabels(timeout, labels);
  }
};

// The Hydra: fixed sensor names.
class HydraAdapter final : public DeviceAdapter<HydraSource, HydraSourceConfig> {
 public:
  using DeviceAdapter::DeviceAdapter;
  bool waitForLabels(std::chrono::milliseconds, std::vector<std::string>& labels) override {
    labels.assign(drivers::kHydraSensorLabels.begin(), drivers::kHydraSensorLabels.end());
    return true;
  }
};

}  // namespace

std::unique_ptr<drivers::MarkerSource> makeHidMarkerStreamSource(HidMarkerStreamSourceConfig config) {
  std::string text = "hid marker stream ";
  text.append(vidPid(config.hid.vendor_id, config.hid.product_id));
  if (!config.hid.serial.empty()) text.append(" serial ").append(config.hid.serial);
  appendRate(text, config.rate_hz);
  const double rate = config.rate_hz;
  return std::make_unique<MarkerStreamAdapter<HidMarkerStreamSource, HidMarkerStreamSourceConfig>>(
      std::move(config), std::move(text), rate);
}

std::unique_ptr<drivers::MarkerSource> makeUsbMarkerStreamSource(UsbMarkerStreamSourceConfig config) {
  char endpoint[48];
  std::snprintf(endpoint, sizeof(endpoint), " interface %d endpoint 0x%02x", config.usb.interface_number,
                static_cast<unsigned>(config.usb.endpoint_in));
  std::string text = "usb marker stream ";
  text.append(vidPid(config.usb.vendor_id, config.usb.product_id)).append(endpoint);
  appendRate(text, config.rate_hz);
  const double rate = config.rate_hz;
  return std::make_unique<MarkerStreamAdapter<UsbMarkerStreamSource, UsbMarkerStreamSourceConfig>>(
      std::move(config), std::move(text), rate);
}

std::unique_ptr<drivers::MarkerSource> makeHydraSource(HydraSourceConfig config) {
  const std::uint16_t vid = config.hid.vendor_id != 0 ? config.hid.vendor_id : drivers::kHydraVendorId;
  const std::uint16_t pid = config.hid.product_id != 0 ? config.hid.product_id : drivers::kHydraProductId;
  std::string text = "razer hydra ";
  text.append(vidPid(vid, pid));
  if (!config.hid.serial.empty()) text.append(" serial ").append(config.hid.serial);
  text.append(", 2 sensors (hydra0, hydra1), 250 Hz nominal");
  return std::make_unique<HydraAdapter>(std::move(config), std::move(text), drivers::kHydraNominalRateHz);
}

}  // namespace tetrig::devices
