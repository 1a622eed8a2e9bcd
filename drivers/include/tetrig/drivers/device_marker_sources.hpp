// The device sources (device_sources.hpp) in the one shape every source has:
// tetrig::drivers::MarkerSource (marker_source.hpp). Each factory returns an adapter that holds
// the configuration and builds the device source itself in start(mailbox) (the device sources
// take their mailbox in the constructor); a later start() after stop() builds a fresh one.
//
//   adapter                     labels (waitForLabels)                     nominalRateHz()
//   makeHidMarkerStreamSource   the device's descriptor (docs/protocol.md  config.rate_hz (0: not set)
//   makeUsbMarkerStreamSource     section 2a), asked for on every open     config.rate_hz (0: not set)
//   makeHydraSource             fixed: id 0 "hydra0", id 1 "hydra1"        250 (documented nominal)
//
// waitForLabels: marker streams wait for the first accepted descriptor (false on timeout, and
// false at once before start()); the Hydra answers at once, started or not. finished() is always
// false (live devices never end). stats() maps DeviceSourceStats (frames published, frames lost,
// decode errors, rejected markers, connected; late_frames 0). lastError() is the last transport
// status event that was trouble (open failed, not found, disconnected, read / write / feature
// error, timeout) as "<event> <device>: <detail>", or why start() failed; "" when none.
//
// Threads: as MarkerSource (control thread; stats(), finished() from any thread). The frames
// are produced on the device source's driver thread. Allocates (construction, start, labels).
#pragma once

#include <tetrig/drivers/device_sources.hpp>
#include <tetrig/drivers/marker_source.hpp>

#include <memory>

namespace tetrig::devices {

std::unique_ptr<drivers::MarkerSource> makeHidMarkerStreamSource(HidMarkerStreamSourceConfig config);
std::unique_ptr<drivers::MarkerSource> makeUsbMarkerStreamSource(UsbMarkerStreamSourceConfig config);
std::unique_ptr<drivers::MarkerSource> makeHydraSource(HydraSourceConfig config);

}  // namespace tetrig::devices
