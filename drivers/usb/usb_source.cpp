#include "drivers/usb/usb_source.hpp"

#include <algorithm>
#include <array>
#include <vector>

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <libusb.h>
#include <spdlog/spdlog.h>

#include "core/error.hpp"
#include "core/time.hpp"

namespace facecap::drivers {
namespace {

namespace proto = formats::device;

constexpr int kTransfers = 4;                 // bulk IN transfers kept in flight
constexpr int kPacketsPerTransfer = 8;        // each a multiple of the endpoint's packet size
constexpr unsigned kControlTimeoutMs = 1000;
// bmRequestType of the protocol's vendor requests to the interface.
constexpr uint8_t kVendorFromDevice =
    uint8_t(LIBUSB_ENDPOINT_IN) | uint8_t(LIBUSB_REQUEST_TYPE_VENDOR) | uint8_t(LIBUSB_RECIPIENT_INTERFACE);
constexpr uint8_t kVendorToDevice =
    uint8_t(LIBUSB_ENDPOINT_OUT) | uint8_t(LIBUSB_REQUEST_TYPE_VENDOR) | uint8_t(LIBUSB_RECIPIENT_INTERFACE);
constexpr int64_t kEventSliceUs = 50'000;     // the event thread checks its state this often
constexpr int64_t kScanIntervalNs = 500 * kNsPerMs;             // without hot-plug events
constexpr int64_t kHotplugScanIntervalNs = 2 * kNsPerSecond;    // with them: a retry after a failed open
constexpr int64_t kStopDrainNs = kNsPerSecond;

std::string usb_error(int code) { return fmt::format("{} ({})", libusb_strerror(code), libusb_error_name(code)); }

// The interface and bulk IN endpoint of the protocol in the device's active (else first)
// configuration.
struct Endpoint {
  int interface = -1;
  uint8_t address = 0;
  int packet_bytes = 0;
};

Endpoint find_marker_endpoint(libusb_device* device) {
  libusb_config_descriptor* config = nullptr;
  if (libusb_get_active_config_descriptor(device, &config) != 0 && libusb_get_config_descriptor(device, 0, &config) != 0)
    return {};
  Endpoint found;
  for (int i = 0; i < config->bNumInterfaces && found.interface < 0; ++i) {
    const libusb_interface& interface = config->interface[i];
    for (int a = 0; a < interface.num_altsetting && found.interface < 0; ++a) {
      const libusb_interface_descriptor& alt = interface.altsetting[a];
      if (alt.bInterfaceClass != proto::kUsbInterfaceClass || alt.bInterfaceSubClass != proto::kUsbInterfaceSubclass ||
          alt.bInterfaceProtocol != proto::kUsbInterfaceProtocol)
        continue;
      for (int e = 0; e < alt.bNumEndpoints; ++e) {
        const libusb_endpoint_descriptor& ep = alt.endpoint[e];
        if ((ep.bEndpointAddress & LIBUSB_ENDPOINT_DIR_MASK) == LIBUSB_ENDPOINT_IN &&
            (ep.bmAttributes & LIBUSB_TRANSFER_TYPE_MASK) == LIBUSB_TRANSFER_TYPE_BULK) {
          found = {alt.bInterfaceNumber, ep.bEndpointAddress, ep.wMaxPacketSize & 0x7FF};
          break;
        }
      }
    }
  }
  libusb_free_config_descriptor(config);
  return found;
}

}  // namespace

// The open device: its handle, interface, and the transfers that read it.
struct UsbSource::Device {
  libusb_device_handle* handle = nullptr;
  libusb_device* device = nullptr;  // referenced while open, to recognise its removal
  Endpoint endpoint;
  proto::DeviceInfo info;
  std::vector<libusb_transfer*> transfers;
  std::vector<std::vector<uint8_t>> buffers;
  int in_flight = 0;
  bool lost = false;  // gone: transfers are not resubmitted, the handle closes once they are back
};

struct UsbSource::Callbacks {
  static void LIBUSB_CALL transfer(libusb_transfer* transfer) {
    static_cast<UsbSource*>(transfer->user_data)->on_transfer(transfer);
  }
  static int LIBUSB_CALL hotplug(libusb_context*, libusb_device* device, libusb_hotplug_event event, void* self) {
    static_cast<UsbSource*>(self)->on_hotplug(device, event == LIBUSB_HOTPLUG_EVENT_DEVICE_ARRIVED);
    return 0;  // stay registered
  }
};

UsbSource::UsbSource(MarkerDeviceOptions options, std::vector<std::string> labels)
    : MarkerDeviceSource(DriverId::kUsb, std::move(options), std::move(labels)) {}

UsbSource::~UsbSource() {
  stop();
  // Transfers that never came back (a device that stopped answering) must not be freed
  // under libusb: they and the context are left to the process's end.
  if (device_ && device_->in_flight > 0) return;
  close_device();
  if (context_) {
    if (hotplug_) libusb_hotplug_deregister_callback(context_, hotplug_handle_);
    libusb_exit(context_);
  }
}

void UsbSource::open() {
  if (!context_) {
    if (const int r = libusb_init(&context_); r != 0) {
      context_ = nullptr;
      throw Error(fmt::format("the usb driver could not start libusb: {}", usb_error(r)));
    }
    if (libusb_has_capability(LIBUSB_CAP_HAS_HOTPLUG)) {
      hotplug_ = libusb_hotplug_register_callback(
                     context_, LIBUSB_HOTPLUG_EVENT_DEVICE_ARRIVED | LIBUSB_HOTPLUG_EVENT_DEVICE_LEFT,
                     LIBUSB_HOTPLUG_NO_FLAGS, options_.vendor_id ? int(options_.vendor_id) : LIBUSB_HOTPLUG_MATCH_ANY,
                     options_.product_id ? int(options_.product_id) : LIBUSB_HOTPLUG_MATCH_ANY,
                     LIBUSB_HOTPLUG_MATCH_ANY, &Callbacks::hotplug, this, &hotplug_handle_) == LIBUSB_SUCCESS;
    }
    if (!hotplug_) spdlog::info("usb: libusb has no hot-plug events here; scanning for the device every {} ms instead",
                                kScanIntervalNs / kNsPerMs);
  }
  if (!device_ && !open_device()) {
    if (!options_.wait_for_device)
      throw Error(fmt::format(
          "no usable USB marker device {} found{}. The usb driver needs a device speaking the facecap marker-device "
          "protocol (interface class ff/46/01, docs/usb-hid-protocol.md) plugged in and readable by this user (a "
          "udev rule for /dev/bus/usb), or source.usb.wait_for_device = true to wait for one",
          wanted_device(), problems_.empty() ? "" : fmt::format(" ({})", fmt::join(problems_, "; "))));
    spdlog::warn("usb: no marker device {} yet; waiting for it (source.usb.wait_for_device)", wanted_device());
  }
  report(monotonic_now_ns());
}

bool UsbSource::open_device() {
  std::vector<std::string> problems;
  // Said once, not at every scan while waiting.
  auto refuse = [&](std::string problem) {
    if (std::find(problems_.begin(), problems_.end(), problem) == problems_.end()) spdlog::warn("usb: {}", problem);
    problems.push_back(std::move(problem));
  };
  libusb_device** list = nullptr;
  const ssize_t count = libusb_get_device_list(context_, &list);
  if (count < 0) {
    spdlog::warn("usb: cannot list devices: {}", usb_error(int(count)));
    return false;
  }
  bool opened = false;
  for (ssize_t i = 0; i < count && !opened; ++i) {
    libusb_device* candidate = list[i];
    libusb_device_descriptor descriptor{};
    if (libusb_get_device_descriptor(candidate, &descriptor) != 0 || !matches(descriptor.idVendor, descriptor.idProduct))
      continue;
    const Endpoint endpoint = find_marker_endpoint(candidate);
    if (endpoint.interface < 0) continue;  // not a marker device
    const std::string where = fmt::format("{:04x}:{:04x} on bus {} address {}", descriptor.idVendor,
                                          descriptor.idProduct, libusb_get_bus_number(candidate),
                                          libusb_get_device_address(candidate));
    libusb_device_handle* handle = nullptr;
    if (const int r = libusb_open(candidate, &handle); r != 0) {
      refuse(fmt::format("cannot open {}: {}{}", where, usb_error(r),
                         r == LIBUSB_ERROR_ACCESS ? ", a udev rule must give this user read-write access" : ""));
      continue;
    }
    std::array<unsigned char, 128> serial{};
    if (descriptor.iSerialNumber != 0) {
      if (const int r = libusb_get_string_descriptor_ascii(handle, descriptor.iSerialNumber, serial.data(),
                                                           int(serial.size() - 1));
          r < 0) {
        if (!options_.serial.empty()) refuse(fmt::format("cannot read the serial number of {}: {}", where, usb_error(r)));
        serial[0] = 0;
      }
    }
    const std::string serial_text(reinterpret_cast<const char*>(serial.data()));
    if (!serial_matches(serial_text)) {
      libusb_close(handle);
      continue;
    }
    libusb_set_auto_detach_kernel_driver(handle, 1);  // unsupported on some platforms: then nothing to detach
    if (const int r = libusb_claim_interface(handle, endpoint.interface); r != 0) {
      refuse(fmt::format("cannot claim interface {} of {}: {}", endpoint.interface, where, usb_error(r)));
      libusb_close(handle);
      continue;
    }
    std::array<uint8_t, proto::kInfoBytes> info_bytes{};
    const int got = libusb_control_transfer(
        handle, kVendorFromDevice, proto::kRequestGetInfo, 0,
        uint16_t(endpoint.interface), info_bytes.data(), uint16_t(info_bytes.size()), kControlTimeoutMs);
    const std::string identity = serial_text.empty() ? where : fmt::format("{} serial {}", where, serial_text);
    try {
      if (got < 0) throw Error(fmt::format("the info request failed: {}", usb_error(got)));
      const proto::DeviceInfo info = proto::parse_info(std::span(info_bytes).first(std::size_t(got)), "usb " + identity);
      start_control(info);  // a rate the device cannot go at refuses it here, not when streaming starts
      device_ = std::make_unique<Device>();
      device_->handle = handle;
      device_->device = libusb_ref_device(candidate);
      device_->endpoint = endpoint;
      device_->info = info;
      device_opened(info, identity);
      opened = true;
    } catch (const Error& e) {
      refuse(fmt::format("{} refused: {}", identity, e.what()));
      libusb_release_interface(handle, endpoint.interface);
      libusb_close(handle);
    }
  }
  libusb_free_device_list(list, 1);
  problems_ = std::move(problems);
  return opened;
}

bool UsbSource::begin_streaming() {
  Device& d = *device_;
  const auto control = proto::encode_control(start_control(d.info));
  const int sent = libusb_control_transfer(
      d.handle, kVendorToDevice, proto::kRequestControl,
      0, uint16_t(d.endpoint.interface), const_cast<uint8_t*>(control.data()), uint16_t(control.size()),
      kControlTimeoutMs);
  if (sent != int(control.size())) {
    d.lost = true;
    device_lost(sent < 0 ? usb_error(sent) : "short control transfer");
    return false;
  }
  const int bytes = std::max(d.endpoint.packet_bytes, 64) * kPacketsPerTransfer;
  d.buffers.assign(kTransfers, std::vector<uint8_t>(std::size_t(bytes)));
  for (int i = 0; i < kTransfers; ++i) {
    libusb_transfer* transfer = libusb_alloc_transfer(0);
    d.transfers.push_back(transfer);
    libusb_fill_bulk_transfer(transfer, d.handle, d.endpoint.address, d.buffers[std::size_t(i)].data(), bytes,
                              &Callbacks::transfer, this, 0);
    if (const int r = libusb_submit_transfer(transfer); r != 0) {
      d.lost = true;
      device_lost(usb_error(r));
      return false;
    }
    ++d.in_flight;
  }
  return true;
}

void UsbSource::on_transfer(libusb_transfer* transfer) noexcept {
  Device& d = *device_;
  --d.in_flight;
  switch (transfer->status) {
    case LIBUSB_TRANSFER_COMPLETED:
      receive(std::span<const uint8_t>(transfer->buffer, std::size_t(transfer->actual_length)), false);
      break;
    case LIBUSB_TRANSFER_TIMED_OUT:
    case LIBUSB_TRANSFER_CANCELLED:
      break;
    case LIBUSB_TRANSFER_OVERFLOW:
      errors_.fetch_add(1, std::memory_order_relaxed);  // more than a transfer holds: its chunks are lost
      break;
    default:  // NO_DEVICE, ERROR, STALL
      if (!d.lost) {
        d.lost = true;
        device_lost(transfer->status == LIBUSB_TRANSFER_NO_DEVICE ? "unplugged" : libusb_error_name(transfer->status));
      }
      return;
  }
  if (d.lost || !running_.load(std::memory_order_relaxed) || transfer->status == LIBUSB_TRANSFER_CANCELLED) return;
  if (const int r = libusb_submit_transfer(transfer); r == 0) {
    ++d.in_flight;
  } else {
    d.lost = true;
    device_lost(r == LIBUSB_ERROR_NO_DEVICE ? "unplugged" : usb_error(r));
  }
}

void UsbSource::on_hotplug(libusb_device* device, bool arrived) noexcept {
  if (arrived) {
    arrived_.store(true, std::memory_order_relaxed);
  } else if (device_ && device_->device == device && !device_->lost) {
    device_->lost = true;
    device_lost("unplugged");
    for (libusb_transfer* transfer : device_->transfers) libusb_cancel_transfer(transfer);
  }
}

void UsbSource::close_device() noexcept {
  if (!device_) return;
  for (libusb_transfer* transfer : device_->transfers) libusb_free_transfer(transfer);
  libusb_release_interface(device_->handle, device_->endpoint.interface);
  libusb_close(device_->handle);
  libusb_unref_device(device_->device);
  device_.reset();
}

void UsbSource::start(const SourceStart& start) {
  if (start.lockstep) throw Error("the usb source runs on the device's clock and cannot run in lockstep");
  stop();
  running_.store(true);
  thread_ = start_driver_thread(start, [this] { run(); });
}

void UsbSource::stop() noexcept {
  running_.store(false);
  if (thread_.joinable()) thread_.join();
}

// libusb's event thread: completes transfers (and so reassembles frames), reopens a
// device that went away, and reports. Not RT-safe (it logs).
void UsbSource::run() {
  if (device_ && !begin_streaming()) spdlog::warn("usb: the device did not start streaming; waiting for it again");
  int64_t next_scan_ns = monotonic_now_ns() + kScanIntervalNs;
  while (running_.load(std::memory_order_relaxed)) {
    timeval slice{0, kEventSliceUs};
    libusb_handle_events_timeout_completed(context_, &slice, nullptr);
    const int64_t now_ns = monotonic_now_ns();
    if (device_ && device_->lost && device_->in_flight == 0) close_device();
    const bool arrived = arrived_.exchange(false, std::memory_order_relaxed);
    if (!device_ && (arrived || now_ns >= next_scan_ns)) {
      if (open_device()) begin_streaming();
      next_scan_ns = now_ns + (hotplug_ ? kHotplugScanIntervalNs : kScanIntervalNs);
    }
    report(now_ns);
  }
  if (!device_) return;
  if (!device_->lost) {  // ask the device to stop; then take every transfer back before closing
    const auto control = proto::encode_control({proto::Command::kStop, 0});
    libusb_control_transfer(device_->handle,
                            kVendorToDevice,
                            proto::kRequestControl, 0, uint16_t(device_->endpoint.interface),
                            const_cast<uint8_t*>(control.data()), uint16_t(control.size()), kControlTimeoutMs);
  }
  for (libusb_transfer* transfer : device_->transfers) libusb_cancel_transfer(transfer);
  const int64_t give_up_ns = monotonic_now_ns() + kStopDrainNs;
  while (device_->in_flight > 0 && monotonic_now_ns() < give_up_ns) {
    timeval slice{0, kEventSliceUs};
    libusb_handle_events_timeout_completed(context_, &slice, nullptr);
  }
  if (device_->in_flight == 0) close_device();
  else spdlog::warn("usb: {} transfers did not come back; the device is left open", device_->in_flight);
}

}  // namespace facecap::drivers
