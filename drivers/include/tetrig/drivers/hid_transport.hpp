// HID transport over hidapi (Linux hidraw backend): finds a device by VID/PID, reads input reports
// on its own driver thread, sends output and feature reports, and survives unplug/replug.
//
// Threads: start()/stop()/send*() from any one control thread; the report sink and the status sink
// run on the driver thread. hidapi allocates and locks internally, so it is used only there (and in
// enumerateHid()). The read loop itself allocates nothing per report: the report buffer is sized
// at construction.
//
// Hotplug: hidraw has no event source here, so a disconnected transport polls hid_enumerate every
// `reconnect_poll_ms` and re-opens the first match; the "on open" reports are sent again after
// every (re)open, so a device that needs a start command or a mode switch resumes streaming on its
// own.
//
// Strings (manufacturer, product, serial) are taken from enumeration, not from the opened handle:
// they are the same data on Linux and the handle queries do not work under umockdev.
#pragma once

#include <tetrig/drivers/transport.hpp>

#include <array>
#include <condition_variable>
#include <cstdint>
#include <memory>
#include <mutex>
#include <span>
#include <string>
#include <thread>
#include <vector>

namespace tetrig::devices {

struct HidDeviceInfo {
  std::string path;          // hidraw node, e.g. /dev/hidraw0 (what hid_open_path takes)
  std::uint16_t vendor_id = 0;
  std::uint16_t product_id = 0;
  std::uint16_t release = 0;  // bcdDevice
  int interface_number = -1;  // USB interface, -1 if unknown
  std::uint16_t usage_page = 0;
  std::uint16_t usage = 0;
  std::string manufacturer;  // UTF-8, from enumeration (empty if the device has none)
  std::string product;
  std::string serial;
};

// All HID devices matching vendor_id/product_id (0 = any). Any thread; allocates; never throws
// for "no device" (returns empty).
std::vector<HidDeviceInfo> enumerateHid(std::uint16_t vendor_id, std::uint16_t product_id);

struct HidTransportConfig {
  std::uint16_t vendor_id = 0;
  std::uint16_t product_id = 0;
  int interface_number = -1;        // open only this USB interface (-1: first match)
  std::string serial;               // open only this serial (empty: any)
  std::size_t report_size = 64;     // bytes per read: exactly one input report (incl. report id
                                    // byte when the device uses numbered reports)
  int read_timeout_ms = 50;         // hid_read_timeout; bounds how fast stop() and sends react
  int reconnect_poll_ms = 100;      // enumeration poll period while disconnected
  // Sent after every successful open, in this order: feature reports (hid_send_feature_report,
  // first byte = report id or 0), then output reports (hid_write, first byte = report id or 0).
  std::vector<std::vector<std::uint8_t>> open_feature_reports;
  std::vector<std::vector<std::uint8_t>> open_output_reports;
  // Devices whose control interface differs from the one that streams (the Razer Hydra reads on
  // interface 0 and takes its mode switch on interface 1): when >= 0 and different from the open
  // interface, every feature report (on-open and sendFeatureReport) goes to this interface of the
  // same device (same VID/PID and serial), opened just for the send. -1: the open device.
  int feature_interface_number = -1;
};

class HidTransport {
 public:
  static constexpr std::size_t kMaxCommandBytes = 256;  // largest report send*() accepts
  static constexpr std::size_t kCommandQueueCapacity = 8;

  // Stores the configuration and sizes the read buffer; opens nothing. Allocates.
  explicit HidTransport(HidTransportConfig config);
  ~HidTransport();  // stop()
  HidTransport(const HidTransport&) = delete;
  HidTransport& operator=(const HidTransport&) = delete;

  // Starts the driver thread, which opens the device (or waits for it) and reads until stop().
  // Returns false if already running. `status` may be empty. Allocates (thread, sinks).
  bool start(ReportSink sink, StatusSink status = {});
  // Stops and joins the driver thread and closes the device. Returns within about
  // read_timeout_ms (plus one hidapi call in progress). Idempotent. The driver thread reports
  // kStopped as its last status.
  void stop();
  bool running() const noexcept { return running_.load(std::memory_order_acquire); }
  // True while a device is open (driver thread's view; any thread).
  bool connected() const noexcept { return connected_.load(std::memory_order_acquire); }

  // Queue a report for the driver thread to send before its next read (first byte = report id or
  // 0). Any thread; no allocation. Returns false (and counts commands_dropped) if the transport is
  // not running, the report is empty or longer than kMaxCommandBytes, or the queue is full. The
  // outcome is reported through the status sink (kReportSent / kWriteError / kFeatureError) and the
  // counters. A report queued while disconnected is sent after the next open.
  bool sendOutputReport(std::span<const std::uint8_t> report);
  bool sendFeatureReport(std::span<const std::uint8_t> report);

  TransportStats stats() const noexcept { return stats_.snapshot(); }
  // Description of the open device (empty path when none). Any thread; allocates.
  HidDeviceInfo currentDevice() const;
  const HidTransportConfig& config() const noexcept { return config_; }

 private:
  struct Command {
    bool feature = false;
    std::uint16_t size = 0;
    std::array<std::uint8_t, kMaxCommandBytes> bytes{};
  };
  struct Impl;  // hidapi handle lives here (keeps hidapi.h out of this header)

  bool enqueue(bool feature, std::span<const std::uint8_t> report);
  void run();
  bool tryOpen(bool& reported_not_found);
  void closeDevice();
  void sendQueued();
  bool sendOne(bool feature, const std::uint8_t* data, std::size_t size);
  void report(TransportEvent event, std::string_view detail, int code);
  bool waitStop(int milliseconds);  // true if stop was requested

  HidTransportConfig config_;
  ReportSink sink_;
  StatusSink status_;
  std::unique_ptr<Impl> impl_;
  std::vector<std::uint8_t> buffer_;
  std::thread thread_;
  std::atomic<bool> running_{false};
  std::atomic<bool> connected_{false};
  bool stop_requested_ = false;  // guarded by wake_mutex_ (for the reconnect wait)
  std::atomic<bool> stop_flag_{false};  // same, lock-free for the read loop
  std::mutex wake_mutex_;
  std::condition_variable wake_;
  std::mutex command_mutex_;
  std::array<Command, kCommandQueueCapacity> commands_{};
  std::size_t command_head_ = 0, command_count_ = 0;  // guarded by command_mutex_
  std::atomic<bool> commands_pending_{false};
  mutable std::mutex info_mutex_;
  HidDeviceInfo current_;  // guarded by info_mutex_
  detail::AtomicTransportStats stats_;
};

}  // namespace tetrig::devices
