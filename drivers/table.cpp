#include "drivers/table.hpp"

#include <cctype>
#include <string>

#include <fmt/format.h>

#include "core/error.hpp"
#if FACECAP_WITH_HID
#include "drivers/hid/hid_source.hpp"
#endif
#if FACECAP_WITH_NATNET
#include "drivers/natnet/natnet_source.hpp"
#endif
#if FACECAP_WITH_REPLAY
#include "drivers/replay/replay_source.hpp"
#endif
#if FACECAP_WITH_SIM
#include "drivers/sim/sim_source.hpp"
#endif
#if FACECAP_WITH_USB
#include "drivers/usb/usb_source.hpp"
#endif
#if FACECAP_WITH_V4L2
#include "drivers/v4l2/camera_calibration.hpp"
#include "drivers/v4l2/v4l2_source.hpp"
#endif

namespace facecap::drivers {
namespace {

#if FACECAP_WITH_SIM
std::unique_ptr<MarkerSource> make_sim(const SourceConfig& config, const SourceContext& context) {
  if (!context.rig) throw Error("the sim source needs the rig being solved");
  return std::make_unique<SimSource>(config.sim, context.rig, context.markers);
}
#endif

#if FACECAP_WITH_REPLAY
std::unique_ptr<MarkerSource> make_replay(const SourceConfig& config, const SourceContext&) {
  return std::make_unique<ReplaySource>(config.replay, config.natnet);
}
#endif

#if FACECAP_WITH_NATNET
std::unique_ptr<MarkerSource> make_natnet(const SourceConfig& config, const SourceContext&) {
  return std::make_unique<NatNetSource>(config.natnet);
}
#endif

#if FACECAP_WITH_USB
std::unique_ptr<MarkerSource> make_usb(const SourceConfig& config, const SourceContext& context) {
  return std::make_unique<UsbSource>(config.usb, context.markers.labels());
}
#endif

#if FACECAP_WITH_HID
std::unique_ptr<MarkerSource> make_hid(const SourceConfig& config, const SourceContext& context) {
  return std::make_unique<HidSource>(config.hid, context.markers.labels());
}
#endif

#if FACECAP_WITH_V4L2
std::unique_ptr<MarkerSource> make_v4l2(const SourceConfig& config, const SourceContext&) {
  return std::make_unique<V4l2Source>(config.v4l2);
}
std::string check_v4l2_files(const SourceConfig& config) {
  if (config.v4l2.calibration.empty()) return "";
  const v4l2::CameraCalibration calibration = v4l2::read_camera_calibration(config.v4l2.calibration);
  return fmt::format("camera calibration {} ({} cameras)", config.v4l2.calibration, calibration.cameras.size());
}
#endif

const DriverEntry kDrivers[] = {
#if FACECAP_WITH_SIM
    {DriverId::kSim, "nothing: it samples the rig being solved", &make_sim},
#endif
#if FACECAP_WITH_REPLAY
    {DriverId::kReplay, "a take file (source.replay.file)", &make_replay},
#endif
#if FACECAP_WITH_NATNET
    {DriverId::kNatNet, "a NatNet server on the network (source.natnet.server_address, or discovery)", &make_natnet},
#endif
#if FACECAP_WITH_USB
    {DriverId::kUsb, "a USB device speaking docs/usb-hid-protocol.md (interface class ff/46/01) and read-write "
                     "access to its /dev/bus/usb node (a udev rule); libusb-1.0", &make_usb},
#endif
#if FACECAP_WITH_HID
    {DriverId::kHid, "a HID device speaking docs/usb-hid-protocol.md (usage page 0xff46) and read-write access to its "
                     "/dev/hidraw node (a udev rule); hidapi (hidraw)", &make_hid},
#endif
#if FACECAP_WITH_V4L2
    {DriverId::kV4l2, "two or more V4L2 cameras streaming GREY, YUYV or MJPEG (source.v4l2.devices) and their "
                      "calibration (source.v4l2.calibration, docs/cameras.md); OpenCV", &make_v4l2, &check_v4l2_files},
#endif
};

}  // namespace

std::span<const DriverEntry> driver_table() noexcept { return kDrivers; }

const DriverEntry* find_driver(DriverId id) noexcept {
  for (const DriverEntry& entry : kDrivers)
    if (entry.id == id) return &entry;
  return nullptr;
}

std::string check_source_files(const SourceConfig& config) {
  const DriverEntry* entry = find_driver(config.driver);
  return entry && entry->check_files ? entry->check_files(config) : "";
}

std::unique_ptr<MarkerSource> make_source(const SourceConfig& config, const SourceContext& context) {
  const DriverEntry* entry = find_driver(config.driver);
  if (!entry) {
    std::string option(kDriverIds.name(config.driver));
    for (char& c : option) c = char(std::toupper(static_cast<unsigned char>(c)));
    throw Error(fmt::format("the {} driver is not built into this facecapd (configure with -DFACECAP_WITH_{}=ON)",
                            kDriverIds.name(config.driver), option));
  }
  return entry->make(config, context);
}

}  // namespace facecap::drivers
