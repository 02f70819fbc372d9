#pragma once
// A marker device on USB bulk transfers, through libusb-1.0 (docs/usb-hid-protocol.md).
// open() finds the device (vendor/product id, serial, and the protocol's interface class),
// claims its interface and reads the info block; start() asks it to stream and keeps
// several bulk IN transfers in flight on libusb's event thread, which also reassembles
// chunks into frames. A device that disappears is reopened when it returns (libusb hot-plug
// callbacks where the platform has them, else a scan every half second) while facecapd
// keeps running; health().state says what is going on meanwhile.
#include <atomic>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "drivers/device/marker_device_source.hpp"

struct libusb_context;
struct libusb_device;
struct libusb_transfer;

namespace facecap::drivers {

class UsbSource final : public MarkerDeviceSource {
 public:
  // labels: one slot per device marker id (the calibration's markers). Not RT-safe.
  UsbSource(MarkerDeviceOptions options, std::vector<std::string> labels);
  ~UsbSource() override;

  // Throws Error when the device is absent and options.wait_for_device is false, naming
  // the device wanted and what the driver needs. Not RT-safe.
  void open() override;
  void start(const SourceStart& start) override;
  void stop() noexcept override;

  // Whether libusb reports device arrival and removal here (else the driver scans).
  bool hotplug() const noexcept { return hotplug_ != 0; }

 private:
  struct Device;

  // Finds and opens the device; false when it is not there. Logs what it skipped.
  bool open_device();
  void close_device() noexcept;
  // Sends the start control block and submits the transfers. False (device lost) on failure.
  bool begin_streaming();
  void run();
  void on_transfer(libusb_transfer* transfer) noexcept;
  void on_hotplug(libusb_device* device, bool arrived) noexcept;
  struct Callbacks;  // libusb's C callbacks, into the two above

  libusb_context* context_ = nullptr;
  int hotplug_handle_ = 0;
  int hotplug_ = 0;
  std::unique_ptr<Device> device_;  // the open device, its transfers; event thread after start()
  std::vector<std::string> problems_;  // why the last scan opened nothing (permissions, ...)
  std::atomic<bool> arrived_{false};  // hot-plug: a matching device was plugged in
  std::thread thread_;
  std::atomic<bool> running_{false};
};

}  // namespace facecap::drivers
