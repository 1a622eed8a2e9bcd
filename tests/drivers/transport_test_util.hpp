// Shared by the HID and USB transport tests: polling wait and a recorder of what a transport
// hands out (its sink and status callbacks run on the driver thread, hence the mutex).
#pragma once

#include "tetrig/drivers/transport.hpp"

#include <chrono>
#include <cstdint>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace tetrig::testing {

// Polls `pred` every millisecond until it holds or `timeout` passes; returns its last value.
template <class Pred>
bool waitFor(Pred pred, std::chrono::milliseconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (!pred()) {
    if (std::chrono::steady_clock::now() > deadline) return pred();
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  return true;
}

struct TransportRecorder {
  std::mutex mutex;
  std::vector<std::vector<std::uint8_t>> reports;  // bytes of each report / bulk transfer
  std::vector<std::int64_t> stamps;                // their receive times
  std::vector<devices::TransportEvent> events;
  std::vector<std::string> details;                // "event device: detail", for failure messages

  devices::ReportSink sink() {
    return [this](const devices::ReceivedReport& r) {
      std::lock_guard lock(mutex);
      reports.emplace_back(r.bytes.begin(), r.bytes.end());
      stamps.push_back(r.receive_ns);
    };
  }
  devices::StatusSink status() {
    return [this](const devices::TransportStatus& s) {
      std::lock_guard lock(mutex);
      events.push_back(s.event);
      details.emplace_back(std::string(devices::transportEventName(s.event)) + " " + std::string(s.device) + ": " +
                           std::string(s.detail));
    };
  }
  std::size_t reportCount() {
    std::lock_guard lock(mutex);
    return reports.size();
  }
  int count(devices::TransportEvent e) {
    std::lock_guard lock(mutex);
    int n = 0;
    for (auto x : events) n += (x == e);
    return n;
  }
  std::string log() {
    std::lock_guard lock(mutex);
    std::string out;
    for (const auto& d : details) out += "\n  " + d;
    return out;
  }
};

}  // namespace tetrig::testing
