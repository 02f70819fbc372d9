#pragma once
// The marker source drivers facecap knows, as one table of (id, name, description): the
// configuration's `source.driver` choices, `facecapd --list-drivers` and the docs read it.
// Which drivers a build contains is decided at configure time (FACECAP_WITH_<DRIVER>,
// defined for this target); drivers/table.cpp holds the factories of those built.
#include <array>
#include <cstdint>

#include "core/enum_table.hpp"

namespace facecap::drivers {

enum class DriverId : uint8_t { kSim, kReplay, kNatNet, kUsb, kHid, kV4l2 };

inline constexpr EnumTable kDriverIds{std::array{
    EnumEntry{DriverId::kSim, "sim", "simulated capture of the rig: built-in motion, noise, dropouts, head sway"},
    EnumEntry{DriverId::kReplay, "replay",
              "a recorded take: C3D, TRC, a facecapd recording (.fcrec) or a NatNet capture (.pcap, .pcapng)"},
    EnumEntry{DriverId::kNatNet, "natnet", "OptiTrack Motive (or facecap natnet-serve) streaming NatNet over UDP"},
    EnumEntry{DriverId::kUsb, "usb", "a marker device on USB bulk transfers (docs/usb-hid-protocol.md), through libusb"},
    EnumEntry{DriverId::kHid, "hid", "a marker device sending HID reports (docs/usb-hid-protocol.md), through hidapi"},
    EnumEntry{DriverId::kV4l2, "v4l2", "calibrated IR cameras over V4L2: blobs triangulated into unlabelled 3D points"},
}};

// Whether the driver can hand every frame in order as fast as the loop asks for them
// (loop.mode = "lockstep"), rather than on its own clock.
constexpr bool supports_lockstep(DriverId id) noexcept { return id == DriverId::kReplay; }

// Whether this build contains the driver (CMake option FACECAP_WITH_<DRIVER>).
constexpr bool driver_built(DriverId id) noexcept {
  switch (id) {
    case DriverId::kSim: return FACECAP_WITH_SIM;
    case DriverId::kReplay: return FACECAP_WITH_REPLAY;
    case DriverId::kNatNet: return FACECAP_WITH_NATNET;
    case DriverId::kUsb: return FACECAP_WITH_USB;
    case DriverId::kHid: return FACECAP_WITH_HID;
    case DriverId::kV4l2: return FACECAP_WITH_V4L2;
  }
  return false;
}

}  // namespace facecap::drivers
