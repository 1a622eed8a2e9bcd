// Live device sources: a transport (HID or USB) + a protocol decoder + the runtime's latest-frame
// mailbox. Each source owns its transport and decoder; frames are decoded straight into the
// mailbox's producer slot on the transport's driver thread (no copy, no allocation, no lock on
// that path) and published; the solver thread takes them with FrameMailbox::tryTakeLatest().
//
//   HidMarkerStreamSource  tetrig marker stream over 64-byte HID reports (docs/protocol.md);
//                          sends START, GET_DESCRIPTOR (and SET_RATE) as output reports 0x02
//                          after every open.
//   HydraSource            Razer Hydra: 52-byte reports on interface 0, two oriented sensors
//                          (marker ids 0 and 1, labels "hydra0"/"hydra1", Marker::buttons = the
//                          raw button byte); motion mode switched on by the 91-byte feature
//                          report on interface 1 after every open.
//   UsbMarkerStreamSource  tetrig marker stream, one message per bulk IN transfer; START,
//                          GET_DESCRIPTOR (and SET_RATE) as vendor control requests after every open.
//
// Labels: a marker-stream source keeps the label table of the last descriptor the device sent
// (docs/protocol.md, section 2a). The driver thread copies it under a mutex when a descriptor
// arrives (rare); frames never take that lock. waitForLabels() hands the labels to the control
// thread. The table survives a reconnect until the device sends a new one (it does after every
// START / GET_DESCRIPTOR, which the source sends on every open).
//
// Threads: construct, start(), stop(), waitForLabels() from a control thread; stats() and
// labelGeneration() from any thread. The mailbox has exactly one producer (this source's driver
// thread) and one consumer (the caller's solver thread). The decoder's sequence state is reset
// after every (re)open, so a partial frame from before an unplug is never completed with bytes
// from after it.
//
// For the one-shape interface (tetrig::drivers::MarkerSource) see device_marker_sources.hpp.
#pragma once

#include <tetrig/drivers/hid_transport.hpp>
#include <tetrig/drivers/hydra.hpp>
#include <tetrig/drivers/marker_stream.hpp>
#include <tetrig/drivers/usb_transport.hpp>
#include <tetrig/frame_mailbox.hpp>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <string>
#include <vector>

namespace tetrig::devices {

// Counters of a source (any thread; relaxed snapshots).
struct DeviceSourceStats {
  std::uint64_t frames_published = 0;  // frames committed to the mailbox
  std::uint64_t decode_errors = 0;     // reports/transfers the decoder rejected (kNeedMore not counted)
  std::uint64_t frames_lost = 0;       // frames the device sent that never arrived (sequence gaps)
  std::uint64_t duplicates = 0;        // frames dropped as duplicates
  std::uint64_t rejected_markers = 0;  // markers invalidated for non-finite/absurd values
  int last_error = 0;                  // last decoder status < 0 (MarkerStreamStatus/HydraStatus value)
  std::uint64_t descriptors_accepted = 0;  // marker stream: descriptors accepted (0 for the Hydra)
  std::uint64_t descriptors_rejected = 0;  // marker stream: descriptors rejected (previous labels kept)
  bool connected = false;              // a device is open now (the transport's view)
  TransportStats transport;            // the transport's own counters
  FrameMailboxStats mailbox;           // published / taken / dropped (overwritten before taken)
};

namespace detail {
struct AtomicSourceStats {
  std::atomic<std::uint64_t> frames_published{0}, decode_errors{0}, frames_lost{0}, duplicates{0},
      rejected_markers{0}, descriptors_accepted{0}, descriptors_rejected{0};
  std::atomic<int> last_error{0};
  DeviceSourceStats snapshot() const noexcept;
};

// The label table handed from a driver thread to a control thread (internal).
class LabelStore {
 public:
  // Driver thread, when the decoder returned kDescriptor: copies `table` (about 8.7 KB, no
  // allocation) under the mutex and wakes waiters.
  void publish(const drivers::MarkerLabelTable& table) noexcept;
  // Control thread: waits up to `timeout` for a first table; fills `labels` indexed by id ("" for
  // unnamed ids below the largest named one). Allocates.
  bool wait(std::chrono::milliseconds timeout, std::vector<std::string>& labels);
  std::uint32_t generation() const noexcept { return generation_.load(std::memory_order_acquire); }

