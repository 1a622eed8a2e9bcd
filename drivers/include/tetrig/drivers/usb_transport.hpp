// USB transport over libusb-1.0: asynchronous bulk or interrupt IN transfers, several in flight,
// resubmitted from their completion callback, on one libusb event thread per transport.
//
// Lifecycle of a connection (all on the event thread):
//   find VID/PID -> open -> claim interface -> optional OUT "start" transfer -> submit N IN transfers
//   -> completion callback: deliver bytes to the sink, resubmit
//   -> device lost (LIBUSB_TRANSFER_NO_DEVICE, hotplug "left", repeated errors, resubmit failure):
//      cancel every transfer still in flight, keep handling events until all are reaped,
//      release + close, then wait for the device again
//   -> stop(): the same cancel-and-reap, then the thread exits; transfers are freed only after that.
// Arrival is detected by a libusb hotplug callback when libusb has hotplug support
// (LIBUSB_CAP_HAS_HOTPLUG), and by polling the device list every `reconnect_poll_ms` otherwise
// (and as a safety net: a missed event costs at most one poll period).
//
// Threads: start()/stop() from one control thread; sinks run on the event thread. libusb
// allocates and locks internally, so it is touched only by the event thread (and start/stop).
// Transfers and their buffers are allocated once in start(); nothing is allocated per transfer.
#pragma once

#include <tetrig/drivers/transport.hpp>

#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <thread>
#include <vector>

namespace tetrig::devices {

enum class UsbEndpointType : std::uint8_t { kBulk, kInterrupt };

// A control request sent after every open (for example the marker-stream START vendor request).
struct UsbControlRequest {
  std::uint8_t request_type = 0;  // bmRequestType; bit 7 must be 0 (host-to-device)
  std::uint8_t request = 0;       // bRequest
  std::uint16_t value = 0;        // wValue
  std::uint16_t index = 0;        // wIndex
  std::vector<std::uint8_t> data; // wLength = data.size()
};

struct UsbTransportConfig {
  std::uint16_t vendor_id = 0;
  std::uint16_t product_id = 0;
  int interface_number = 0;
  std::uint8_t endpoint_in = 0x81;        // IN endpoint address (bit 7 set)
  UsbEndpointType endpoint_type = UsbEndpointType::kBulk;
  std::size_t transfer_size = 512;        // bytes per IN transfer: at least one whole frame
  int transfers_in_flight = 4;            // IN transfers kept submitted (1..64)
  unsigned int transfer_timeout_ms = 1000;  // per IN transfer; 0 = none. Timeouts are counted and
                                            // the transfer resubmitted (no data is not an error).
  int reconnect_poll_ms = 100;            // device-list poll period while disconnected
  bool use_hotplug = true;                // use libusb hotplug when available
  int max_consecutive_errors = 8;         // failed transfers in a row that count as "device lost"
  // Sent in this order after every (re)open, before the IN transfers are submitted: the control
  // requests (synchronous, `out_timeout_ms` each), then `open_out_data` as one synchronous bulk
  // OUT transfer on `endpoint_out` (empty: none). A failure is reported and counted
  // (write_errors); streaming starts anyway unless the device is gone.
  std::vector<UsbControlRequest> open_control_requests;
  std::uint8_t endpoint_out = 0x01;
  std::vector<std::uint8_t> open_out_data;
  unsigned int out_timeout_ms = 500;
};

class UsbTransport {
 public:
  // Stores the configuration; touches no device. Allocates.
  explicit UsbTransport(UsbTransportConfig config);
  ~UsbTransport();  // stop()
  UsbTransport(const UsbTransport&) = delete;
  UsbTransport& operator=(const UsbTransport&) = delete;

  // Creates the libusb context, registers the hotplug callback if possible, allocates the
  // transfers and starts the event thread. Returns false if already running or libusb cannot be
  // initialised (reported through `status`). Allocates.
  bool start(ReportSink sink, StatusSink status = {});
  // Cancels all transfers, waits until every one is reaped, closes the device, joins the thread,
  // frees the transfers and the context. Idempotent. Returns within about a second even if the
  // device never completes a cancel (then it reports and leaks nothing: the handle is closed only
  // after libusb reports every transfer finished, or the context is torn down as a whole).
  void stop();
  bool running() const noexcept { return running_.load(std::memory_order_acquire); }
  bool connected() const noexcept { return connected_.load(std::memory_order_acquire); }
  // True if libusb reported hotplug support when start() ran.
  bool hotplugActive() const noexcept { return hotplug_active_.load(std::memory_order_acquire); }
  // IN transfers currently submitted (event thread's view; any thread).
  int transfersInFlight() const noexcept { return in_flight_.load(std::memory_order_acquire); }

  TransportStats stats() const noexcept { return stats_.snapshot(); }
  const UsbTransportConfig& config() const noexcept { return config_; }

  struct Impl;  // libusb state (keeps libusb.h out of this header); public for the C callbacks

 private:
  UsbTransportConfig config_;
  std::unique_ptr<Impl> impl_;
  std::thread thread_;
  std::atomic<bool> running_{false};
  std::atomic<bool> connected_{false};
  std::atomic<bool> hotplug_active_{false};
  std::atomic<int> in_flight_{0};
  detail::AtomicTransportStats stats_;
};

}  // namespace tetrig::devices
