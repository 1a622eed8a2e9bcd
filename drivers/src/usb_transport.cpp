// USB transport over libusb-1.0's asynchronous API: N IN transfers in flight, one event thread,
// hotplug (or polling) reconnect, cancel-and-reap before anything is closed or freed.
#include <tetrig/drivers/usb_transport.hpp>

#include <libusb.h>

#include <algorithm>
#include <cstdio>
#include <utility>

namespace tetrig::devices {

namespace {
constexpr int kEventSliceMs = 20;          // longest libusb_handle_events wait per loop turn
constexpr std::int64_t kStopReapBoundNs = 1'000'000'000;  // stop(): give up waiting for reaps
}  // namespace

struct UsbTransport::Impl {
  struct Slot {
    Impl* impl = nullptr;
    libusb_transfer* transfer = nullptr;
    bool submitted = false;
  };

  UsbTransport& owner;
  const UsbTransportConfig& cfg;
  ReportSink sink;
  StatusSink status;
  libusb_context* ctx = nullptr;
  libusb_device_handle* handle = nullptr;
  bool interface_claimed = false;
  libusb_hotplug_callback_handle hotplug_handle{};
  bool hotplug_registered = false;
  std::vector<Slot> slots;
  std::vector<std::uint8_t> buffers;  // slots.size() * cfg.transfer_size
  int in_flight = 0;
  int consecutive_errors = 0;
  bool lost = false;             // current device must be torn down
  bool cancel_issued = false;    // cancel sent to all in-flight transfers of this teardown
  bool reported_not_found = false;
  bool idle_reported = false;    // a timeout was reported since the last completed transfer
  std::atomic<bool> stop_requested{false};
  bool arrival = false;          // set by the hotplug callback (event thread)
  std::int64_t next_poll_ns = 0;
  std::string device_name;
  std::string scratch;
  std::string last_open_error;

  Impl(UsbTransport& o, const UsbTransportConfig& c) : owner(o), cfg(c) {}

  void report(TransportEvent event, std::string_view detail, int code) {
    if (!status) return;
    TransportStatus s;
    s.event = event;
    s.device = device_name;
    s.detail = detail;
    s.code = code;
    status(s);
  }

  void setInFlight(int delta) {
    in_flight += delta;
    owner.in_flight_.store(in_flight, std::memory_order_release);
  }

  bool submit(Slot& slot) {
    const int r = libusb_submit_transfer(slot.transfer);
    if (r == 0) {
      slot.submitted = true;
      setInFlight(+1);
      return true;
    }
    detail::AtomicTransportStats::bump(owner.stats_.read_errors);
    scratch = std::string("libusb_submit_transfer failed: ") + libusb_error_name(r);
    if (r == LIBUSB_ERROR_NO_DEVICE) {
      markLost(scratch, r);
    } else {
      report(TransportEvent::kReadError, scratch, r);
      if (++consecutive_errors >= cfg.max_consecutive_errors) markLost("too many transfer errors", r);
    }
    return false;
  }

  void markLost(std::string_view why, int code) {
    if (lost || handle == nullptr) return;
    lost = true;
    cancel_issued = false;
    detail::AtomicTransportStats::bump(owner.stats_.disconnects);
    scratch = std::string(why);
    report(TransportEvent::kDisconnected, scratch, code);
  }

  static void LIBUSB_CALL onTransfer(libusb_transfer* t) {
    auto* slot = static_cast<Slot*>(t->user_data);
    slot->impl->handleTransfer(*slot);
  }

  void handleTransfer(Slot& slot) {
    slot.submitted = false;
    setInFlight(-1);
    libusb_transfer* t = slot.transfer;
    bool resubmit = false;
    switch (t->status) {
      case LIBUSB_TRANSFER_COMPLETED:
        consecutive_errors = 0;
        idle_reported = false;
        deliver(t);
        resubmit = true;
        break;
      case LIBUSB_TRANSFER_TIMED_OUT:
        detail::AtomicTransportStats::bump(owner.stats_.timeouts);
        deliver(t);  // a timed-out transfer may still carry data
        if (!idle_reported) {  // once per idle period, not once per transfer
          idle_reported = true;
          report(TransportEvent::kTimeout, "IN transfers time out (device idle?), resubmitting",
                 LIBUSB_TRANSFER_TIMED_OUT);
        }
        resubmit = true;
        break;
      case LIBUSB_TRANSFER_CANCELLED:
        break;  // stop or teardown
      case LIBUSB_TRANSFER_NO_DEVICE:
        detail::AtomicTransportStats::bump(owner.stats_.read_errors);
        markLost("IN transfer: no device (unplugged)", LIBUSB_TRANSFER_NO_DEVICE);
        break;
      case LIBUSB_TRANSFER_STALL:
      case LIBUSB_TRANSFER_OVERFLOW:
      case LIBUSB_TRANSFER_ERROR:
      default:
        detail::AtomicTransportStats::bump(owner.stats_.read_errors);
        report(TransportEvent::kReadError,
               t->status == LIBUSB_TRANSFER_STALL      ? "IN transfer stalled"
               : t->status == LIBUSB_TRANSFER_OVERFLOW ? "IN transfer overflow"
                                                       : "IN transfer error",
               static_cast<int>(t->status));
        if (++consecutive_errors >= cfg.max_consecutive_errors) {
          markLost("too many consecutive transfer errors", static_cast<int>(t->status));
        } else {
          resubmit = true;
        }
        break;
    }
    if (resubmit && !lost && !stop_requested.load(std::memory_order_acquire) && handle != nullptr) {
      submit(slot);
    }
  }

