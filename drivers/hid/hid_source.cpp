#include "drivers/hid/hid_source.hpp"

#include <algorithm>
#include <array>
#include <cwchar>

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <hidapi/hidapi.h>
#include <spdlog/spdlog.h>

#include "core/error.hpp"
#include "core/time.hpp"

namespace facecap::drivers {
namespace {

namespace proto = formats::device;

constexpr int kReadTimeoutMs = 50;  // the read thread checks its state this often
constexpr int64_t kScanIntervalNs = 250 * kNsPerMs;
constexpr std::size_t kMaxReportBytes = 4096;  // hidraw's largest report

// hidapi's wide strings (serial numbers, errors) as UTF-8; they are ASCII in practice.
std::string narrow(const wchar_t* text) {
  std::string out;
  for (; text && *text; ++text) out += *text < 0x80 ? char(*text) : '?';
  return out;
}

}  // namespace

HidSource::HidSource(MarkerDeviceOptions options, std::vector<std::string> labels)
    : MarkerDeviceSource(DriverId::kHid, std::move(options), std::move(labels)) {}

HidSource::~HidSource() {
  stop();
  close_device();
  if (hidapi_started_) hid_exit();
}

void HidSource::open() {
  if (!hidapi_started_) {
    if (hid_init() != 0) throw Error(fmt::format("the hid driver could not start hidapi: {}", narrow(hid_error(nullptr))));
    hidapi_started_ = true;
  }
  if (!device_ && !open_device()) {
    if (!options_.wait_for_device)
      throw Error(fmt::format(
          "no usable HID marker device {} found{}. The hid driver needs a device speaking the facecap marker-device "
          "protocol (usage page 0xFF46, usage 1, docs/usb-hid-protocol.md) plugged in and readable by this user (a "
          "udev rule for /dev/hidraw*), or source.hid.wait_for_device = true to wait for one",
          wanted_device(), problems_.empty() ? "" : fmt::format(" ({})", fmt::join(problems_, "; "))));
    spdlog::warn("hid: no marker device {} yet; waiting for it (source.hid.wait_for_device)", wanted_device());
  }
  report(monotonic_now_ns());
}

bool HidSource::open_device() {
  std::vector<std::string> problems;
  auto refuse = [&](std::string problem) {
    if (std::find(problems_.begin(), problems_.end(), problem) == problems_.end()) spdlog::warn("hid: {}", problem);
    problems.push_back(std::move(problem));
  };
  hid_device_info* list = hid_enumerate(uint16_t(options_.vendor_id), uint16_t(options_.product_id));
  for (const hid_device_info* d = list; d && !device_; d = d->next) {
    if (d->usage_page != proto::kHidUsagePage || d->usage != proto::kHidUsage) continue;  // not a marker device
    const std::string serial = narrow(d->serial_number);
    if (!serial_matches(serial)) continue;
    const std::string where = fmt::format("{:04x}:{:04x}{} at {}", d->vendor_id, d->product_id,
                                          serial.empty() ? "" : " serial " + serial, d->path);
    hid_device* handle = hid_open_path(d->path);
    if (!handle) {
      refuse(fmt::format("cannot open {}: {} (a udev rule must give this user read-write access)", where,
                         narrow(hid_error(nullptr))));
      continue;
    }
    std::array<uint8_t, 1 + proto::kInfoBytes> report{proto::kHidInfoReport};
    try {
      const int got = hid_get_feature_report(handle, report.data(), report.size());
      if (got < 1) throw Error(fmt::format("the info report could not be read: {}", narrow(hid_error(handle))));
      const proto::DeviceInfo info = proto::parse_info(std::span(report).subspan(1, std::size_t(got) - 1), "hid " + where);
      start_control(info);  // a rate the device cannot go at refuses it here
      device_ = handle;
      info_block_ = info;
      device_opened(info, where);
    } catch (const Error& e) {
      refuse(fmt::format("{} refused: {}", where, e.what()));
      hid_close(handle);
    }
  }
  hid_free_enumeration(list);
  problems_ = std::move(problems);
  return device_ != nullptr;
}

bool HidSource::send_control(const proto::Control& control) {
  std::array<uint8_t, 1 + proto::kControlBytes> report{proto::kHidControlReport};
  const auto block = proto::encode_control(control);
  std::copy(block.begin(), block.end(), report.begin() + 1);
  return hid_send_feature_report(device_, report.data(), report.size()) == int(report.size());
}

void HidSource::close_device() noexcept {
  if (device_) hid_close(device_);
  device_ = nullptr;
}

void HidSource::start(const SourceStart& start) {
  if (start.lockstep) throw Error("the hid source runs on the device's clock and cannot run in lockstep");
  stop();
  running_.store(true);
  thread_ = start_driver_thread(start, [this] { run(); });
}

void HidSource::stop() noexcept {
  running_.store(false);
  if (thread_.joinable()) thread_.join();
}

// The read thread: one input report at a time, each one chunk; reopens a device that went
// away, and reports. Not RT-safe (it logs).
void HidSource::run() {
  std::vector<uint8_t> buffer(kMaxReportBytes);
  auto lose = [&](const std::string& why) {
    device_lost(why);
    close_device();
  };
  if (device_ && !send_control(start_control(info_block_))) lose("the start report was refused");
  int64_t next_scan_ns = 0;
  while (running_.load(std::memory_order_relaxed)) {
    const int64_t now_ns = monotonic_now_ns();
    if (device_) {
      const int got = hid_read_timeout(device_, buffer.data(), buffer.size(), kReadTimeoutMs);
      if (got < 0) {
        lose(narrow(hid_error(device_)));
      } else if (got > 0 && buffer[0] == proto::kHidChunkReport) {
        receive(std::span<const uint8_t>(buffer.data() + 1, std::size_t(got) - 1), true);
      } else if (got > 0) {
        errors_.fetch_add(1, std::memory_order_relaxed);  // a report id the protocol does not send
      }
    } else if (now_ns >= next_scan_ns) {
      if (open_device() && !send_control(start_control(info_block_))) lose("the start report was refused");
      next_scan_ns = now_ns + kScanIntervalNs;
    } else {
      sleep_until(std::min(next_scan_ns, now_ns + kReadTimeoutMs * kNsPerMs));
    }
    report(monotonic_now_ns());
  }
  if (device_) send_control({proto::Command::kStop, 0});
  close_device();
}

}  // namespace facecap::drivers
