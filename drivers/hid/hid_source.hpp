#pragma once
// A marker device sending HID reports, through hidapi's hidraw backend
// (docs/usb-hid-protocol.md). open() finds the device (vendor/product id, serial, and the
// protocol's usage page), reads the info block (feature report 1); start() asks it to
// stream (feature report 2) and a thread reads input reports (id 3, one chunk each),
// reassembling frames. hidapi has no hot-plug events: a device that disappears is looked
// for again every quarter second and reopened when it returns, while facecapd keeps
// running; health().state says what is going on meanwhile.
#include <atomic>
#include <string>
#include <thread>
#include <vector>

#include "drivers/device/marker_device_source.hpp"

struct hid_device_;

namespace facecap::drivers {

class HidSource final : public MarkerDeviceSource {
 public:
  // labels: one slot per device marker id (the calibration's markers). Not RT-safe.
  HidSource(MarkerDeviceOptions options, std::vector<std::string> labels);
  ~HidSource() override;

  // Throws Error when the device is absent and options.wait_for_device is false, naming
  // the device wanted and what the driver needs. Not RT-safe.
  void open() override;
  void start(const SourceStart& start) override;
  void stop() noexcept override;

 private:
  // Finds and opens the device; false when it is not there.
  bool open_device();
  void close_device() noexcept;
  bool send_control(const formats::device::Control& control);
  void run();

  hid_device_* device_ = nullptr;
  formats::device::DeviceInfo info_block_;
  std::vector<std::string> problems_;  // why the last scan opened nothing (permissions, ...)
  bool hidapi_started_ = false;
  std::thread thread_;
  std::atomic<bool> running_{false};
};

}  // namespace facecap::drivers
