// Test helper: emulated HID (hidraw) and USB (usbfs) devices on an in-process umockdev testbed,
// so the REAL hidapi and libusb code runs against them.
//
// - The test binary must run with umockdev's preload library (umockdev-wrapper). If it was started
//   without it, the helper re-executes the binary under umockdev-wrapper once, before main();
//   if that is impossible, requireMockEnvironment() fails the test (never skips).
// - MockHidDevice: sysfs tree usb_device -> usb_interface -> hid -> hidraw, the hidraw node is a pty
//   (umockdev's choice) switched to raw mode; input reports are written to the pty master, output
//   reports written by hidapi are read back from it; an ioctl handler answers the report-descriptor
//   ioctls and records feature reports (HIDIOCSFEATURE). Unplug hangs up the pty and removes the
//   sysfs tree; plug() adds a fresh one.
// - MockUsbDevice: sysfs usb_device with descriptors and a usbfs node whose ioctls are served by a
//   virtual device: SUBMITURB/REAPURB(NDELAY)/DISCARDURB with a queue of submitted URBs and a queue
//   of data per IN endpoint; OUT data is recorded. Unplug makes every pending URB and every later
//   ioctl fail with ENODEV, sends the "remove" uevent and removes the sysfs entry.
#pragma once

#include <cstdint>
#include <deque>
#include <map>
#include <memory>
#include <mutex>
#include <span>
#include <string>
#include <vector>

typedef struct _UMockdevTestbed UMockdevTestbed;
typedef struct _UMockdevIoctlBase UMockdevIoctlBase;
typedef struct _UMockdevIoctlClient UMockdevIoctlClient;
typedef struct _UMockdevIoctlData UMockdevIoctlData;

namespace tetrig::testing {

// True if the umockdev preload library is active in this process.
bool inMockEnvironment();
// Human-readable reason for the failure when inMockEnvironment() is false.
const char* mockEnvironmentHelp();

// Owns one umockdev testbed (a private /sys and /dev for this process). One per test.
class Testbed {
 public:
  Testbed();
  ~Testbed();
  Testbed(const Testbed&) = delete;
  Testbed& operator=(const Testbed&) = delete;
  UMockdevTestbed* get() const { return testbed_; }
  bool addFromString(const std::string& description);  // umockdev-record format
  void removeDevice(const std::string& sysfs_path);    // "/sys/devices/..."
  void uevent(const std::string& sysfs_path, const char* action);
  // Remove a leftover /sys/bus/<subsystem>/devices/<name> link (umockdev keeps some on removal).
  void unlinkBusEntry(const std::string& subsystem, const std::string& name);
  // Remove a leftover device node and its major:minor marker (umockdev keeps them for some nodes).
  void unlinkDevNode(const std::string& devnode);

 private:
  UMockdevTestbed* testbed_ = nullptr;
};

struct MockHidSpec {
  std::uint16_t vendor_id = 0x1209;
  std::uint16_t product_id = 0x7e70;
  int hidraw_index = 0;  // /dev/hidraw<N> at the first plug; each replug takes the next number
  int usb_port = 1;      // sysfs name 1-<port>
  std::string manufacturer = "tetrig test";
  std::string product = "mock marker stream";
  std::string serial = "TT0001";
  std::size_t input_report_size = 64;  // bytes per input report (the pty delivers whole reports)
  int interface_number = 0;            // USB interface the hidraw node belongs to
  // A second interface of an already plugged device (e.g. the Hydra's control interface) adds
  // only its interface/hid/hidraw entries under the same usb_device; unplug it first.
  bool shares_usb_device = false;
  std::vector<std::uint8_t> report_descriptor;  // empty: a vendor-defined 64-byte in/out/feature one
};

class MockHidDevice {
 public:
  MockHidDevice(Testbed& testbed, MockHidSpec spec);
  ~MockHidDevice();
  MockHidDevice(const MockHidDevice&) = delete;
  MockHidDevice& operator=(const MockHidDevice&) = delete;

  void plug();    // add the sysfs tree and a fresh pty node
  void unplug();  // hang up the pty (reader sees POLLHUP), remove the sysfs tree
  bool plugged() const { return master_fd_ >= 0; }
  const std::string& devnode() const { return devnode_; }  // of the current/last plug

