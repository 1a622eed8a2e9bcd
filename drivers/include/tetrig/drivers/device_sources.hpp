// Live device sources: a transport (HID or USB) + a protocol decoder + the runtime's latest-frame
// mailbox. Each source owns its transport and decoder; frames are decoded straight into the
// mailbox's producer slot on the transport's driver thread (no copy, no allocation, no lock on
// that path) and published; the solver thread takes them with FrameMailbox::tryTakeLatest().
//
//   HidMarkerStreamSource  tetrig marker stream over 64-byte HID reports (docs/protocol.md);
//                          sends START (and SET_RATE) as output report 0x02 after every open.
//   HydraSource            Razer Hydra: 52-byte reports on interface 0, two oriented sensors
//                          (marker ids 0 and 1); motion mode switched on by the 91-byte feature
//                          report on interface 1 after every open.
//   UsbMarkerStreamSource  tetrig marker stream, one frame per bulk IN transfer; START (and
//                          SET_RATE) as vendor control requests after every open.
//
// Threads: construct, start(), stop() and stats() from a control thread; the mailbox has exactly
// one producer (this source's driver thread) and one consumer (the caller's solver thread).
// The decoder is reset after every (re)open, so a partial frame from before an unplug is never
// completed with bytes from after it.
#pragma once

#include <tetrig/drivers/hid_transport.hpp>
#include <tetrig/drivers/hydra.hpp>
#include <tetrig/drivers/marker_stream.hpp>
#include <tetrig/drivers/usb_transport.hpp>
#include <tetrig/frame_mailbox.hpp>

#include <atomic>
#include <cstdint>

namespace tetrig::devices {

// Counters of a source (any thread; relaxed snapshots).
struct DeviceSourceStats {
  std::uint64_t frames_published = 0;  // frames committed to the mailbox
  std::uint64_t decode_errors = 0;     // reports/transfers the decoder rejected (kNeedMore not counted)
  std::uint64_t frames_lost = 0;       // frames the device sent that never arrived (sequence gaps)
  std::uint64_t duplicates = 0;        // frames dropped as duplicates
  std::uint64_t rejected_markers = 0;  // markers invalidated for non-finite/absurd values
  int last_error = 0;                  // last decoder status < 0 (MarkerStreamStatus/HydraStatus value)
  TransportStats transport;            // the transport's own counters
  FrameMailboxStats mailbox;           // published / taken / dropped (overwritten before taken)
};

namespace detail {
struct AtomicSourceStats {
  std::atomic<std::uint64_t> frames_published{0}, decode_errors{0}, frames_lost{0}, duplicates{0},
      rejected_markers{0};
  std::atomic<int> last_error{0};
  DeviceSourceStats snapshot() const noexcept;
};
}  // namespace detail

// ---------------------------------------------------------------------------------------------

struct HidMarkerStreamSourceConfig {
  HidTransportConfig hid;  // vendor/product id etc.; report_size is forced to 64 and the START
                           // command is appended to hid.open_output_reports
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

 private:
  void onReport(const ReceivedReport& report) noexcept;
  FrameMailbox& mailbox_;
  HidTransport transport_;
  drivers::MarkerStreamDecoder decoder_;
  StatusSink user_status_;
  detail::AtomicSourceStats stats_;
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
  UsbTransportConfig usb;  // transfer_size is raised to kMarkerStreamMaxFrameSize; START (and
                           // SET_RATE) control requests are appended to usb.open_control_requests
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

 private:
  void onTransfer(const ReceivedReport& report) noexcept;
  FrameMailbox& mailbox_;
  UsbTransport transport_;
  drivers::MarkerStreamDecoder decoder_;
  StatusSink user_status_;
  detail::AtomicSourceStats stats_;
};

}  // namespace tetrig::devices
