#include "tests/fake_marker_devices.hpp"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <unistd.h>

#include <fmt/format.h>
#include <linux/hidraw.h>
#include <linux/usbdevice_fs.h>
#include <sys/ioctl.h>
#include <sys/stat.h>
#include <umockdev.h>

#include "core/time.hpp"

namespace facecap::test {
namespace {

namespace proto = formats::device;

// Re-executes the test binary with libumockdev-preload loaded, once, before main(). glibc
// passes constructors the program's arguments.
constexpr const char* kPreload = "libumockdev-preload.so.0";
constexpr const char* kReexecMark = "FACECAP_UMOCKDEV_REEXEC";

[[gnu::constructor]] void run_under_umockdev(int, char** argv, char**) {
  const char* preload = std::getenv("LD_PRELOAD");
  if ((preload && std::strstr(preload, "libumockdev-preload")) || std::getenv(kReexecMark)) return;
  const std::string value = preload && *preload ? fmt::format("{}:{}", kPreload, preload) : kPreload;
  setenv("LD_PRELOAD", value.c_str(), 1);
  setenv(kReexecMark, "1", 1);  // the library missing: the second run goes on without it
  execv("/proc/self/exe", argv);
}

// Addresses and hidraw minors are handed out once per process, as the kernel hands out
// fresh ones on every plug (umockdev cannot recreate a node it made once).
std::atomic<int> next_usb_address{2};
std::atomic<int> next_hidraw_minor{0};

std::string hex(std::span<const uint8_t> bytes) {
  std::string out;
  for (const uint8_t b : bytes) out += fmt::format("{:02x}", b);
  return out;
}

// Device, configuration, interface (class ff/46/01 or ff/00/00) and bulk IN endpoint 0x81.
std::vector<uint8_t> usb_descriptors(const FakeDeviceSpec& spec) {
  const uint8_t subclass = spec.marker_interface ? proto::kUsbInterfaceSubclass : 0;
  const uint8_t protocol = spec.marker_interface ? proto::kUsbInterfaceProtocol : 0;
  return {18, 1, 0x00, 0x02, 0, 0, 0, 64, uint8_t(spec.vendor_id), uint8_t(spec.vendor_id >> 8),
          uint8_t(spec.product_id), uint8_t(spec.product_id >> 8), 0x00, 0x01, 1, 2, 3, 1,
          9, 2, 25, 0, 1, 1, 0, 0x80, 50,
          9, 4, 0, 0, 1, proto::kUsbInterfaceClass, subclass, protocol, 0,
          7, 5, 0x81, 0x02, 64, 0, 0};
}

// Usage page 0xFF46, usage 1: input report 3 and feature reports 1 and 2 of bytes.
std::vector<uint8_t> hid_report_descriptor(const FakeDeviceSpec& spec) {
  const auto chunk = uint8_t(spec.info.max_chunk_bytes);
  return {0x06, 0x46, 0xFF, 0x09, 0x01, 0xA1, 0x01, 0x15, 0x00, 0x26, 0xFF, 0x00, 0x75, 0x08,
          0x85, proto::kHidChunkReport, 0x09, 0x02, 0x95, chunk, 0x81, 0x02,
          0x85, proto::kHidInfoReport, 0x09, 0x03, 0x95, uint8_t(proto::kInfoBytes), 0xB1, 0x02,
          0x85, proto::kHidControlReport, 0x09, 0x04, 0x95, uint8_t(proto::kControlBytes), 0xB1, 0x02, 0xC0};
}

std::vector<uint8_t> string_descriptor(std::string_view text) {
  std::vector<uint8_t> out{uint8_t(2 + 2 * text.size()), 3};
  for (const char c : text) out.insert(out.end(), {uint8_t(c), 0});
  return out;
}

UMockdevIoctlData* resolve(UMockdevIoctlData* data, std::size_t offset, std::size_t length) {
  GError* error = nullptr;
  UMockdevIoctlData* child = umockdev_ioctl_data_resolve(data, offset, length, &error);
  if (error) g_error_free(error);
  return child;
}

}  // namespace

// -- Testbed ------------------------------------------------------------------------------

Umockdev::Umockdev() : bed_(umockdev_testbed_new()) {
  struct stat sys{};
  // The preload library turns /sys into the testbed's directory (not inode 1, sysfs's root).
  active_ = stat("/sys", &sys) == 0 && sys.st_ino > 1;
}

Umockdev::~Umockdev() { g_object_unref(bed_); }

std::string Umockdev::inactive_message() {
  return "SKIPPED: umockdev's preload library is not active (install the umockdev package; the test re-runs itself "
         "with LD_PRELOAD=libumockdev-preload.so.0)";
}

// -- What both fakes share ----------------------------------------------------------------

FakeDeviceBase::FakeDeviceBase(FakeDeviceSpec spec) : spec_(std::move(spec)) {}

void FakeDeviceBase::send_chunk(std::vector<uint8_t> chunk) {
  std::lock_guard lock(mutex_);
  chunks_.push_back(std::move(chunk));
  changed_.notify_all();
}

void FakeDeviceBase::send_frame(const proto::DeviceFrame& frame) {
  for (auto& chunk : proto::encode_frame_chunks(frame, spec_.info.max_chunk_bytes)) send_chunk(std::move(chunk));
}

bool FakeDeviceBase::streaming() const {
  std::lock_guard lock(mutex_);
  return streaming_;
}
uint32_t FakeDeviceBase::rate_mhz() const {
  std::lock_guard lock(mutex_);
  return rate_mhz_;
}
int FakeDeviceBase::controls_received() const {
  std::lock_guard lock(mutex_);
  return controls_;
}
std::size_t FakeDeviceBase::queued() const {
  std::lock_guard lock(mutex_);
  return chunks_.size();
}
bool FakeDeviceBase::plugged() const {
  std::lock_guard lock(mutex_);
  return plugged_;
}

bool FakeDeviceBase::wait_until_read(int64_t timeout_ns) const {
  std::unique_lock lock(mutex_);
  return changed_.wait_for(lock, std::chrono::nanoseconds(timeout_ns), [&] { return chunks_.empty(); });
}

void FakeDeviceBase::on_control(const std::vector<uint8_t>& block) {
  const proto::Control control = proto::parse_control(block, "fake device");
  streaming_ = control.command == proto::Command::kStart;
  rate_mhz_ = control.rate_mhz;
  ++controls_;
  changed_.notify_all();
}

// -- USB ----------------------------------------------------------------------------------

FakeUsbMarkerDevice::FakeUsbMarkerDevice(Umockdev& bed, FakeDeviceSpec spec, bool plugged_in)
    : FakeDeviceBase(std::move(spec)), bed_(bed), handler_(umockdev_ioctl_base_new()) {
  g_signal_connect(handler_, "handle-ioctl", G_CALLBACK(&FakeUsbMarkerDevice::on_ioctl), this);
  if (plugged_in) plug();
}

FakeUsbMarkerDevice::~FakeUsbMarkerDevice() {
  if (plugged()) unplug();
  g_signal_handlers_disconnect_by_data(handler_, this);
  g_object_unref(handler_);
  for (auto* list : {&control_done_, &bulk_pending_, &returned_})
    for (void* urb : *list) g_object_unref(urb);
}

std::string FakeUsbMarkerDevice::syspath() const { return "/sys/devices/pci0000:00/usb1/1-" + spec_.port; }

std::string FakeUsbMarkerDevice::node() const { return fmt::format("/dev/bus/usb/001/{:03d}", address_); }

void FakeUsbMarkerDevice::plug() {
  address_ = next_usb_address++;
  const std::string node = this->node();
  const std::string record = fmt::format(
      "P: /devices/pci0000:00/usb1/1-{port}\nN: bus/usb/001/{address:03d}\n"
      "E: SUBSYSTEM=usb\nE: DEVTYPE=usb_device\nE: DEVNAME={node}\nE: BUSNUM=001\nE: DEVNUM={address:03d}\n"
      "A: busnum=1\\n\nA: devnum={address}\\n\nA: speed=12\\n\nA: dev=189:{address}\\n\nA: bConfigurationValue=1\\n\n"
      "A: idVendor={vendor:04x}\\n\nA: idProduct={product:04x}\\n\nA: serial={serial}\\n\nH: descriptors={descriptors}\n",
      fmt::arg("port", spec_.port), fmt::arg("address", address_), fmt::arg("node", node),
      fmt::arg("vendor", spec_.vendor_id), fmt::arg("product", spec_.product_id), fmt::arg("serial", spec_.serial),
      fmt::arg("descriptors", hex(usb_descriptors(spec_))));
  {
    std::lock_guard lock(mutex_);
    plugged_ = true;
    streaming_ = false;
  }
  // The handler first: the "add" event that add_from_string sends may be acted on at once.
  GError* error = nullptr;
  if (!umockdev_testbed_attach_ioctl(bed_.bed(), node.c_str(), handler_, &error) ||
      !umockdev_testbed_add_from_string(bed_.bed(), record.c_str(), &error))
    throw std::runtime_error(fmt::format("umockdev: {}", error ? error->message : "?"));
}

void FakeUsbMarkerDevice::unplug() {
  {
    std::lock_guard lock(mutex_);
    plugged_ = false;
    streaming_ = false;
    chunks_.clear();  // what the device had not sent yet is lost with it
    // The kernel kills the URBs in flight; they can still be reaped, with -ESHUTDOWN.
    for (auto* list : {&control_done_, &bulk_pending_}) {
      for (void* urb : *list) {
        reinterpret_cast<usbdevfs_urb*>(static_cast<UMockdevIoctlData*>(urb)->data)->status = -ESHUTDOWN;
        returned_.push_back(urb);
      }
      list->clear();
    }
    changed_.notify_all();
  }
  umockdev_testbed_uevent(bed_.bed(), syspath().c_str(), "remove");
  umockdev_testbed_remove_device(bed_.bed(), syspath().c_str());
}

int FakeUsbMarkerDevice::on_ioctl(UMockdevIoctlBase*, UMockdevIoctlClient* client, void* self) {
  return static_cast<FakeUsbMarkerDevice*>(self)->handle_ioctl(client);
}

// usbdevfs as the kernel answers it, for the calls libusb makes: capabilities, claiming,
// URBs submitted, reaped and discarded. Control URBs complete at once; bulk IN URBs when a
// chunk is queued and the device streams. A reap with nothing ready waits up to 2 ms
// first: the testbed's node is a regular file, always "ready" to poll(), so libusb's
// event loop would otherwise spin.
int FakeUsbMarkerDevice::handle_ioctl(UMockdevIoctlClient* client) {
  const gulong request = umockdev_ioctl_client_get_request(client);
  UMockdevIoctlData* arg = umockdev_ioctl_client_get_arg(client);
  std::unique_lock lock(mutex_);
  const bool reap = request == USBDEVFS_REAPURB || request == USBDEVFS_REAPURBNDELAY;
  // A node of an earlier plug is disconnected too: only reaping its killed URBs works.
  const bool connected = plugged_ && umockdev_ioctl_client_get_devnode(client) == node();
  if (!connected && !(reap && !returned_.empty())) {
    umockdev_ioctl_client_complete(client, -1, ENODEV);
    return TRUE;
  }
  switch (request) {
    case USBDEVFS_GET_CAPABILITIES: {
      UMockdevIoctlData* caps = resolve(arg, 0, sizeof(uint32_t));
      const uint32_t value = USBDEVFS_CAP_BULK_CONTINUATION | USBDEVFS_CAP_NO_PACKET_SIZE_LIM |
                             USBDEVFS_CAP_REAP_AFTER_DISCONNECT | USBDEVFS_CAP_ZERO_PACKET;
      std::memcpy(caps->data, &value, sizeof value);
      g_object_unref(caps);
      umockdev_ioctl_client_complete(client, 0, 0);
      return TRUE;
    }
    case USBDEVFS_CLAIMINTERFACE:
    case USBDEVFS_RELEASEINTERFACE:
    case USBDEVFS_DISCONNECT_CLAIM:
      umockdev_ioctl_client_complete(client, 0, 0);
      return TRUE;
    case USBDEVFS_SUBMITURB: {
      UMockdevIoctlData* urb_data = resolve(arg, 0, sizeof(usbdevfs_urb));
      auto* urb = reinterpret_cast<usbdevfs_urb*>(urb_data->data);
      if (urb->type == USBDEVFS_URB_TYPE_CONTROL) {
        UMockdevIoctlData* buffer = resolve(urb_data, offsetof(usbdevfs_urb, buffer), std::size_t(urb->buffer_length));
        const uint8_t* setup = buffer->data;
        const unsigned value = setup[2] | (setup[3] << 8), length = setup[6] | (setup[7] << 8);
        std::vector<uint8_t> reply;
        urb->status = 0;
        if (setup[0] == 0x80 && setup[1] == 6 && (value >> 8) == 3) {  // GET_DESCRIPTOR (string)
          reply = (value & 0xFF) == 0 ? std::vector<uint8_t>{4, 3, 0x09, 0x04}
                                      : string_descriptor((value & 0xFF) == 3 ? spec_.serial : "facecap fake");
        } else if (setup[0] == 0xC1 && setup[1] == proto::kRequestGetInfo) {
          const auto info = proto::encode_info(spec_.info);
          reply.assign(info.begin(), info.end());
        } else if (setup[0] == 0x41 && setup[1] == proto::kRequestControl) {
          on_control(std::vector<uint8_t>(setup + 8, setup + 8 + std::min<unsigned>(length, proto::kControlBytes)));
        } else {
          urb->status = -EPIPE;  // a request the device does not know: stall
        }
        reply.resize(std::min<std::size_t>(reply.size(), length));
        std::memcpy(buffer->data + 8, reply.data(), reply.size());
        // IN: what the device answered; OUT: everything the host sent was taken.
        urb->actual_length = int((setup[0] & 0x80) ? reply.size() : length);
        g_object_unref(buffer);
        control_done_.push_back(urb_data);
      } else {
        bulk_pending_.push_back(urb_data);
      }
      umockdev_ioctl_client_complete(client, 0, 0);
      return TRUE;
    }
    case USBDEVFS_DISCARDURB: {
      gulong address = 0;
      std::memcpy(&address, arg->data, sizeof address);
      const auto it = std::find_if(bulk_pending_.begin(), bulk_pending_.end(), [&](void* urb) {
        return static_cast<UMockdevIoctlData*>(urb)->client_addr == address;
      });
      if (it == bulk_pending_.end()) {
        umockdev_ioctl_client_complete(client, -1, EINVAL);
        return TRUE;
      }
      reinterpret_cast<usbdevfs_urb*>(static_cast<UMockdevIoctlData*>(*it)->data)->status = -ENOENT;
      returned_.push_back(*it);
      bulk_pending_.erase(it);
      umockdev_ioctl_client_complete(client, 0, 0);
      return TRUE;
    }
    case USBDEVFS_REAPURB:
    case USBDEVFS_REAPURBNDELAY: {
      changed_.wait_for(lock, std::chrono::milliseconds(2), [&] {
        return !control_done_.empty() || !returned_.empty() || (streaming_ && !chunks_.empty() && !bulk_pending_.empty());
      });
      UMockdevIoctlData* done = nullptr;
      for (auto* list : {&control_done_, &returned_}) {
        if (!done && !list->empty()) {
          done = static_cast<UMockdevIoctlData*>(list->front());
          list->pop_front();
        }
      }
      if (!done && streaming_ && !chunks_.empty() && !bulk_pending_.empty()) {
        done = static_cast<UMockdevIoctlData*>(bulk_pending_.front());
        bulk_pending_.pop_front();
        auto* urb = reinterpret_cast<usbdevfs_urb*>(done->data);
        const std::vector<uint8_t> chunk = std::move(chunks_.front());
        chunks_.pop_front();
        const std::size_t n = std::min(chunk.size(), std::size_t(urb->buffer_length));
        UMockdevIoctlData* buffer = resolve(done, offsetof(usbdevfs_urb, buffer), std::size_t(urb->buffer_length));
        std::memcpy(buffer->data, chunk.data(), n);
        g_object_unref(buffer);
        urb->actual_length = int(n);
        urb->status = 0;
        changed_.notify_all();  // wait_until_read()
      }
      if (!done) {
        umockdev_ioctl_client_complete(client, -1, EAGAIN);
        return TRUE;
      }
      UMockdevIoctlData* pointer = resolve(arg, 0, sizeof(void*));
      umockdev_ioctl_data_set_ptr(pointer, 0, done);
      g_object_unref(pointer);
      g_object_unref(done);
      umockdev_ioctl_client_complete(client, 0, 0);
      return TRUE;
    }
    default:
      umockdev_ioctl_client_complete(client, -1, ENOTTY);
      return TRUE;
  }
}

// -- HID ----------------------------------------------------------------------------------

FakeHidMarkerDevice::FakeHidMarkerDevice(Umockdev& bed, FakeDeviceSpec spec, bool plugged_in)
    : FakeDeviceBase(std::move(spec)), bed_(bed), handler_(umockdev_ioctl_base_new()) {
  g_signal_connect(handler_, "handle-ioctl", G_CALLBACK(&FakeHidMarkerDevice::on_ioctl), this);
  g_signal_connect(handler_, "handle-read", G_CALLBACK(&FakeHidMarkerDevice::on_read), this);
  if (plugged_in) plug();
}

FakeHidMarkerDevice::~FakeHidMarkerDevice() {
  if (plugged()) unplug();
  g_signal_handlers_disconnect_by_data(handler_, this);
  g_object_unref(handler_);
}

std::string FakeHidMarkerDevice::node() const { return fmt::format("/dev/hidraw{}", minor_); }

std::string FakeHidMarkerDevice::syspath() const {
  return fmt::format("/sys/devices/pci0000:00/usb1/1-{}/1-{}:1.0/0003:{:04X}:{:04X}.{:04X}", spec_.port, spec_.port,
                     spec_.vendor_id, spec_.product_id, minor_ + 1);
}

void FakeHidMarkerDevice::plug() {
  minor_ = next_hidraw_minor++;
  const std::string hid = syspath().substr(4);  // without "/sys"
  const std::string usb = fmt::format("/devices/pci0000:00/usb1/1-{}", spec_.port);
  const uint16_t usage_page = spec_.marker_interface ? proto::kHidUsagePage : 0xFF00;
  std::vector<uint8_t> descriptor = hid_report_descriptor(spec_);
  descriptor[1] = uint8_t(usage_page);
  descriptor[2] = uint8_t(usage_page >> 8);
  const std::string record = fmt::format(
      "P: {hid}/hidraw/hidraw{minor}\nN: hidraw{minor}\nE: SUBSYSTEM=hidraw\nE: DEVNAME=/dev/hidraw{minor}\n"
      "A: dev=245:{minor}\\n\nL: device=../../../{hidname}\n\n"
      "P: {hid}\nE: SUBSYSTEM=hid\nE: HID_ID=0003:{vendor:08X}:{product:08X}\nE: HID_NAME=facecap fake markers\n"
      "E: HID_UNIQ={serial}\nH: report_descriptor={descriptor}\n\n"
      "P: {usb}/1-{port}:1.0\nE: SUBSYSTEM=usb\nE: DEVTYPE=usb_interface\nA: bInterfaceNumber=00\\n\n\n"
      "P: {usb}\nE: SUBSYSTEM=usb\nE: DEVTYPE=usb_device\nA: manufacturer=facecap\\n\nA: product=fake markers\\n\n"
      "A: bcdDevice=0100\\n\n",
      fmt::arg("hid", hid), fmt::arg("minor", minor_), fmt::arg("hidname", hid.substr(hid.rfind('/') + 1)),
      fmt::arg("vendor", spec_.vendor_id), fmt::arg("product", spec_.product_id), fmt::arg("serial", spec_.serial),
      fmt::arg("descriptor", hex(descriptor)), fmt::arg("usb", usb), fmt::arg("port", spec_.port));
  {
    std::lock_guard lock(mutex_);
    plugged_ = true;
    streaming_ = false;
  }
  GError* error = nullptr;
  if (!umockdev_testbed_attach_ioctl(bed_.bed(), node().c_str(), handler_, &error) ||
      !umockdev_testbed_add_from_string(bed_.bed(), record.c_str(), &error))
    throw std::runtime_error(fmt::format("umockdev: {}", error ? error->message : "?"));
  // The node is a pty: one byte in it keeps poll() saying "readable", so hidapi always
  // goes on to read(), which on_read answers (waiting up to 2 ms for a report).
  const int pty = umockdev_testbed_get_dev_fd(bed_.bed(), node().c_str());
  const char token = 0;
  if (pty < 0 || write(pty, &token, 1) != 1) throw std::runtime_error("umockdev: no pty behind " + node());
}

void FakeHidMarkerDevice::unplug() {
  {
    std::lock_guard lock(mutex_);
    plugged_ = false;
    streaming_ = false;
    chunks_.clear();
    changed_.notify_all();
  }
  // The tree goes children first, each with its node and class links.
  const std::string usb = fmt::format("/sys/devices/pci0000:00/usb1/1-{}", spec_.port);
  const std::string hidraw = syspath() + fmt::format("/hidraw/hidraw{}", minor_);
  umockdev_testbed_uevent(bed_.bed(), hidraw.c_str(), "remove");
  for (const std::string& path : {hidraw, syspath(), usb + fmt::format("/1-{}:1.0", spec_.port), usb})
    umockdev_testbed_remove_device(bed_.bed(), path.c_str());
}

int FakeHidMarkerDevice::on_ioctl(UMockdevIoctlBase*, UMockdevIoctlClient* client, void* self_) {
  auto* self = static_cast<FakeHidMarkerDevice*>(self_);
  const gulong request = umockdev_ioctl_client_get_request(client);
  UMockdevIoctlData* arg = umockdev_ioctl_client_get_arg(client);
  const std::size_t size = _IOC_SIZE(request);
  std::lock_guard lock(self->mutex_);
  if (!self->plugged_) {
    umockdev_ioctl_client_complete(client, -1, ENODEV);
    return TRUE;
  }
  if (request == HIDIOCGRDESCSIZE) {
    UMockdevIoctlData* out = resolve(arg, 0, sizeof(int));
    const int bytes = int(hid_report_descriptor(self->spec_).size());
    std::memcpy(out->data, &bytes, sizeof bytes);
    g_object_unref(out);
    umockdev_ioctl_client_complete(client, 0, 0);
  } else if (_IOC_TYPE(request) == 'H' && (_IOC_NR(request) == 0x06 || _IOC_NR(request) == 0x07) && size > 1) {
    UMockdevIoctlData* report = resolve(arg, 0, size);
    long result = -1;
    if (_IOC_NR(request) == 0x07 && report->data[0] == proto::kHidInfoReport) {  // HIDIOCGFEATURE
      const auto info = proto::encode_info(self->spec_.info);
      result = long(std::min(size - 1, info.size()));
      std::memcpy(report->data + 1, info.data(), std::size_t(result));
      result += 1;
    } else if (_IOC_NR(request) == 0x06 && report->data[0] == proto::kHidControlReport) {  // HIDIOCSFEATURE
      self->on_control(std::vector<uint8_t>(report->data + 1, report->data + size));
      result = long(size);
    }
    g_object_unref(report);
    umockdev_ioctl_client_complete(client, result, result < 0 ? EINVAL : 0);
  } else {
    umockdev_ioctl_client_complete(client, -1, ENOTTY);
  }
  return TRUE;
}

int FakeHidMarkerDevice::on_read(UMockdevIoctlBase*, UMockdevIoctlClient* client, void* self_) {
  auto* self = static_cast<FakeHidMarkerDevice*>(self_);
  UMockdevIoctlData* arg = umockdev_ioctl_client_get_arg(client);
  std::unique_lock lock(self->mutex_);
  self->changed_.wait_for(lock, std::chrono::milliseconds(2), [&] {
    return !self->plugged_ || (self->streaming_ && !self->chunks_.empty());
  });
  if (!self->plugged_) {
    umockdev_ioctl_client_complete(client, -1, ENODEV);
  } else if (!self->streaming_ || self->chunks_.empty()) {
    umockdev_ioctl_client_complete(client, -1, EAGAIN);
  } else {
    // Input report 3: the chunk, zero-padded to the report's fixed size.
    std::vector<uint8_t> report(1 + self->spec_.info.max_chunk_bytes, 0);
    report[0] = proto::kHidChunkReport;
    const std::vector<uint8_t>& chunk = self->chunks_.front();
    std::copy_n(chunk.begin(), std::min(chunk.size(), report.size() - 1), report.begin() + 1);
    self->chunks_.pop_front();
    self->changed_.notify_all();
    const std::size_t n = std::min(report.size(), std::size_t(arg->data_len));
    std::memcpy(arg->data, report.data(), n);
    umockdev_ioctl_client_complete(client, long(n), 0);
  }
  return TRUE;
}

}  // namespace facecap::test