  void deliver(libusb_transfer* t) {
    if (t->actual_length <= 0) return;
    const std::int64_t now = monotonicNowNs();
    detail::AtomicTransportStats::bump(owner.stats_.reports);
    detail::AtomicTransportStats::bump(owner.stats_.bytes, static_cast<std::uint64_t>(t->actual_length));
    if (sink) sink(ReceivedReport{std::span<const std::uint8_t>(t->buffer, static_cast<std::size_t>(t->actual_length)), now});
  }

  static int LIBUSB_CALL onHotplug(libusb_context*, libusb_device* device, libusb_hotplug_event event,
                                   void* user_data) {
    auto* self = static_cast<Impl*>(user_data);
    if (event == LIBUSB_HOTPLUG_EVENT_DEVICE_ARRIVED) {
      self->arrival = true;
      detail::AtomicTransportStats::bump(self->owner.stats_.hotplug_arrivals);
      self->report(TransportEvent::kHotplugArrived, "matching device arrived", 0);
    } else if (event == LIBUSB_HOTPLUG_EVENT_DEVICE_LEFT) {
      if (self->handle != nullptr && libusb_get_device(self->handle) == device) {
        self->markLost("hotplug: device left", LIBUSB_ERROR_NO_DEVICE);
      }
    }
    return 0;  // stay registered
  }

  // Reports a streak of identical open failures once (the poll retries every period).
  void reportOpenFailure(std::string text, int code) {
    if (text == last_open_error) return;
    last_open_error = std::move(text);
    report(TransportEvent::kOpenFailed, last_open_error, code);
  }

  void cancelAll() {
    for (Slot& s : slots) {
      if (s.submitted) libusb_cancel_transfer(s.transfer);  // NOT_FOUND if already completing: fine
    }
    cancel_issued = true;
  }

  void closeHandle() {
    if (handle == nullptr) return;
    if (interface_claimed) libusb_release_interface(handle, cfg.interface_number);
    interface_claimed = false;
    libusb_close(handle);
    handle = nullptr;
    owner.connected_.store(false, std::memory_order_release);
  }