  // Write one input report to the pty master (what the host reads). False if unplugged/failed.
  bool inject(std::span<const std::uint8_t> report);
  // Read up to `max` bytes that the host wrote (output reports), waiting up to timeout_ms.
  std::vector<std::uint8_t> readOutput(std::size_t max, int timeout_ms);
  // Feature reports received through HIDIOCSFEATURE, in order (copies; any thread).
  std::vector<std::vector<std::uint8_t>> featureReports() const;
  // Make HIDIOCSFEATURE fail with this errno (0: succeed).
  void setFeatureErrno(int err);

  // ioctl handler entry (GLib signal callback; public only for the C trampoline).
  bool handleIoctl(UMockdevIoctlClient* client);

 private:
  Testbed& testbed_;
  MockHidSpec spec_;
  std::string devnode_;
  std::string usb_syspath_;
  int master_fd_ = -1;
  int plug_count_ = 0;
  std::vector<std::string> attached_;  // device nodes the ioctl handler is attached to
  std::vector<std::pair<std::string, std::string>> plugged_paths_;  // sysfs path, subsystem
  UMockdevIoctlBase* handler_ = nullptr;
  mutable std::mutex mutex_;
  std::vector<std::vector<std::uint8_t>> features_;
  int feature_errno_ = 0;
};

struct MockUsbSpec {
  std::uint16_t vendor_id = 0x1209;
  std::uint16_t product_id = 0x7e71;
  int bus = 1;
  int address = 2;
  std::uint8_t endpoint_in = 0x81;   // bulk IN, 512-byte packets
  std::uint8_t endpoint_out = 0x01;  // bulk OUT
};

class MockUsbDevice {
 public:
  MockUsbDevice(Testbed& testbed, MockUsbSpec spec);
  ~MockUsbDevice();
  MockUsbDevice(const MockUsbDevice&) = delete;
  MockUsbDevice& operator=(const MockUsbDevice&) = delete;

  void plug();    // add the sysfs device (umockdev sends the "add" uevent)
  void unplug();  // surprise removal: URBs fail with ENODEV, "remove" uevent, sysfs entry removed
  bool plugged() const;

  // Queue data the device will return on the IN endpoint: one chunk completes one IN URB
  // (truncated to the URB's length).
  void pushIn(std::span<const std::uint8_t> chunk);
  // Queue a failed IN completion instead of data (negative errno as the kernel reports it:
  // -EPROTO/-EILSEQ -> LIBUSB_TRANSFER_ERROR, -EPIPE -> STALL, -EOVERFLOW -> OVERFLOW).
  void pushInError(int negative_errno);
  std::size_t pendingInData() const;
  // Bytes of every OUT URB the host submitted, in order.
  std::vector<std::vector<std::uint8_t>> outTransfers() const;
  // Every control request the host sent: 8-byte setup packet followed by the data stage.
  std::vector<std::vector<std::uint8_t>> controlRequests() const;

  int lastInUrbType() const;        // usbdevfs URB type of the last IN URB (1 interrupt, 3 bulk)
  int urbsPending() const;          // IN URBs submitted and not yet reaped
  int maxUrbsPending() const;       // high-water mark of urbsPending()
  int urbsSubmitted() const;        // IN URBs ever submitted
  int urbsDiscarded() const;        // DISCARDURB requests that found their URB
  int urbsReapedAfterDiscard() const;

  bool handleIoctl(UMockdevIoctlClient* client);

 private:
  struct Urb {
    UMockdevIoctlData* data = nullptr;  // owned reference
    int status = 0;
    bool discarded = false;
  };
  void completeReap(UMockdevIoctlClient* client, Urb urb, int status, std::span<const std::uint8_t> payload);
  void clearLocked();

  Testbed& testbed_;
  MockUsbSpec spec_;
  std::string syspath_;
  std::string devnode_;
  UMockdevIoctlBase* handler_ = nullptr;
  mutable std::mutex mutex_;
  bool plugged_ = false;
  bool gone_ = false;
  std::deque<Urb> pending_in_;   // submitted IN URBs, oldest first
  std::deque<Urb> finished_;     // OUT URBs done / discarded URBs, waiting to be reaped
  struct InChunk {
    std::vector<std::uint8_t> bytes;
    int status = 0;
  };
  std::deque<InChunk> in_data_;
  std::vector<std::vector<std::uint8_t>> out_data_;
  std::vector<std::vector<std::uint8_t>> control_;
  int max_pending_ = 0;
  int last_in_type_ = -1;
  int submitted_ = 0;
  int discarded_ = 0;
  int reaped_discarded_ = 0;
};

}  // namespace tetrig::testing
