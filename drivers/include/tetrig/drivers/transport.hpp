// Common vocabulary of the device transports (HID over hidapi, USB over libusb): what a transport
// hands to its caller (raw reports with a receive timestamp), how it reports trouble (status events
// and counters), and the host clock it stamps with.
//
// A transport moves bytes only. Decoding (tetrig marker stream, Razer Hydra) happens in the caller's
// report sink, on the transport's driver thread; see device_sources.hpp for the ready-made pairings.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <span>
#include <string_view>

namespace tetrig::devices {

// Host CLOCK_MONOTONIC in nanoseconds (the clock MarkerFrame::receive_timestamp_ns uses): the
// runtime's tetrig::monotonicNowNs() (tetrig/clock.hpp), named here for the transports' callers.
// Any thread; no allocation.
std::int64_t monotonicNowNs() noexcept;

// One input report (HID) or one completed IN transfer (USB) as received.
// `bytes` points into the transport's own preallocated buffer and is valid only during the sink call.
struct ReceivedReport {
  std::span<const std::uint8_t> bytes;
  std::int64_t receive_ns = 0;  // monotonicNowNs() right after the read/transfer completed
};

// Called on the transport's driver thread for every report. Must not block for long (the next
// read waits for it) and must not call start()/stop() of its own transport. The transport never
// allocates around this call; what the sink does is up to the sink (decoders: no allocation).
using ReportSink = std::function<void(const ReceivedReport&)>;

enum class TransportEvent : std::uint8_t {
  kOpened,            // device opened (first time or after a replug)
  kOpenFailed,        // a matching device was found but could not be opened/claimed (a streak of
                      // identical failures is reported once; every one is counted)
  kNotFound,          // (reported once per disconnected period) no matching device present
  kDisconnected,      // device lost: read error, POLLHUP, LIBUSB_TRANSFER_NO_DEVICE, hotplug "left"
  kReadError,         // a read/transfer failed without (yet) meaning the device is gone
  kTimeout,           // USB IN transfers time out (reported once per idle period; every one is
                      // counted in TransportStats::timeouts). HID read timeouts are not reported.
  kWriteError,        // an output report / OUT transfer failed
  kFeatureError,      // a feature report failed
  kReportSent,        // an output or feature report was sent (detail says which)
  kHotplugArrived,    // libusb hotplug: a matching device arrived
  kStopped,           // the driver thread finished (all transfers reaped, device closed)
};

// Name of an event, for logs ("opened", "disconnected", ...). Any thread; no allocation.
std::string_view transportEventName(TransportEvent event) noexcept;

// What happened, to which device. The views are valid only during the status callback.
struct TransportStatus {
  TransportEvent event = TransportEvent::kOpened;
  std::string_view device;  // hidraw path or "bus-address vid:pid" (may be empty when none is open)
  std::string_view detail;  // library error text or a short description
  int code = 0;             // library error code (negative hidapi/libusb value, errno, or transfer status)
};

// Called on the driver thread (kStopped is its last call). May allocate.
using StatusSink = std::function<void(const TransportStatus&)>;

// Monotonic counters, readable from any thread while the transport runs.
struct TransportStats {
  std::uint64_t reports = 0;          // reports/transfers delivered to the sink (non-empty)
  std::uint64_t bytes = 0;            // bytes delivered to the sink
  std::uint64_t opens = 0;            // successful opens (first + reconnects)
  std::uint64_t open_failures = 0;    // failed open/claim attempts of a present device
  std::uint64_t disconnects = 0;      // device-lost events
  std::uint64_t read_errors = 0;      // failed reads/transfers (including those that meant unplug)
  std::uint64_t timeouts = 0;         // USB transfer timeouts (HID read timeouts are not counted)
  std::uint64_t write_errors = 0;     // failed output/feature reports or OUT transfers
  std::uint64_t reports_sent = 0;     // output/feature reports or OUT transfers that succeeded
  std::uint64_t hotplug_arrivals = 0; // libusb hotplug arrivals seen (USB only)
  std::uint64_t commands_dropped = 0; // send requests refused (queue full or transport stopped)
};

namespace detail {
// Relaxed atomic twin of TransportStats (internal; written by the driver thread only).
struct AtomicTransportStats {
  std::atomic<std::uint64_t> reports{0}, bytes{0}, opens{0}, open_failures{0}, disconnects{0},
      read_errors{0}, timeouts{0}, write_errors{0}, reports_sent{0}, hotplug_arrivals{0},
      commands_dropped{0};
  static void bump(std::atomic<std::uint64_t>& counter, std::uint64_t by = 1) noexcept {
    counter.fetch_add(by, std::memory_order_relaxed);
  }
  TransportStats snapshot() const noexcept;
};
}  // namespace detail

}  // namespace tetrig::devices
