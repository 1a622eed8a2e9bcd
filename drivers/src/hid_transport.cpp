// HID transport over hidapi's hidraw backend: driver thread, reconnect by enumeration polling.
#include <tetrig/drivers/hid_transport.hpp>

#include <hidapi.h>

#include <algorithm>
#include <chrono>
#include <cstring>
#include <cwchar>
#include <mutex>
#include <utility>

namespace tetrig::devices {

namespace {

// hidapi strings are wchar_t (UTF-32 on Linux); encode as UTF-8 without depending on the locale.
std::string toUtf8(const wchar_t* text) {
  std::string out;
  if (text == nullptr) return out;
  for (; *text != L'\0'; ++text) {
    auto c = static_cast<std::uint32_t>(*text);
    if (c > 0x10FFFF || (c >= 0xD800 && c <= 0xDFFF)) c = 0xFFFD;
    if (c < 0x80) {
      out.push_back(static_cast<char>(c));
    } else if (c < 0x800) {
      out.push_back(static_cast<char>(0xC0 | (c >> 6)));
      out.push_back(static_cast<char>(0x80 | (c & 0x3F)));
    } else if (c < 0x10000) {
      out.push_back(static_cast<char>(0xE0 | (c >> 12)));
      out.push_back(static_cast<char>(0x80 | ((c >> 6) & 0x3F)));
      out.push_back(static_cast<char>(0x80 | (c & 0x3F)));
    } else {
      out.push_back(static_cast<char>(0xF0 | (c >> 18)));
      out.push_back(static_cast<char>(0x80 | ((c >> 12) & 0x3F)));
      out.push_back(static_cast<char>(0x80 | ((c >> 6) & 0x3F)));
      out.push_back(static_cast<char>(0x80 | (c & 0x3F)));
    }
  }
  return out;
}

void hidInitOnce() {
  static std::once_flag once;
  std::call_once(once, [] { hid_init(); });
}

HidDeviceInfo toInfo(const hid_device_info& d) {
  HidDeviceInfo info;
  info.path = d.path != nullptr ? d.path : "";
  info.vendor_id = d.vendor_id;
  info.product_id = d.product_id;
  info.release = d.release_number;
  info.interface_number = d.interface_number;
  info.usage_page = d.usage_page;
  info.usage = d.usage;
  info.manufacturer = toUtf8(d.manufacturer_string);
  info.product = toUtf8(d.product_string);
  info.serial = toUtf8(d.serial_number);
  return info;
}

}  // namespace

std::vector<HidDeviceInfo> enumerateHid(std::uint16_t vendor_id, std::uint16_t product_id) {
  hidInitOnce();
  std::vector<HidDeviceInfo> out;
  hid_device_info* list = hid_enumerate(vendor_id, product_id);
  for (const hid_device_info* d = list; d != nullptr; d = d->next) {
    // hidapi lists one entry per top-level usage; keep one per path.
    if (d->path != nullptr &&
        std::none_of(out.begin(), out.end(), [&](const HidDeviceInfo& e) { return e.path == d->path; })) {
      out.push_back(toInfo(*d));
    }
  }
  hid_free_enumeration(list);
  return out;
}

struct HidTransport::Impl {
  hid_device* device = nullptr;
  std::string path;          // of the open device, for status reports
  std::string feature_path;  // separate feature interface's node (empty: use `device`)
  std::string error_text;    // scratch for hid_error() conversions (error path only)
  std::string last_open_error;  // last reported open failure (cleared by a successful open)
};

HidTransport::HidTransport(HidTransportConfig config)
    : config_(std::move(config)), impl_(std::make_unique<Impl>()) {
  config_.report_size = std::max<std::size_t>(config_.report_size, 1);
  config_.read_timeout_ms = std::max(config_.read_timeout_ms, 1);
  config_.reconnect_poll_ms = std::max(config_.reconnect_poll_ms, 1);
  buffer_.assign(config_.report_size, 0);
}

HidTransport::~HidTransport() { stop(); }

bool HidTransport::start(ReportSink sink, StatusSink status) {
  if (running_.load(std::memory_order_acquire) || thread_.joinable()) return false;
  hidInitOnce();
  sink_ = std::move(sink);
  status_ = std::move(status);
  {
    std::lock_guard lock(wake_mutex_);
    stop_requested_ = false;
  }
  stop_flag_.store(false, std::memory_order_release);
  running_.store(true, std::memory_order_release);
  thread_ = std::thread([this] { run(); });
  return true;
}

void HidTransport::stop() {
  {
    std::lock_guard lock(wake_mutex_);
    stop_requested_ = true;
  }
  stop_flag_.store(true, std::memory_order_release);
  wake_.notify_all();
  if (thread_.joinable()) thread_.join();
  running_.store(false, std::memory_order_release);
}

bool HidTransport::waitStop(int milliseconds) {
  std::unique_lock lock(wake_mutex_);
  wake_.wait_for(lock, std::chrono::milliseconds(milliseconds), [this] { return stop_requested_; });
  return stop_requested_;
}

bool HidTransport::sendOutputReport(std::span<const std::uint8_t> report) { return enqueue(false, report); }
bool HidTransport::sendFeatureReport(std::span<const std::uint8_t> report) { return enqueue(true, report); }

bool HidTransport::enqueue(bool feature, std::span<const std::uint8_t> report) {
  if (!running_.load(std::memory_order_acquire) || report.empty() || report.size() > kMaxCommandBytes) {
    detail::AtomicTransportStats::bump(stats_.commands_dropped);
    return false;
  }
  {
    std::lock_guard lock(command_mutex_);
    if (command_count_ == kCommandQueueCapacity) {
      detail::AtomicTransportStats::bump(stats_.commands_dropped);
      return false;
    }
    Command& c = commands_[(command_head_ + command_count_) % kCommandQueueCapacity];
    c.feature = feature;
    c.size = static_cast<std::uint16_t>(report.size());
    std::memcpy(c.bytes.data(), report.data(), report.size());
    ++command_count_;
  }
  commands_pending_.store(true, std::memory_order_release);
  return true;
}

HidDeviceInfo HidTransport::currentDevice() const {
  std::lock_guard lock(info_mutex_);
  return current_;
}

void HidTransport::report(TransportEvent event, std::string_view detail, int code) {
  if (!status_) return;
  TransportStatus s;
  s.event = event;
  s.device = impl_->path;
  s.detail = detail;
  s.code = code;
  status_(s);
}

bool HidTransport::tryOpen(bool& reported_not_found) {
  hid_device_info* list = hid_enumerate(config_.vendor_id, config_.product_id);
  const hid_device_info* match = nullptr;
  for (const hid_device_info* d = list; d != nullptr; d = d->next) {
    if (d->path == nullptr) continue;
    if (config_.interface_number >= 0 && d->interface_number != config_.interface_number) continue;
    if (!config_.serial.empty() && toUtf8(d->serial_number) != config_.serial) continue;
    match = d;
    break;
  }
  if (match == nullptr) {
    hid_free_enumeration(list);
    if (!reported_not_found) {
      reported_not_found = true;
      impl_->path.clear();
      report(TransportEvent::kNotFound, "no matching HID device", 0);
    }
    return false;
  }
  HidDeviceInfo info = toInfo(*match);
  hid_free_enumeration(list);

  impl_->path = info.path;
  hid_device* dev = hid_open_path(info.path.c_str());
  if (dev == nullptr) {
    detail::AtomicTransportStats::bump(stats_.open_failures);
    std::string text = "hid_open_path failed: " + toUtf8(hid_error(nullptr));
    if (text != impl_->last_open_error) {  // report a streak of identical failures once
      impl_->last_open_error = text;
      report(TransportEvent::kOpenFailed, text, -1);
    }
    return false;
  }
  impl_->last_open_error.clear();
  impl_->device = dev;
  impl_->feature_path.clear();
  if (config_.feature_interface_number >= 0 && config_.feature_interface_number != info.interface_number) {
    for (const HidDeviceInfo& other : enumerateHid(config_.vendor_id, config_.product_id)) {
      if (other.interface_number == config_.feature_interface_number && other.serial == info.serial) {
        impl_->feature_path = other.path;
        break;
      }
    }
    if (impl_->feature_path.empty()) {
      detail::AtomicTransportStats::bump(stats_.write_errors);
      report(TransportEvent::kFeatureError, "feature interface not found; feature reports will fail", -1);
    }
  }
  {
    std::lock_guard lock(info_mutex_);
    current_ = std::move(info);
  }
  reported_not_found = false;
  connected_.store(true, std::memory_order_release);
  detail::AtomicTransportStats::bump(stats_.opens);
  report(TransportEvent::kOpened, "opened", 0);

  for (const auto& r : config_.open_feature_reports) {
    if (!sendOne(true, r.data(), r.size())) break;
  }
  for (const auto& r : config_.open_output_reports) {
    if (!sendOne(false, r.data(), r.size())) break;
  }
  return impl_->device != nullptr;
}

void HidTransport::closeDevice() {
  if (impl_->device != nullptr) {
    hid_close(impl_->device);
    impl_->device = nullptr;
  }
  connected_.store(false, std::memory_order_release);
  std::lock_guard lock(info_mutex_);
  current_ = HidDeviceInfo{};
}

bool HidTransport::sendOne(bool feature, const std::uint8_t* data, std::size_t size) {
  if (impl_->device == nullptr || size == 0) return false;
  const bool separate = feature && config_.feature_interface_number >= 0 &&
                        config_.feature_interface_number != current_.interface_number;
  hid_device* target = impl_->device;
  if (separate) {
    target = impl_->feature_path.empty() ? nullptr : hid_open_path(impl_->feature_path.c_str());
    if (target == nullptr) {
      detail::AtomicTransportStats::bump(stats_.write_errors);
      impl_->error_text = "cannot open the feature interface: " + toUtf8(hid_error(nullptr));
      report(TransportEvent::kFeatureError, impl_->error_text, -1);
      return false;
    }
  }
  const int res = feature ? hid_send_feature_report(target, data, size) : hid_write(target, data, size);
  if (res < 0) impl_->error_text = toUtf8(hid_error(target));
  if (separate) hid_close(target);
  if (res < 0) {
    detail::AtomicTransportStats::bump(stats_.write_errors);
    impl_->error_text = (feature ? "hid_send_feature_report failed: " : "hid_write failed: ") + impl_->error_text;
    report(feature ? TransportEvent::kFeatureError : TransportEvent::kWriteError, impl_->error_text, res);
    return false;
  }
  detail::AtomicTransportStats::bump(stats_.reports_sent);
  report(TransportEvent::kReportSent, feature ? "feature report" : "output report", res);
  return true;
}

void HidTransport::sendQueued() {
  while (impl_->device != nullptr) {
    Command c;
    {
      std::lock_guard lock(command_mutex_);
      if (command_count_ == 0) {
        commands_pending_.store(false, std::memory_order_release);
        return;
      }
      c = commands_[command_head_];
      command_head_ = (command_head_ + 1) % kCommandQueueCapacity;
      --command_count_;
    }
    sendOne(c.feature, c.bytes.data(), c.size);
  }
}

void HidTransport::run() {
  bool reported_not_found = false;
  while (!stop_flag_.load(std::memory_order_acquire)) {
    if (impl_->device == nullptr) {
      if (!tryOpen(reported_not_found)) {
        if (waitStop(config_.reconnect_poll_ms)) break;
        continue;
      }
    }
    if (commands_pending_.load(std::memory_order_acquire)) sendQueued();
    if (impl_->device == nullptr) continue;

    const int n = hid_read_timeout(impl_->device, buffer_.data(), buffer_.size(), config_.read_timeout_ms);
    if (n > 0) {
      const std::int64_t now = monotonicNowNs();
      detail::AtomicTransportStats::bump(stats_.reports);
      detail::AtomicTransportStats::bump(stats_.bytes, static_cast<std::uint64_t>(n));
      if (sink_) sink_(ReceivedReport{std::span<const std::uint8_t>(buffer_.data(), static_cast<std::size_t>(n)), now});
      continue;
    }
    if (n == 0) continue;  // timeout: nothing arrived

    // Read error: on hidraw this means the device went away (POLLHUP/ENODEV). Close, then look
    // for it again after one poll period (the node disappears a little after the read fails).
    detail::AtomicTransportStats::bump(stats_.read_errors);
    detail::AtomicTransportStats::bump(stats_.disconnects);
    std::string err = toUtf8(hid_error(impl_->device));
    if (err.empty() || err == "Success") err = "hang-up/error on the hidraw node";
    impl_->error_text = "read failed, device closed: " + err;
    closeDevice();
    report(TransportEvent::kDisconnected, impl_->error_text, n);
    if (waitStop(config_.reconnect_poll_ms)) break;
  }
  closeDevice();
  report(TransportEvent::kStopped, "driver thread stopped", 0);
}

}  // namespace tetrig::devices
