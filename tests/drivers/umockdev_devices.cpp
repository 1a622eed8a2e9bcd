// Emulated hidraw and usbfs devices for the transport tests (see umockdev_devices.hpp).
// Written from umockdev's documented API (UMockdevTestbed, UMockdevIoctlBase) and the Linux
// hidraw/usbdevfs ioctl definitions.
#include "umockdev_devices.hpp"

#include <umockdev.h>

#include <dlfcn.h>
#include <fcntl.h>
#include <linux/hidraw.h>
#include <linux/input.h>
#include <linux/usb/ch9.h>
#include <linux/usbdevice_fs.h>
#include <poll.h>
#include <sys/ioctl.h>
#include <termios.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstddef>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iterator>
#include <sstream>

namespace tetrig::testing {

namespace {

// Run the whole binary under umockdev's preload library: re-exec once through umockdev-wrapper
// before main() when it is not active (ctest and a developer's shell both work the same way).
bool preloadActive() {
  // umockdev_in_mock_environment() caches its answer and is only true once a testbed exists, so it
  // cannot be asked before main(); the preload library itself is found through LD_PRELOAD.
  const char* preload = std::getenv("LD_PRELOAD");
  return preload != nullptr && std::strstr(preload, "libumockdev-preload") != nullptr;
}

#if defined(__SANITIZE_ADDRESS__)
#define TETRIG_TEST_ASAN 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define TETRIG_TEST_ASAN 1
#endif
#endif

#ifdef TETRIG_TEST_ASAN
extern "C" void __asan_init();
#endif

// Path of the AddressSanitizer runtime this binary uses, or "" when it is not instrumented.
std::string asanRuntimePath() {
#ifdef TETRIG_TEST_ASAN
  Dl_info info{};
  if (dladdr(reinterpret_cast<void*>(&__asan_init), &info) != 0 && info.dli_fname != nullptr) {
    // A static runtime (clang's default) lives in the executable: nothing to preload.
    char self[4096];
    const ssize_t n = readlink("/proc/self/exe", self, sizeof(self) - 1);
    char* resolved = realpath(info.dli_fname, nullptr);
    std::string path = resolved != nullptr ? resolved : info.dli_fname;
    std::free(resolved);
    if (n > 0 && path == std::string(self, static_cast<std::size_t>(n))) return {};
    return path;
  }
#endif
  return {};
}

struct ReexecUnderUmockdev {
  ReexecUnderUmockdev() {
    if (preloadActive()) return;
    if (std::getenv("TETRIG_UMOCKDEV_REEXEC") != nullptr) return;  // tried once already
    setenv("TETRIG_UMOCKDEV_REEXEC", "1", 1);
    char self[4096];
    const ssize_t n = readlink("/proc/self/exe", self, sizeof(self) - 1);
    if (n <= 0) return;
    self[n] = '\0';
    std::ifstream cmdline("/proc/self/cmdline", std::ios::binary);
    std::string all((std::istreambuf_iterator<char>(cmdline)), std::istreambuf_iterator<char>());
    std::vector<std::string> args;
    for (std::size_t start = 0; start < all.size();) {
      const std::size_t end = all.find('\0', start);
      args.push_back(all.substr(start, end == std::string::npos ? std::string::npos : end - start));
      if (end == std::string::npos) break;
      start = end + 1;
    }
    std::vector<char*> argv;
    std::string wrapper = "umockdev-wrapper";
    const std::string asan = asanRuntimePath();
    if (asan.empty()) argv.push_back(wrapper.data());
    argv.push_back(self);
    for (std::size_t i = 1; i < args.size(); ++i) argv.push_back(args[i].data());
    argv.push_back(nullptr);
    if (asan.empty()) {
      execvp(argv[0], argv.data());
    } else {
      // What umockdev-wrapper does, but with the sanitizer runtime first in the preload list
      // (AddressSanitizer refuses to start otherwise).
      const char* old_preload = std::getenv("LD_PRELOAD");
      std::string preload = asan + ":libumockdev-preload.so.0";
      if (old_preload != nullptr && *old_preload != '\0') preload += std::string(":") + old_preload;
      setenv("LD_PRELOAD", preload.c_str(), 1);
      execv(argv[0], argv.data());
    }
    // Not installed: carry on; every test then fails in inMockEnvironment().
  }
};
const ReexecUnderUmockdev kReexec;

std::string hex(std::span<const std::uint8_t> bytes) {
  static const char* digits = "0123456789ABCDEF";
  std::string out;
  for (std::uint8_t b : bytes) {
    out.push_back(digits[b >> 4]);
    out.push_back(digits[b & 15]);
  }
  return out;
}

std::string hex4(unsigned v) {
  char buf[8];
  std::snprintf(buf, sizeof(buf), "%04x", v & 0xffffu);
  return buf;
}

std::vector<std::uint8_t> defaultReportDescriptor() {
  // Vendor page 0xFF00, usage 1, application collection; 64-byte input, output and feature
  // reports of 8-bit fields, no report ids.
  return {0x06, 0x00, 0xFF, 0x09, 0x01, 0xA1, 0x01, 0x15, 0x00, 0x26, 0xFF, 0x00, 0x75, 0x08,
          0x95, 0x40, 0x09, 0x01, 0x81, 0x02, 0x95, 0x40, 0x09, 0x01, 0x91, 0x02, 0x95, 0x40,
          0x09, 0x01, 0xB1, 0x02, 0xC0};
}

extern "C" gboolean hidIoctlTrampoline(UMockdevIoctlBase*, UMockdevIoctlClient* client, gpointer self) {
  return static_cast<MockHidDevice*>(self)->handleIoctl(client) ? TRUE : FALSE;
}
extern "C" gboolean usbIoctlTrampoline(UMockdevIoctlBase*, UMockdevIoctlClient* client, gpointer self) {
  return static_cast<MockUsbDevice*>(self)->handleIoctl(client) ? TRUE : FALSE;
}

}  // namespace

bool inMockEnvironment() {
  if (!preloadActive()) return false;
  Testbed probe;  // the check needs a live testbed (it looks at the redirected /sys)
  return umockdev_in_mock_environment() != FALSE;
}

const char* mockEnvironmentHelp() {
  return "umockdev's preload library is not active: install the Debian packages 'umockdev' and "
         "'libumockdev-dev' (tools/setup.sh) and run the test under umockdev-wrapper";
}

// ---------------------------------------------------------------- Testbed

Testbed::Testbed() : testbed_(umockdev_testbed_new()) {}

Testbed::~Testbed() {
  if (testbed_ != nullptr) g_object_unref(testbed_);
}

bool Testbed::addFromString(const std::string& description) {
  GError* error = nullptr;
  const gboolean ok = umockdev_testbed_add_from_string(testbed_, description.c_str(), &error);
  if (error != nullptr) {
    std::fprintf(stderr, "umockdev add_from_string: %s\n", error->message);
    g_error_free(error);
  }
  return ok != FALSE;
}

void Testbed::removeDevice(const std::string& sysfs_path) { umockdev_testbed_remove_device(testbed_, sysfs_path.c_str()); }

void Testbed::unlinkBusEntry(const std::string& subsystem, const std::string& name) {
  gchar* sys = umockdev_testbed_get_sys_dir(testbed_);
  const std::string link = std::string(sys) + "/bus/" + subsystem + "/devices/" + name;
  g_free(sys);
  unlink(link.c_str());  // absent is fine
}

void Testbed::unlinkDevNode(const std::string& devnode) {
  gchar* root = umockdev_testbed_get_root_dir(testbed_);
  std::string flat = devnode.substr(5);  // without "/dev/"
  std::replace(flat.begin(), flat.end(), '/', '_');
  char target[256];
  const ssize_t n = readlink((std::string(root) + devnode).c_str(), target, sizeof(target) - 1);
  if (n > 0) {  // a pty node: umockdev also keeps /dev/.ptymap/<pty path with '_'>
    std::string pty(target, static_cast<std::size_t>(n));
    std::replace(pty.begin(), pty.end(), '/', '_');
    unlink((std::string(root) + "/dev/.ptymap/" + pty).c_str());
  }
  unlink((std::string(root) + devnode).c_str());
  unlink((std::string(root) + "/dev/.node/" + flat).c_str());
  g_free(root);
}

void Testbed::uevent(const std::string& sysfs_path, const char* action) {
  umockdev_testbed_uevent(testbed_, sysfs_path.c_str(), action);
}

// ---------------------------------------------------------------- HID

MockHidDevice::MockHidDevice(Testbed& testbed, MockHidSpec spec) : testbed_(testbed), spec_(std::move(spec)) {
  if (spec_.report_descriptor.empty()) spec_.report_descriptor = defaultReportDescriptor();
  usb_syspath_ = "/sys/devices/pci0000:00/0000:00:14.0/usb1/1-" + std::to_string(spec_.usb_port);
  handler_ = umockdev_ioctl_base_new();
  g_signal_connect(handler_, "handle-ioctl", G_CALLBACK(hidIoctlTrampoline), this);
}

MockHidDevice::~MockHidDevice() {
  if (plugged()) unplug();
  for (const std::string& node : attached_) {
    GError* error = nullptr;
    umockdev_testbed_detach_ioctl(testbed_.get(), node.c_str(), &error);
    if (error != nullptr) g_error_free(error);
  }
  g_signal_handlers_disconnect_by_data(handler_, this);
  g_object_unref(handler_);
}

void MockHidDevice::plug() {
  if (plugged()) return;
  // umockdev 0.17 cannot re-create a pty node under a name it used before in the same testbed,
  // so every plug gets the next hidraw number (as a real replug often does).
  const int index = spec_.hidraw_index + plug_count_++;
  devnode_ = "/dev/hidraw" + std::to_string(index);
  GError* error = nullptr;
  umockdev_testbed_attach_ioctl(testbed_.get(), devnode_.c_str(), handler_, &error);
  if (error != nullptr) {
    std::fprintf(stderr, "umockdev attach_ioctl %s: %s\n", devnode_.c_str(), error->message);
    g_error_free(error);
  } else {
    attached_.push_back(devnode_);
  }
  const std::string usb = usb_syspath_.substr(4);  // without "/sys"
  const std::string port = "1-" + std::to_string(spec_.usb_port);
  const std::string intf = usb + "/" + port + ":1." + std::to_string(spec_.interface_number);
  const std::string hid_name = "0003:" + hex4(spec_.vendor_id) + ":" + hex4(spec_.product_id) + "." +
                               hex4(static_cast<unsigned>(index + 1));
  std::string upper_hid = hid_name;
  std::transform(upper_hid.begin(), upper_hid.end(), upper_hid.begin(), ::toupper);
  const std::string hid = intf + "/" + upper_hid;
  const std::string raw = hid + "/hidraw/hidraw" + std::to_string(index);
  char hid_id[64];
  std::snprintf(hid_id, sizeof(hid_id), "0003:%08X:%08X", spec_.vendor_id, spec_.product_id);

  char intf_number[8];
  std::snprintf(intf_number, sizeof(intf_number), "%02x", spec_.interface_number & 0xff);
  std::ostringstream d;
  if (!spec_.shares_usb_device) {
    d << "P: " << usb << "\n"
    << "E: SUBSYSTEM=usb\nE: DEVTYPE=usb_device\nE: DRIVER=usb\n"
    << "A: idVendor=" << hex4(spec_.vendor_id) << "\n"
    << "A: idProduct=" << hex4(spec_.product_id) << "\n"
    << "A: bcdDevice=0100\n"
    << "A: manufacturer=" << spec_.manufacturer << "\n"
    << "A: product=" << spec_.product << "\n"
    << "A: serial=" << spec_.serial << "\n\n";
  }
  d << "P: " << intf << "\n"
    << "E: SUBSYSTEM=usb\nE: DEVTYPE=usb_interface\nE: DRIVER=usbhid\n"
    << "A: bInterfaceNumber=" << intf_number << "\nA: bInterfaceClass=03\n\n";
  d << "P: " << hid << "\n"
    << "E: SUBSYSTEM=hid\nE: DRIVER=hid-generic\n"
    << "E: HID_ID=" << hid_id << "\n"
    << "E: HID_NAME=" << spec_.manufacturer << " " << spec_.product << "\n"
    << "E: HID_UNIQ=" << spec_.serial << "\n"
    << "E: MODALIAS=hid:b0003g0001v0000" << hex4(spec_.vendor_id) << "p0000" << hex4(spec_.product_id) << "\n"
    << "H: report_descriptor=" << hex(spec_.report_descriptor) << "\n\n";
  d << "P: " << raw << "\n"
    << "N: hidraw" << index << "\n"
    << "E: SUBSYSTEM=hidraw\n"
    << "E: DEVNAME=" << devnode_ << "\n"
    << "E: MAJOR=241\nE: MINOR=" << index << "\n"
    << "A: dev=241:" << index << "\n"
    << "L: device=../..\n\n";  // hidapi reads <hidraw>/device/uevent to filter by VID/PID
  if (!testbed_.addFromString(d.str())) return;
  plugged_paths_ = {{"/sys" + intf, "usb"}, {"/sys" + hid, "hid"}, {"/sys" + raw, "hidraw"}};
  if (!spec_.shares_usb_device) plugged_paths_.insert(plugged_paths_.begin(), {"/sys" + usb, "usb"});

  master_fd_ = umockdev_testbed_get_dev_fd(testbed_.get(), devnode_.c_str());
  if (master_fd_ < 0) return;
  // Raw pty: no signals, no flow control, no translation. VMIN = one input report, so a reader
  // sees (poll and read) whole reports only, like a real hidraw node.
  termios tio{};
  if (tcgetattr(master_fd_, &tio) == 0) {
    cfmakeraw(&tio);
    tio.c_cc[VMIN] = static_cast<cc_t>(std::min<std::size_t>(spec_.input_report_size, 255));
    tio.c_cc[VTIME] = 0;
    tcsetattr(master_fd_, TCSANOW, &tio);
  }
}

void MockHidDevice::unplug() {
  if (!plugged()) return;
  // Hang up: replace the master by /dev/null (closing the only master reference, so the reader
  // gets POLLHUP/EIO) while keeping the descriptor number valid for the testbed, which closes it
  // again when it is destroyed.
  const int devnull = open("/dev/null", O_RDWR | O_CLOEXEC);
  if (devnull >= 0) {
    dup2(devnull, master_fd_);
    close(devnull);
  }
  master_fd_ = -1;
  if (!spec_.shares_usb_device) testbed_.uevent(usb_syspath_, "remove");
  testbed_.unlinkDevNode(devnode_);  // before removal: it follows the node's pty link
  // Deepest first; umockdev removes class links and usb bus links itself, the hid bus link and the
  // interface's usb bus link are left behind and would make the next plug() fail.
  for (auto it = plugged_paths_.rbegin(); it != plugged_paths_.rend(); ++it) {
    testbed_.removeDevice(it->first);
    testbed_.unlinkBusEntry(it->second, it->first.substr(it->first.rfind('/') + 1));
  }
  plugged_paths_.clear();
}

bool MockHidDevice::inject(std::span<const std::uint8_t> report) {
  if (master_fd_ < 0) return false;
  std::size_t done = 0;
  while (done < report.size()) {
    const ssize_t n = write(master_fd_, report.data() + done, report.size() - done);
    if (n < 0) {
      if (errno == EINTR) continue;
      return false;
    }
    done += static_cast<std::size_t>(n);
  }
  return true;
}

std::vector<std::uint8_t> MockHidDevice::readOutput(std::size_t max, int timeout_ms) {
  std::vector<std::uint8_t> out;
  if (master_fd_ < 0) return out;
  const auto deadline = g_get_monotonic_time() + static_cast<gint64>(timeout_ms) * 1000;
  while (out.size() < max) {
    const gint64 left_us = deadline - g_get_monotonic_time();
    if (left_us <= 0) break;
    pollfd p{master_fd_, POLLIN, 0};
    if (poll(&p, 1, static_cast<int>(left_us / 1000 + 1)) <= 0) continue;
    std::uint8_t buf[256];
    const ssize_t n = read(master_fd_, buf, std::min(sizeof(buf), max - out.size()));
    if (n <= 0) {
      // EIO while no client has the node open (the master sees a hang-up until then).
      g_usleep(1000);
      continue;
    }
    out.insert(out.end(), buf, buf + n);
  }
  return out;
}

std::vector<std::vector<std::uint8_t>> MockHidDevice::featureReports() const {
  std::lock_guard lock(mutex_);
  return features_;
}

void MockHidDevice::setFeatureErrno(int err) {
  std::lock_guard lock(mutex_);
  feature_errno_ = err;
}

bool MockHidDevice::handleIoctl(UMockdevIoctlClient* client) {
  const gulong request = umockdev_ioctl_client_get_request(client);
  UMockdevIoctlData* arg = umockdev_ioctl_client_get_arg(client);
  if (_IOC_TYPE(request) != 'H') return false;
  const auto size = static_cast<gsize>(_IOC_SIZE(request));
  switch (_IOC_NR(request)) {
    case _IOC_NR(HIDIOCGRDESCSIZE): {
      UMockdevIoctlData* d = umockdev_ioctl_data_resolve(arg, 0, sizeof(int), nullptr);
      if (d == nullptr) return false;
      *reinterpret_cast<int*>(d->data) = static_cast<int>(spec_.report_descriptor.size());
      umockdev_ioctl_client_complete(client, 0, 0);
      g_object_unref(d);
      return true;
    }
    case _IOC_NR(HIDIOCGRDESC): {
      UMockdevIoctlData* d = umockdev_ioctl_data_resolve(arg, 0, sizeof(hidraw_report_descriptor), nullptr);
      if (d == nullptr) return false;
      auto* desc = reinterpret_cast<hidraw_report_descriptor*>(d->data);
      const std::size_t n = std::min<std::size_t>(spec_.report_descriptor.size(), HID_MAX_DESCRIPTOR_SIZE);
      desc->size = static_cast<__u32>(n);
      std::memcpy(desc->value, spec_.report_descriptor.data(), n);
      umockdev_ioctl_client_complete(client, 0, 0);
      g_object_unref(d);
      return true;
    }
    case _IOC_NR(HIDIOCGRAWINFO): {
      UMockdevIoctlData* d = umockdev_ioctl_data_resolve(arg, 0, sizeof(hidraw_devinfo), nullptr);
      if (d == nullptr) return false;
      auto* info = reinterpret_cast<hidraw_devinfo*>(d->data);
      info->bustype = BUS_USB;
      info->vendor = static_cast<__s16>(spec_.vendor_id);
      info->product = static_cast<__s16>(spec_.product_id);
      umockdev_ioctl_client_complete(client, 0, 0);
      g_object_unref(d);
      return true;
    }
    case 0x06: {  // HIDIOCSFEATURE(len)
      UMockdevIoctlData* d = umockdev_ioctl_data_resolve(arg, 0, size, nullptr);
      if (d == nullptr) return false;
      int err = 0;
      {
        std::lock_guard lock(mutex_);
        err = feature_errno_;
        if (err == 0) features_.emplace_back(d->data, d->data + size);
      }
      if (err != 0) {
        umockdev_ioctl_client_complete(client, -1, err);
      } else {
        umockdev_ioctl_client_complete(client, static_cast<glong>(size), 0);
      }
      g_object_unref(d);
      return true;
    }
    case 0x07: {  // HIDIOCGFEATURE(len): report id kept, payload zero
      UMockdevIoctlData* d = umockdev_ioctl_data_resolve(arg, 0, size, nullptr);
      if (d == nullptr) return false;
      if (size > 1) std::memset(d->data + 1, 0, size - 1);
      umockdev_ioctl_client_complete(client, static_cast<glong>(size), 0);
      g_object_unref(d);
      return true;
    }
    default:
      umockdev_ioctl_client_complete(client, -1, ENOTTY);
      return true;
  }
}

// ---------------------------------------------------------------- USB

MockUsbDevice::MockUsbDevice(Testbed& testbed, MockUsbSpec spec) : testbed_(testbed), spec_(spec) {
  char node[64];
  std::snprintf(node, sizeof(node), "/dev/bus/usb/%03d/%03d", spec_.bus, spec_.address);
  devnode_ = node;
  syspath_ = "/sys/devices/pci0000:00/0000:00:14.0/usb" + std::to_string(spec_.bus) + "/" +
             std::to_string(spec_.bus) + "-" + std::to_string(spec_.address);
  handler_ = umockdev_ioctl_base_new();
  g_signal_connect(handler_, "handle-ioctl", G_CALLBACK(usbIoctlTrampoline), this);
  GError* error = nullptr;
  umockdev_testbed_attach_ioctl(testbed_.get(), devnode_.c_str(), handler_, &error);
  if (error != nullptr) {
    std::fprintf(stderr, "umockdev attach_ioctl %s: %s\n", devnode_.c_str(), error->message);
    g_error_free(error);
  }
}

MockUsbDevice::~MockUsbDevice() {
  if (plugged()) unplug();
  GError* error = nullptr;
  umockdev_testbed_detach_ioctl(testbed_.get(), devnode_.c_str(), &error);
  if (error != nullptr) g_error_free(error);
  g_signal_handlers_disconnect_by_data(handler_, this);
  g_object_unref(handler_);
  std::lock_guard lock(mutex_);
  clearLocked();
}

void MockUsbDevice::clearLocked() {
  for (Urb& u : pending_in_) g_object_unref(u.data);
  for (Urb& u : finished_) g_object_unref(u.data);
  pending_in_.clear();
  finished_.clear();
}

void MockUsbDevice::plug() {
  {
    std::lock_guard lock(mutex_);
    if (plugged_) return;
    clearLocked();
    in_data_.clear();
    gone_ = false;
    plugged_ = true;
  }
  // Device descriptor (18 bytes) + configuration 1: one vendor interface with a bulk IN and a
  // bulk OUT endpoint of 512-byte packets.
  const auto vid_lo = static_cast<std::uint8_t>(spec_.vendor_id & 0xff);
  const auto vid_hi = static_cast<std::uint8_t>(spec_.vendor_id >> 8);
  const auto pid_lo = static_cast<std::uint8_t>(spec_.product_id & 0xff);
  const auto pid_hi = static_cast<std::uint8_t>(spec_.product_id >> 8);
  const std::vector<std::uint8_t> descriptors = {
      0x12, 0x01, 0x00, 0x02, 0x00, 0x00, 0x00, 0x40, vid_lo, vid_hi, pid_lo, pid_hi, 0x00, 0x01, 0x00, 0x00,
      0x00, 0x01,                                                   // device
      0x09, 0x02, 0x20, 0x00, 0x01, 0x01, 0x00, 0x80, 0x32,         // configuration, 32 bytes total
      0x09, 0x04, 0x00, 0x00, 0x02, 0xFF, 0x00, 0x00, 0x00,         // interface 0, 2 endpoints
      0x07, 0x05, spec_.endpoint_in, 0x02, 0x00, 0x02, 0x00,        // bulk IN, 512
      0x07, 0x05, spec_.endpoint_out, 0x02, 0x00, 0x02, 0x00};      // bulk OUT, 512
  char numbers[128];
  std::snprintf(numbers, sizeof(numbers), "E: BUSNUM=%03d\nE: DEVNUM=%03d\nA: busnum=%d\nA: devnum=%d\n", spec_.bus,
                spec_.address, spec_.bus, spec_.address);
  std::ostringstream d;
  d << "P: " << syspath_.substr(4) << "\n"
    << "N: " << devnode_.substr(5) << "\n"
    << "E: SUBSYSTEM=usb\nE: DEVTYPE=usb_device\nE: DRIVER=usb\n"
    << "E: DEVNAME=" << devnode_ << "\n"
    << numbers
    << "A: idVendor=" << hex4(spec_.vendor_id) << "\nA: idProduct=" << hex4(spec_.product_id) << "\n"
    << "A: bConfigurationValue=1\nA: speed=480\n"
    << "H: descriptors=" << hex(descriptors) << "\n\n";
  testbed_.addFromString(d.str());
}

void MockUsbDevice::unplug() {
  {
    std::lock_guard lock(mutex_);
    if (!plugged_) return;
    gone_ = true;
    plugged_ = false;
  }
  testbed_.uevent(syspath_, "remove");
  testbed_.removeDevice(syspath_);
}

bool MockUsbDevice::plugged() const {
  std::lock_guard lock(mutex_);
  return plugged_;
}

void MockUsbDevice::pushIn(std::span<const std::uint8_t> chunk) {
  std::lock_guard lock(mutex_);
  in_data_.push_back(InChunk{std::vector<std::uint8_t>(chunk.begin(), chunk.end()), 0});
}

void MockUsbDevice::pushInError(int negative_errno) {
  std::lock_guard lock(mutex_);
  in_data_.push_back(InChunk{{}, negative_errno});
}

std::size_t MockUsbDevice::pendingInData() const {
  std::lock_guard lock(mutex_);
  return in_data_.size();
}

std::vector<std::vector<std::uint8_t>> MockUsbDevice::outTransfers() const {
  std::lock_guard lock(mutex_);
  return out_data_;
}

std::vector<std::vector<std::uint8_t>> MockUsbDevice::controlRequests() const {
  std::lock_guard lock(mutex_);
  return control_;
}

int MockUsbDevice::lastInUrbType() const {
  std::lock_guard lock(mutex_);
  return last_in_type_;
}

int MockUsbDevice::urbsPending() const {
  std::lock_guard lock(mutex_);
  return static_cast<int>(pending_in_.size());
}
int MockUsbDevice::maxUrbsPending() const {
  std::lock_guard lock(mutex_);
  return max_pending_;
}
int MockUsbDevice::urbsSubmitted() const {
  std::lock_guard lock(mutex_);
  return submitted_;
}
int MockUsbDevice::urbsDiscarded() const {
  std::lock_guard lock(mutex_);
  return discarded_;
}
int MockUsbDevice::urbsReapedAfterDiscard() const {
  std::lock_guard lock(mutex_);
  return reaped_discarded_;
}

void MockUsbDevice::completeReap(UMockdevIoctlClient* client, Urb urb, int status,
                                 std::span<const std::uint8_t> payload) {
  auto* u = reinterpret_cast<usbdevfs_urb*>(urb.data->data);
  const std::size_t n = std::min<std::size_t>(payload.size(), static_cast<std::size_t>(std::max(u->buffer_length, 0)));
  if (n > 0) std::memcpy(u->buffer, payload.data(), n);
  if (payload.size() > 0 || status != 0) u->actual_length = static_cast<int>(n);
  u->status = status;
  UMockdevIoctlData* arg = umockdev_ioctl_client_get_arg(client);
  UMockdevIoctlData* slot = umockdev_ioctl_data_resolve(arg, 0, sizeof(void*), nullptr);
  umockdev_ioctl_data_set_ptr(slot, 0, urb.data);
  umockdev_ioctl_client_complete(client, 0, 0);
  g_object_unref(slot);
  g_object_unref(urb.data);
}

bool MockUsbDevice::handleIoctl(UMockdevIoctlClient* client) {
  const gulong request = umockdev_ioctl_client_get_request(client);
  UMockdevIoctlData* arg = umockdev_ioctl_client_get_arg(client);
  if (_IOC_TYPE(request) != 'U') return false;
  std::unique_lock lock(mutex_);

  switch (request) {
    case USBDEVFS_GET_CAPABILITIES: {
      UMockdevIoctlData* d = umockdev_ioctl_data_resolve(arg, 0, sizeof(__u32), nullptr);
      if (d == nullptr) return false;
      *reinterpret_cast<__u32*>(d->data) = USBDEVFS_CAP_ZERO_PACKET | USBDEVFS_CAP_BULK_CONTINUATION |
                                          USBDEVFS_CAP_NO_PACKET_SIZE_LIM | USBDEVFS_CAP_REAP_AFTER_DISCONNECT;
      umockdev_ioctl_client_complete(client, 0, 0);
      g_object_unref(d);
      return true;
    }
    case USBDEVFS_CLAIMINTERFACE:
    case USBDEVFS_RELEASEINTERFACE:
    case USBDEVFS_SETINTERFACE:
    case USBDEVFS_SETCONFIGURATION:
    case USBDEVFS_CLEAR_HALT:
    case USBDEVFS_RESET:
    case USBDEVFS_RESETEP:
    case USBDEVFS_DISCONNECT_CLAIM:
      if (gone_) {
        umockdev_ioctl_client_complete(client, -1, ENODEV);
      } else {
        umockdev_ioctl_client_complete(client, 0, 0);
      }
      return true;
    case USBDEVFS_GETDRIVER:
    case USBDEVFS_IOCTL:  // no kernel driver bound: nothing to detach
      umockdev_ioctl_client_complete(client, -1, gone_ ? ENODEV : ENODATA);
      return true;
    case USBDEVFS_GET_SPEED:
      umockdev_ioctl_client_complete(client, 3 /* USB_SPEED_HIGH */, 0);
      return true;

    case USBDEVFS_SUBMITURB: {
      if (gone_) {
        umockdev_ioctl_client_complete(client, -1, ENODEV);
        return true;
      }
      UMockdevIoctlData* urb_data = umockdev_ioctl_data_resolve(arg, 0, sizeof(usbdevfs_urb), nullptr);
      if (urb_data == nullptr) return false;
      auto* urb = reinterpret_cast<usbdevfs_urb*>(urb_data->data);
      UMockdevIoctlData* buffer = nullptr;
      if (urb->buffer_length > 0) {
        buffer = umockdev_ioctl_data_resolve(urb_data, offsetof(usbdevfs_urb, buffer),
                                             static_cast<gsize>(urb->buffer_length), nullptr);
      }
      if (urb->type == USBDEVFS_URB_TYPE_CONTROL) {
        // Setup packet (8 bytes) + data stage; host-to-device only: accepted and recorded.
        const auto* bytes = static_cast<const std::uint8_t*>(urb->buffer);
        control_.emplace_back(bytes, bytes + std::max(urb->buffer_length, 0));
        urb->actual_length = std::max(urb->buffer_length - 8, 0);
        urb->status = 0;
        finished_.push_back(Urb{urb_data, 0, false});
      } else if ((urb->endpoint & 0x80) != 0) {
        pending_in_.push_back(Urb{urb_data, 0, false});  // keeps the resolve reference
        ++submitted_;
        last_in_type_ = urb->type;
        max_pending_ = std::max(max_pending_, static_cast<int>(pending_in_.size()));
      } else {
        const auto* bytes = static_cast<const std::uint8_t*>(urb->buffer);
        out_data_.emplace_back(bytes, bytes + std::max(urb->buffer_length, 0));
        urb->actual_length = urb->buffer_length;
        urb->status = 0;
        finished_.push_back(Urb{urb_data, 0, false});
      }
      umockdev_ioctl_client_complete(client, 0, 0);
      if (buffer != nullptr) g_object_unref(buffer);
      return true;
    }

    case USBDEVFS_DISCARDURB: {
      // The argument is the client's URB address itself.
      const gulong client_urb = *reinterpret_cast<const gulong*>(arg->data);
      auto it = std::find_if(pending_in_.begin(), pending_in_.end(),
                             [&](const Urb& u) { return u.data->client_addr == client_urb; });
      if (it == pending_in_.end()) {
        umockdev_ioctl_client_complete(client, -1, EINVAL);
        return true;
      }
      Urb u = *it;
      pending_in_.erase(it);
      u.discarded = true;
      u.status = -ENOENT;
      finished_.push_back(u);
      ++discarded_;
      umockdev_ioctl_client_complete(client, 0, 0);
      return true;
    }

    case USBDEVFS_REAPURB:
    case USBDEVFS_REAPURBNDELAY: {
      if (!finished_.empty()) {
        Urb u = finished_.front();
        finished_.pop_front();
        if (u.discarded) ++reaped_discarded_;
        auto* urb = reinterpret_cast<usbdevfs_urb*>(u.data->data);
        const int status = u.discarded ? u.status : urb->status;
        if (u.discarded) urb->actual_length = 0;
        completeReap(client, u, status, {});
        return true;
      }
      if (gone_ && !pending_in_.empty()) {  // surprise removal: every URB dies with ENODEV
        Urb u = pending_in_.front();
        pending_in_.pop_front();
        reinterpret_cast<usbdevfs_urb*>(u.data->data)->actual_length = 0;
        completeReap(client, u, -ENODEV, {});
        return true;
      }
      if (gone_) {
        umockdev_ioctl_client_complete(client, -1, ENODEV);
        return true;
      }
      if (!pending_in_.empty() && !in_data_.empty()) {
        Urb u = pending_in_.front();
        pending_in_.pop_front();
        InChunk chunk = std::move(in_data_.front());
        in_data_.pop_front();
        if (chunk.status != 0) reinterpret_cast<usbdevfs_urb*>(u.data->data)->actual_length = 0;
        completeReap(client, u, chunk.status, chunk.bytes);
        return true;
      }
      umockdev_ioctl_client_complete(client, -1, EAGAIN);
      return true;
    }
    default:
      umockdev_ioctl_client_complete(client, -1, ENOTTY);
      return true;
  }
}

}  // namespace tetrig::testing