 private:
  mutable std::mutex mutex_;
  std::condition_variable changed_;
  drivers::MarkerLabelTable table_;  // guarded by mutex_
  std::atomic<std::uint32_t> generation_{0};
};
}  // namespace detail

// ---------------------------------------------------------------------------------------------

struct HidMarkerStreamSourceConfig {
  HidTransportConfig hid;  // vendor/product id etc.; report_size is forced to 64 and the START,
                           // GET_DESCRIPTOR (and SET_RATE) commands are appended to
                           // hid.open_output_reports
  drivers::MarkerRecordFormat record_format = drivers::MarkerRecordFormat::kPosition;  // asked in START
  std::uint16_t rate_hz = 0;  // > 0: SET_RATE sent after START
  drivers::MarkerStreamDecoderOptions decoder;
};

class HidMarkerStreamSource {
 public:
  // `mailbox` must outlive the source. Allocates (transport); opens nothing.
  HidMarkerStreamSource(HidMarkerStreamSourceConfig config, FrameMailbox& mailbox);
  ~HidMarkerStreamSource();
  HidMarkerStreamSource(const HidMarkerStreamSource&) = delete;
  HidMarkerStreamSource& operator=(const HidMarkerStreamSource&) = delete;

  bool start(StatusSink status = {});  // see HidTransport::start
  void stop();                         // joins the driver thread
  DeviceSourceStats stats() const noexcept;
  HidTransport& transport() noexcept { return transport_; }

  // Waits up to `timeout` until the device has sent a descriptor (returns at once if one was
  // accepted before); then fills `labels` indexed by marker id ("" for ids below the largest
  // named id that the descriptor does not name) and returns true. False on timeout. Control
  // thread; allocates.
  bool waitForLabels(std::chrono::milliseconds timeout, std::vector<std::string>& labels);
  // Generation of the labels held (MarkerLabelTable::generation; 0: none yet). Any thread.
  std::uint32_t labelGeneration() const noexcept { return labels_.generation(); }

 private:
  void onReport(const ReceivedReport& report) noexcept;
  FrameMailbox& mailbox_;
  HidTransport transport_;
  drivers::MarkerStreamDecoder decoder_;
  StatusSink user_status_;
  detail::AtomicSourceStats stats_;
  detail::LabelStore labels_;
};

// ---------------------------------------------------------------------------------------------

struct HydraSourceConfig {
  HidTransportConfig hid;  // defaults filled in by the constructor when left 0: VID 1532, PID 0300,
                           // interface 0, report_size 52, feature interface 1 + motion-mode report
};

class HydraSource {
 public:
  HydraSource(HydraSourceConfig config, FrameMailbox& mailbox);
  ~HydraSource();
  HydraSource(const HydraSource&) = delete;
  HydraSource& operator=(const HydraSource&) = delete;

  bool start(StatusSink status = {});
  void stop();
  DeviceSourceStats stats() const noexcept;
  HidTransport& transport() noexcept { return transport_; }

 private:
  void onReport(const ReceivedReport& report) noexcept;
  FrameMailbox& mailbox_;
  HidTransport transport_;
  drivers::HydraDecoder decoder_;
  StatusSink user_status_;
  detail::AtomicSourceStats stats_;
};

// ---------------------------------------------------------------------------------------------

struct UsbMarkerStreamSourceConfig {
  UsbTransportConfig usb;  // transfer_size is raised to kMarkerStreamMaxMessageSize; START,
                           // GET_DESCRIPTOR (and SET_RATE) control requests are appended to
                           // usb.open_control_requests
  drivers::MarkerRecordFormat record_format = drivers::MarkerRecordFormat::kPosition;
  std::uint16_t rate_hz = 0;
  drivers::MarkerStreamDecoderOptions decoder;
};

class UsbMarkerStreamSource {
 public:
  UsbMarkerStreamSource(UsbMarkerStreamSourceConfig config, FrameMailbox& mailbox);
  ~UsbMarkerStreamSource();
  UsbMarkerStreamSource(const UsbMarkerStreamSource&) = delete;
  UsbMarkerStreamSource& operator=(const UsbMarkerStreamSource&) = delete;

  bool start(StatusSink status = {});
  void stop();
  DeviceSourceStats stats() const noexcept;
  UsbTransport& transport() noexcept { return transport_; }

  // As HidMarkerStreamSource::waitForLabels / labelGeneration.
  bool waitForLabels(std::chrono::milliseconds timeout, std::vector<std::string>& labels);
  std::uint32_t labelGeneration() const noexcept { return labels_.generation(); }

 private:
  void onTransfer(const ReceivedReport& report) noexcept;
  FrameMailbox& mailbox_;
  UsbTransport transport_;
  drivers::MarkerStreamDecoder decoder_;
  StatusSink user_status_;
  detail::AtomicSourceStats stats_;
  detail::LabelStore labels_;
};

}  // namespace tetrig::devices
