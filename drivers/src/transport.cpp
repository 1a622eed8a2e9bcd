// Shared helpers of the device transports: host clock, event names, counter snapshots.
#include <tetrig/drivers/transport.hpp>

#include <tetrig/clock.hpp>

namespace tetrig::devices {

std::int64_t monotonicNowNs() noexcept { return tetrig::monotonicNowNs(); }

std::string_view transportEventName(TransportEvent event) noexcept {
  switch (event) {
    case TransportEvent::kOpened: return "opened";
    case TransportEvent::kOpenFailed: return "open failed";
    case TransportEvent::kNotFound: return "not found";
    case TransportEvent::kDisconnected: return "disconnected";
    case TransportEvent::kReadError: return "read error";
    case TransportEvent::kTimeout: return "timeout";
    case TransportEvent::kWriteError: return "write error";
    case TransportEvent::kFeatureError: return "feature report error";
    case TransportEvent::kReportSent: return "report sent";
    case TransportEvent::kHotplugArrived: return "hotplug arrived";
    case TransportEvent::kStopped: return "stopped";
  }
  return "unknown";
}

namespace detail {
TransportStats AtomicTransportStats::snapshot() const noexcept {
  constexpr auto kRelaxed = std::memory_order_relaxed;
  TransportStats s;
  s.reports = reports.load(kRelaxed);
  s.bytes = bytes.load(kRelaxed);
  s.opens = opens.load(kRelaxed);
  s.open_failures = open_failures.load(kRelaxed);
  s.disconnects = disconnects.load(kRelaxed);
  s.read_errors = read_errors.load(kRelaxed);
  s.timeouts = timeouts.load(kRelaxed);
  s.write_errors = write_errors.load(kRelaxed);
  s.reports_sent = reports_sent.load(kRelaxed);
  s.hotplug_arrivals = hotplug_arrivals.load(kRelaxed);
  s.commands_dropped = commands_dropped.load(kRelaxed);
  return s;
}
}  // namespace detail

}  // namespace tetrig::devices
