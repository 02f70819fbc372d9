#include "drivers/device/marker_device_source.hpp"

#include <cmath>
#include <limits>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include "core/error.hpp"
#include "core/time.hpp"

namespace facecap::drivers {
namespace {

using formats::device::DeviceInfo;
using formats::device::FrameAssembler;

constexpr int64_t kStateRefreshNs = 250 * kNsPerMs;
constexpr int64_t kDropLogIntervalNs = kNsPerSecond;

double millimetres_per_unit(formats::device::Units units) {
  switch (units) {
    case formats::device::Units::kMillimetres: return 1.0;
    case formats::device::Units::kCentimetres: return 10.0;
    case formats::device::Units::kMetres: return 1000.0;
  }
  return 1.0;
}

double seconds(int64_t ns) { return double(ns) / kNsPerSecond; }

}  // namespace

MarkerDeviceSource::MarkerDeviceSource(DriverId transport, MarkerDeviceOptions options, std::vector<std::string> labels)
    : options_(std::move(options)), transport_(transport) {
  if (labels.empty()) throw Error(fmt::format("the {} driver needs the calibration's markers to name its slots",
                                              kDriverIds.name(transport)));
  if (options_.vendor_id < 0 || options_.vendor_id > 0xFFFF || options_.product_id < 0 || options_.product_id > 0xFFFF)
    throw Error(fmt::format("{} vendor and product ids must be 0 to 65535 (0x0000 to 0xFFFF)", kDriverIds.name(transport)));
  info_.labels = std::move(labels);
  info_.units = "mm";
  info_.nominal_rate_hz = options_.rate_hz;
  info_.own_clock = true;
  configure_mailbox(info_.labels);
  waiting_since_ns_ = monotonic_now_ns();
}

std::string MarkerDeviceSource::wanted_device() const {
  std::string text = options_.vendor_id ? fmt::format("{:04x}", options_.vendor_id) : std::string("any vendor");
  text += options_.product_id ? fmt::format(":{:04x}", options_.product_id) : std::string(", any product");
  if (!options_.serial.empty()) text += fmt::format(", serial {}", options_.serial);
  return text;
}

std::string MarkerDeviceSource::device_name() const {
  return fmt::format("{} marker device {}", kDriverIds.name(transport_), identity_.empty() ? wanted_device() : identity_);
}

bool MarkerDeviceSource::matches(uint16_t vendor_id, uint16_t product_id) const noexcept {
  return (options_.vendor_id == 0 || options_.vendor_id == vendor_id) &&
         (options_.product_id == 0 || options_.product_id == product_id);
}

bool MarkerDeviceSource::serial_matches(std::string_view serial) const noexcept {
  return options_.serial.empty() || options_.serial == serial;
}

formats::device::Control MarkerDeviceSource::start_control(const DeviceInfo& device) const {
  const auto rate_mhz = uint32_t(std::llround(options_.rate_hz * 1000.0));
  if (rate_mhz > 0 && rate_mhz != device.rate_mhz) {
    if (!(device.capabilities & formats::device::kCapabilityRateSettable))
      throw Error(fmt::format("{}: rate_hz {:g} asked for, but the device runs only at {:g} Hz", device_name(),
                              options_.rate_hz, device.rate_mhz / 1000.0));
    if (rate_mhz > device.max_rate_mhz)
      throw Error(fmt::format("{}: rate_hz {:g} asked for, but the device goes up to {:g} Hz", device_name(),
                              options_.rate_hz, device.max_rate_mhz / 1000.0));
  }
  return {formats::device::Command::kStart, rate_mhz};
}

std::string MarkerDeviceSource::description() const {
  const std::string slots = fmt::format("{} marker slots (the calibration's markers by device id), in mm", info_.labels.size());
  if (!last_info_) return fmt::format("{}: not present yet; {}", device_name(), slots);
  const DeviceInfo& d = *last_info_;
  return fmt::format("{}: protocol {}.{}, {} markers at {:g} Hz in {}; {}", device_name(), d.version_major,
                     d.version_minor, d.marker_capacity,
                     options_.rate_hz > 0 ? options_.rate_hz : d.rate_mhz / 1000.0, units_name(d.units), slots);
}

void MarkerDeviceSource::device_opened(const DeviceInfo& device, std::string identity) {
  identity_ = std::move(identity);
  current_ = device;
  last_info_ = device;
  to_mm_ = millimetres_per_unit(device.units);
  if (info_.nominal_rate_hz == 0.0 && !lost_) info_.nominal_rate_hz = device.rate_mhz / 1000.0;
  // Frames up to the device's own capacity are read whole; ids past our slots are counted.
  assembler_ = FrameAssembler(formats::device::frame_body_bytes(device.marker_capacity));
  scratch_.markers.reserve(device.marker_capacity);
  if (device.marker_capacity > info_.labels.size())
    spdlog::warn("{} has {} markers; ids from {} on are ignored (the calibration has {})", device_name(),
                 device.marker_capacity, info_.labels.size(), info_.labels.size());
  if (lost_) {
    gap_pending_ = true;
    spdlog::info("{} is back after {:.2f} s; waiting for its frames", device_name(),
                 seconds(monotonic_now_ns() - waiting_since_ns_));
    state_.set(fmt::format("{} reopened, waiting for frames", device_name()));
  } else {
    spdlog::info("opened {}", description());
    state_.set("");
  }
}

void MarkerDeviceSource::device_lost(std::string_view why) {
  if (!current_) return;
  current_.reset();
  assembler_.reset();
  lost_ = true;
  lost_why_ = why;
  waiting_since_ns_ = monotonic_now_ns();
  gap_start_ns_ = last_receive_ns_;
  gap_start_frame_no_ = last_frame_no_;
  spdlog::warn("{} lost ({}); waiting for it to return", device_name(), why);
  state_.set(fmt::format("{} lost ({}), waiting for it to return", device_name(), why));
  state_written_ns_ = waiting_since_ns_;
}

void MarkerDeviceSource::receive(std::span<const uint8_t> bytes, bool single_chunk) noexcept {
  while (!bytes.empty() && current_) {
    const FrameAssembler::Result r = assembler_.push(bytes);
    if (r.abandoned) errors_.fetch_add(1, std::memory_order_relaxed);
    if (r.status == FrameAssembler::Status::kDropped) {
      errors_.fetch_add(1, std::memory_order_relaxed);
      last_error_ = r.error.error;
    } else if (r.status == FrameAssembler::Status::kComplete) {
      publish(assembler_.body());
    }
    if (single_chunk) break;
    bytes = bytes.subspan(r.used);
  }
}

void MarkerDeviceSource::publish(std::span<const uint8_t> body) noexcept {
  const formats::device::DeviceParseResult parsed =
      formats::device::parse_frame_body(body, current_->marker_capacity, scratch_);
  if (!parsed.ok()) {
    errors_.fetch_add(1, std::memory_order_relaxed);
    last_error_ = parsed.error;
    return;
  }
  const int64_t now_ns = monotonic_now_ns();
  // The wire's 32-bit frame number, continued past wrap-arounds.
  int64_t frame_no = scratch_.frame_no;
  if (last_frame_no_ >= 0) {
    const auto step = int32_t(uint32_t(scratch_.frame_no) - uint32_t(last_frame_no_));
    frame_no = last_frame_no_ + step;
  }
  if (gap_pending_) {
    gap_pending_ = false;
    gap_end_ns_ = now_ns;
    gap_end_frame_no_ = frame_no;
  } else if (last_frame_no_ >= 0 && frame_no > last_frame_no_ + 1) {
    frames_dropped_.fetch_add(uint64_t(frame_no - last_frame_no_ - 1), std::memory_order_relaxed);
  }
  last_frame_no_ = frame_no;
  last_receive_ns_ = now_ns;

  MarkerFrame& out = mailbox_->write_buffer();
  for (Marker& m : out.markers) {
    m.flags = kMarkerMissing;
    m.position.setConstant(std::numeric_limits<double>::quiet_NaN());
  }
  for (const formats::device::DeviceMarker& d : scratch_.markers) {
    if (d.id >= out.markers.size()) {
      markers_ignored_.fetch_add(1, std::memory_order_relaxed);
      continue;
    }
    Marker& m = out.markers[d.id];
    m.id = d.id;
    if (d.flags & formats::device::kMarkerOccluded) continue;
    m.flags = (d.flags & formats::device::kMarkerUnlabelled) ? kMarkerUnlabelled : 0u;
    m.position = Eigen::Vector3d(d.position[0], d.position[1], d.position[2]) * to_mm_;
  }
  // Device ticks to ns without overflow: whole seconds, then the remainder.
  const uint64_t clock_hz = current_->clock_hz;
  out.frame_no = frame_no;
  out.source_time_ns = int64_t(scratch_.device_time / clock_hz) * kNsPerSecond +
                       int64_t((scratch_.device_time % clock_hz) * uint64_t(kNsPerSecond) / clock_hz);
  out.receive_time_ns = now_ns;
  out.timecode = Timecode{};
  mailbox_->publish();
}

void MarkerDeviceSource::report(int64_t now_ns) {
  if (!current_ && now_ns - state_written_ns_ >= kStateRefreshNs) {
    const double absent_s = seconds(now_ns - waiting_since_ns_);
    state_.set(lost_ ? fmt::format("{} lost {:.1f} s ago ({}), waiting for it to return", device_name(), absent_s, lost_why_)
                     : fmt::format("waiting {:.1f} s for {} to be plugged in", absent_s, device_name()));
    state_written_ns_ = now_ns;
  }
  if (gap_end_frame_no_ >= 0) {
    // Frames resumed after a loss: the gap in time, and in frames when the device kept
    // numbering (a device that restarted counts from 0 again, so only time is known).
    const double gap_s = seconds(gap_end_ns_ - gap_start_ns_);
    const std::string frames =
        gap_start_frame_no_ >= 0 && gap_end_frame_no_ > gap_start_frame_no_
            ? fmt::format("{} frames missed", gap_end_frame_no_ - gap_start_frame_no_ - 1)
            : fmt::format("the device restarted its frame numbers at {}", gap_end_frame_no_);
    const std::string line = fmt::format("{} streaming again after a {:.2f} s gap ({})", device_name(), gap_s, frames);
    spdlog::warn("{}", line);
    state_.set(line);
    reconnects_.fetch_add(1, std::memory_order_relaxed);
    lost_ = false;
    gap_end_frame_no_ = -1;
  }
  const uint64_t dropped = frames_dropped_.load(std::memory_order_relaxed);
  if (dropped > dropped_logged_ && now_ns - drops_logged_ns_ >= kDropLogIntervalNs) {
    spdlog::warn("{}: {} frames dropped ({} in all; the last error: {})", device_name(), dropped - dropped_logged_,
                 dropped, formats::device::device_error_name(last_error_));
    dropped_logged_ = dropped;
    drops_logged_ns_ = now_ns;
  }
}

}  // namespace facecap::drivers
