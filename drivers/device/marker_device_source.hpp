#pragma once
// What the usb and hid drivers share (docs/usb-hid-protocol.md): which device the options
// select, what its info block means for the frames, reassembly of its chunks into frames,
// their conversion into the mailbox, the counters, and the state line an operator reads
// (waiting for the device, lost, back after a gap). A transport (UsbSource, HidSource)
// moves the bytes and calls the protected hooks from its own thread.
//
// Marker identity: device marker id k fills slot k, whose label is the k-th marker of the
// calibration facecapd solves with (SourceContext::markers), so a device that tracks a
// fixed marker set reports it in calibration order. Ids past the slots are counted and
// ignored. Positions are converted to millimetres, whatever units the device sends.
#include <atomic>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "drivers/api/driver_id.hpp"
#include "drivers/api/marker_source.hpp"
#include "drivers/api/source_config.hpp"
#include "formats/marker_device.hpp"

namespace facecap::drivers {

class MarkerDeviceSource : public MailboxSource {
 public:
  const SourceInfo& info() const noexcept override { return info_; }
  // "usb marker device 1209:0001 serial SN1: 52 markers at 120 Hz in mm, protocol 1.0". Not RT-safe.
  std::string description() const override;

  // Markers the device sent with ids past the frame's slots, and frames dropped for a bad
  // CRC, a lost chunk or a malformed body (also counted in health().errors). RT-safe.
  uint64_t markers_ignored() const noexcept { return markers_ignored_.load(std::memory_order_relaxed); }
  uint64_t frames_dropped() const noexcept { return frames_dropped_.load(std::memory_order_relaxed); }

 protected:
  // transport: kUsb or kHid; labels: one slot per marker id (the calibration's markers).
  // Not RT-safe.
  MarkerDeviceSource(DriverId transport, MarkerDeviceOptions options, std::vector<std::string> labels);

  // "1209:0001 serial SN1", "any vendor's" ... for messages. Not RT-safe.
  std::string wanted_device() const;
  // Whether a device of these ids and serial is the one the options select. RT-safe.
  bool matches(uint16_t vendor_id, uint16_t product_id) const noexcept;
  bool serial_matches(std::string_view serial) const noexcept;
  // The control block that starts streaming at the configured rate. Throws Error when the
  // device cannot go that fast. Not RT-safe.
  formats::device::Control start_control(const formats::device::DeviceInfo& device) const;

  // The transport opened a device (`identity`: "1209:0001 serial SN1 on bus 1 address 2")
  // and read its info block: sizes the reassembly. Transport thread (or open()). Not RT-safe.
  void device_opened(const formats::device::DeviceInfo& device, std::string identity);
  // The device went away (`why`: the library's words). Transport thread. Not RT-safe.
  void device_lost(std::string_view why);
  bool device_present() const noexcept { return current_.has_value(); }

  // Bytes from the device: one bulk transfer (chunks back to back) or one HID report's
  // payload (one chunk, padding after it ignored). Complete frames go to the mailbox.
  // Transport thread. RT-safe: no allocation, lock or text; problems are counted.
  void receive(std::span<const uint8_t> bytes, bool single_chunk) noexcept;

  // What an operator should hear, called by the transport's loop every few tens of ms: the
  // state line while the device is absent (and for how long), the gap once frames resume
  // after a loss, dropped frames (logged at most once a second). Not RT-safe.
  void report(int64_t now_ns);

  MarkerDeviceOptions options_;

 private:
  void publish(std::span<const uint8_t> body) noexcept;
  std::string device_name() const;  // "usb marker device 1209:0001 serial SN1"

  DriverId transport_;
  SourceInfo info_;
  // Transport thread only, besides description() before start() and after stop().
  std::optional<formats::device::DeviceInfo> current_;       // the device open now
  std::optional<formats::device::DeviceInfo> last_info_;  // the last one opened
  std::string identity_;
  formats::device::FrameAssembler assembler_{0};
  formats::device::DeviceFrame scratch_;
  double to_mm_ = 1.0;                // device units to millimetres
  int64_t waiting_since_ns_ = 0;      // device absent since (lost, or at start)
  std::string lost_why_;
  bool lost_ = false;                 // absent after having been open
  bool gap_pending_ = false;          // reopened after a loss; the gap is reported with the first frame
  int64_t gap_start_ns_ = 0;          // receive time of the last frame before the loss
  int64_t gap_start_frame_no_ = -1;
  int64_t gap_end_ns_ = 0, gap_end_frame_no_ = -1;
  int64_t last_frame_no_ = -1;        // the wire's 32-bit numbers extended to 64 bits
  int64_t last_receive_ns_ = 0;
  int64_t state_written_ns_ = 0;
  uint64_t dropped_logged_ = 0;       // frames_dropped_ when last logged
  int64_t drops_logged_ns_ = 0;
  formats::device::DeviceError last_error_ = formats::device::DeviceError::kNone;
  std::atomic<uint64_t> markers_ignored_{0};
  std::atomic<uint64_t> frames_dropped_{0};
};

}  // namespace facecap::drivers