  bool tryOpen() {
    libusb_device** list = nullptr;
    const ssize_t n = libusb_get_device_list(ctx, &list);
    libusb_device_handle* h = nullptr;
    bool found = false;
    for (ssize_t i = 0; i < n && h == nullptr; ++i) {
      libusb_device_descriptor desc{};
      if (libusb_get_device_descriptor(list[i], &desc) != 0) continue;
      if (desc.idVendor != cfg.vendor_id || desc.idProduct != cfg.product_id) continue;
      found = true;
      char name[64];
      std::snprintf(name, sizeof(name), "usb %03u-%03u %04x:%04x", libusb_get_bus_number(list[i]),
                    libusb_get_device_address(list[i]), cfg.vendor_id, cfg.product_id);
      device_name = name;
      const int r = libusb_open(list[i], &h);
      if (r != 0) {
        h = nullptr;
        detail::AtomicTransportStats::bump(owner.stats_.open_failures);
        reportOpenFailure(std::string("libusb_open failed: ") + libusb_error_name(r), r);
      }
    }
    if (list != nullptr) libusb_free_device_list(list, 1);
    if (!found) {
      if (!reported_not_found) {
        reported_not_found = true;
        device_name.clear();
        report(TransportEvent::kNotFound, "no matching USB device", 0);
      }
      return false;
    }
    if (h == nullptr) return false;
    reported_not_found = false;

    libusb_set_auto_detach_kernel_driver(h, 1);  // unsupported on some platforms: ignored
    const int claim = libusb_claim_interface(h, cfg.interface_number);
    if (claim != 0) {
      detail::AtomicTransportStats::bump(owner.stats_.open_failures);
      reportOpenFailure(std::string("libusb_claim_interface failed: ") + libusb_error_name(claim), claim);
      libusb_close(h);
      return false;
    }
    last_open_error.clear();
    handle = h;
    interface_claimed = true;
    lost = false;
    cancel_issued = false;
    consecutive_errors = 0;
    owner.connected_.store(true, std::memory_order_release);
    detail::AtomicTransportStats::bump(owner.stats_.opens);
    report(TransportEvent::kOpened, "opened and claimed", 0);

    // One write of the open sequence: counted and reported; false when the device is gone.
    auto openWrite = [&](const char* what, int r, bool complete, int bytes) {
      if (r >= 0 && complete) {
        detail::AtomicTransportStats::bump(owner.stats_.reports_sent);
        report(TransportEvent::kReportSent, what, bytes);
        return true;
      }
      detail::AtomicTransportStats::bump(owner.stats_.write_errors);
      scratch = std::string(what) + " failed: " + (r < 0 ? libusb_error_name(r) : "short transfer");
      report(TransportEvent::kWriteError, scratch, r);
      if (r != LIBUSB_ERROR_NO_DEVICE) return true;
      markLost(scratch, r);
      return false;
    };
    for (const UsbControlRequest& c : cfg.open_control_requests) {
      std::vector<std::uint8_t> data = c.data;  // libusb wants a mutable buffer
      const int r = libusb_control_transfer(handle, static_cast<std::uint8_t>(c.request_type & 0x7f), c.request,
                                            c.value, c.index, data.empty() ? nullptr : data.data(),
                                            static_cast<std::uint16_t>(data.size()), cfg.out_timeout_ms);
      if (!openWrite("control request", r, r == static_cast<int>(data.size()), r)) return false;
    }
    if (!cfg.open_out_data.empty()) {
      std::vector<std::uint8_t> out = cfg.open_out_data;  // libusb wants a mutable buffer
      int transferred = 0;
      const int r = libusb_bulk_transfer(handle, cfg.endpoint_out, out.data(), static_cast<int>(out.size()),
                                         &transferred, cfg.out_timeout_ms);
      if (!openWrite("start OUT transfer", r, r == 0 && transferred == static_cast<int>(out.size()), transferred)) {
        return false;
      }
    }
    for (Slot& s : slots) {
      if (lost) break;
      s.transfer->dev_handle = handle;
      submit(s);
    }
    return true;
  }

  // One event-thread loop; returns when stopped and every transfer is reaped (or the bound hit).
  void run() {
    std::int64_t stop_deadline = 0;
    next_poll_ns = 0;
    while (true) {
      const bool stopping = stop_requested.load(std::memory_order_acquire);
      const std::int64_t now = monotonicNowNs();
      if (stopping) {
        if (stop_deadline == 0) stop_deadline = now + kStopReapBoundNs;
        if (!cancel_issued) cancelAll();
        if (in_flight == 0) break;
        if (now > stop_deadline) {
          report(TransportEvent::kReadError, "stop: transfers not reaped within 1 s; leaving them allocated",
                 in_flight);
          return;  // the caller keeps the transfers (never frees an in-flight one)
        }
      } else if (lost && handle != nullptr) {
        if (!cancel_issued) cancelAll();
        if (in_flight == 0) {
          closeHandle();
          lost = false;
          next_poll_ns = now + static_cast<std::int64_t>(cfg.reconnect_poll_ms) * 1'000'000;
        }
      } else if (handle == nullptr && (arrival || now >= next_poll_ns)) {
        arrival = false;
        if (!tryOpen()) next_poll_ns = now + static_cast<std::int64_t>(cfg.reconnect_poll_ms) * 1'000'000;
      }
      timeval tv{0, kEventSliceMs * 1000};
      const int r = libusb_handle_events_timeout_completed(ctx, &tv, nullptr);
      if (r != 0 && r != LIBUSB_ERROR_INTERRUPTED && r != LIBUSB_ERROR_TIMEOUT) {
        scratch = std::string("libusb_handle_events failed: ") + libusb_error_name(r);
        report(TransportEvent::kReadError, scratch, r);
      }
    }
    closeHandle();
  }
};

UsbTransport::UsbTransport(UsbTransportConfig config) : config_(std::move(config)) {
  config_.transfers_in_flight = std::clamp(config_.transfers_in_flight, 1, 64);
  config_.transfer_size = std::max<std::size_t>(config_.transfer_size, 1);
  config_.reconnect_poll_ms = std::max(config_.reconnect_poll_ms, 1);
  config_.max_consecutive_errors = std::max(config_.max_consecutive_errors, 1);
  config_.endpoint_in |= 0x80;
  config_.endpoint_out &= 0x7f;
}

UsbTransport::~UsbTransport() { stop(); }

bool UsbTransport::start(ReportSink sink, StatusSink status) {
  if (running_.load(std::memory_order_acquire) || thread_.joinable()) return false;
  impl_ = std::make_unique<Impl>(*this, config_);
  Impl& im = *impl_;
  im.sink = std::move(sink);
  im.status = std::move(status);

  const int r = libusb_init(&im.ctx);
  if (r != 0) {
    im.scratch = std::string("libusb_init failed: ") + libusb_error_name(r);
    im.report(TransportEvent::kOpenFailed, im.scratch, r);
    impl_.reset();
    return false;
  }

  const auto n = static_cast<std::size_t>(config_.transfers_in_flight);
  im.buffers.assign(n * config_.transfer_size, 0);
  im.slots.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    Impl::Slot& s = im.slots[i];
    s.impl = &im;
    s.transfer = libusb_alloc_transfer(0);
    if (s.transfer == nullptr) {
      im.report(TransportEvent::kOpenFailed, "libusb_alloc_transfer failed", LIBUSB_ERROR_NO_MEM);
      for (auto& t : im.slots) {
        if (t.transfer != nullptr) libusb_free_transfer(t.transfer);
      }
      libusb_exit(im.ctx);
      impl_.reset();
      return false;
    }
  }

