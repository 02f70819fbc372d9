#pragma once
// Marker devices faked with umockdev, below libusb and hidapi: the drivers enumerate
// them through udev and sysfs, open their /dev nodes, and every ioctl, transfer and read
// they make is answered here as a device would (usbdevfs URBs for USB; feature reports
// and input reports for hidraw). Unplugging announces the removal to udev monitors (libusb's
// hot-plug thread hears it) and fails the open device's calls with ENODEV, as the kernel
// does; plugging in again adds it at a new address.
//
// The test binary must run with libumockdev-preload loaded: this file's constructor
// re-executes the binary under it once (so `build/tests/test_x` works directly); when the
// library is missing, Umockdev::active() is false and the tests skip with a message.
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <mutex>
#include <string>
#include <vector>

#include "formats/marker_device.hpp"

struct _UMockdevTestbed;
struct _UMockdevIoctlBase;
struct _UMockdevIoctlClient;

namespace facecap::test {

// A umockdev testbed: while it lives, /sys and the /dev nodes it creates are fakes.
class Umockdev {
 public:
  Umockdev();
  ~Umockdev();
  Umockdev(const Umockdev&) = delete;
  Umockdev& operator=(const Umockdev&) = delete;

  // Whether the preload library redirects this process's /sys (else tests must skip).
  bool active() const noexcept { return active_; }
  static std::string inactive_message();
  _UMockdevTestbed* bed() const noexcept { return bed_; }

 private:
  _UMockdevTestbed* bed_ = nullptr;
  bool active_ = false;
};

struct FakeDeviceSpec {
  uint16_t vendor_id = 0x1209;
  uint16_t product_id = 0x0001;
  std::string serial = "SN-1";
  std::string port = "1";                 // USB port on bus 1: sysfs name 1-<port>
  formats::device::DeviceInfo info;       // what the device answers to the info request
  bool marker_interface = true;           // false: some other device with the same ids
};

// What a fake device was asked (control blocks) and what it holds, safe from any thread.
class FakeDeviceBase {
 public:
  virtual ~FakeDeviceBase() = default;
  // Queues one chunk (one bulk packet, or one input report's payload); the device sends
  // queued chunks only while streaming, as a real one would.
  void send_chunk(std::vector<uint8_t> chunk);
  // `frame` as chunks of the info block's max_chunk_bytes.
  void send_frame(const formats::device::DeviceFrame& frame);
  bool streaming() const;
  uint32_t rate_mhz() const;               // from the last start control block
  int controls_received() const;
  std::size_t queued() const;
  // Waits until the host has read every queued chunk; false on timeout.
  bool wait_until_read(int64_t timeout_ns) const;
  bool plugged() const;
  const FakeDeviceSpec& spec() const noexcept { return spec_; }

 protected:
  explicit FakeDeviceBase(FakeDeviceSpec spec);
  void on_control(const std::vector<uint8_t>& block);

  FakeDeviceSpec spec_;
  mutable std::mutex mutex_;
  mutable std::condition_variable changed_;
  std::deque<std::vector<uint8_t>> chunks_;
  bool streaming_ = false;
  bool plugged_ = false;
  uint32_t rate_mhz_ = 0;
  int controls_ = 0;
};

// A full-speed USB device: one vendor interface (class ff/46/01 unless spec says otherwise)
// with a bulk IN endpoint of 64-byte packets, its serial in string descriptor 3.
class FakeUsbMarkerDevice final : public FakeDeviceBase {
 public:
  // plugged_in false: the device is made, but not there until plug().
  FakeUsbMarkerDevice(Umockdev& bed, FakeDeviceSpec spec, bool plugged_in = true);
  ~FakeUsbMarkerDevice() override;

  void plug();    // appears at a new address and is announced
  void unplug();  // removal announced; calls on it fail with ENODEV from now on
  std::string node() const;  // /dev/bus/usb/001/<address>

 private:
  struct Urb;
  static int on_ioctl(_UMockdevIoctlBase* handler, _UMockdevIoctlClient* client, void* self);
  int handle_ioctl(_UMockdevIoctlClient* client);
  std::string syspath() const;

  Umockdev& bed_;
  _UMockdevIoctlBase* handler_ = nullptr;
  int address_ = 0;
  // UMockdevIoctlData of URBs: control ones answered, bulk IN ones waiting for a chunk, and
  // ones returned without data (discarded, or killed by an unplug).
  std::deque<void*> control_done_, bulk_pending_, returned_;
};

// A HID device behind hidraw: usage page 0xFF46, feature reports 1 (info) and 2
// (control), input report 3 (one chunk, zero-padded to max_chunk_bytes).
class FakeHidMarkerDevice final : public FakeDeviceBase {
 public:
  FakeHidMarkerDevice(Umockdev& bed, FakeDeviceSpec spec, bool plugged_in = true);
  ~FakeHidMarkerDevice() override;

  void plug();    // appears as the next /dev/hidrawN
  void unplug();  // reads and feature requests fail with ENODEV from now on
  std::string node() const;

 private:
  static int on_ioctl(_UMockdevIoctlBase* handler, _UMockdevIoctlClient* client, void* self);
  static int on_read(_UMockdevIoctlBase* handler, _UMockdevIoctlClient* client, void* self);
  std::string syspath() const;

  Umockdev& bed_;
  _UMockdevIoctlBase* handler_ = nullptr;
  int minor_ = -1;
};

}  // namespace facecap::test