  hotplug_active_.store(false, std::memory_order_release);
  if (config_.use_hotplug && libusb_has_capability(LIBUSB_CAP_HAS_HOTPLUG) != 0) {
    const int h = libusb_hotplug_register_callback(
        im.ctx,
        static_cast<libusb_hotplug_event>(LIBUSB_HOTPLUG_EVENT_DEVICE_ARRIVED | LIBUSB_HOTPLUG_EVENT_DEVICE_LEFT),
        static_cast<libusb_hotplug_flag>(0), config_.vendor_id, config_.product_id, LIBUSB_HOTPLUG_MATCH_ANY,
        &Impl::onHotplug, &im, &im.hotplug_handle);
    im.hotplug_registered = (h == 0);
    hotplug_active_.store(im.hotplug_registered, std::memory_order_release);
  }

  // The transfers' fields that never change; the handle is filled in per open.
  for (std::size_t i = 0; i < n; ++i) {
    libusb_transfer* t = im.slots[i].transfer;
    std::uint8_t* buf = im.buffers.data() + i * config_.transfer_size;
    const int len = static_cast<int>(config_.transfer_size);
    if (config_.endpoint_type == UsbEndpointType::kInterrupt) {
      libusb_fill_interrupt_transfer(t, nullptr, config_.endpoint_in, buf, len, &Impl::onTransfer, &im.slots[i],
                                     config_.transfer_timeout_ms);
    } else {
      libusb_fill_bulk_transfer(t, nullptr, config_.endpoint_in, buf, len, &Impl::onTransfer, &im.slots[i],
                                config_.transfer_timeout_ms);
    }
  }

  running_.store(true, std::memory_order_release);
  thread_ = std::thread([this] {
    Impl& self = *impl_;
    self.run();
    self.report(TransportEvent::kStopped, "event thread stopped", 0);
  });
  return true;
}

void UsbTransport::stop() {
  if (!impl_) return;
  Impl& im = *impl_;
  im.stop_requested.store(true, std::memory_order_release);
  if (im.ctx != nullptr) libusb_interrupt_event_handler(im.ctx);
  if (thread_.joinable()) thread_.join();
  if (im.hotplug_registered) libusb_hotplug_deregister_callback(im.ctx, im.hotplug_handle);
  im.hotplug_registered = false;
  const bool all_reaped = (im.in_flight == 0);
  if (all_reaped) {
    im.closeHandle();
    for (auto& s : im.slots) libusb_free_transfer(s.transfer);
    im.slots.clear();
    libusb_exit(im.ctx);
    impl_.reset();
  } else {
    // Transfers still owned by libusb: freeing them (or the context) would be a use-after-free.
    // Keep impl_ (buffers, transfers, context) alive for the rest of the process.
    (void)impl_.release();
  }
  running_.store(false, std::memory_order_release);
  connected_.store(false, std::memory_order_release);
}

}  // namespace tetrig::devices
