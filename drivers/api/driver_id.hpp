#pragma once
// The marker source drivers facecap knows, as one table of (id, name, description): the
// configuration's `source.driver` choices, `facecapd --list-drivers` and the docs read it.
// Which drivers a build contains is decided at configure time (FACECAP_WITH_<DRIVER>,
// defined for this target); drivers/table.cpp holds the factories of those built.
#include <array>
#include <cstdint>

#include "core/enum_table.hpp"

namespace facecap::drivers {

enum class DriverId : uint8_t { kSim, kReplay, kNatNet };

inline constexpr EnumTable kDriverIds{std::array{
    EnumEntry{DriverId::kSim, "sim", "simulated capture of the rig: built-in motion, noise, dropouts, head sway"},
    EnumEntry{DriverId::kReplay, "replay",
              "a recorded take: C3D, TRC, a facecapd recording (.fcrec) or a NatNet capture (.pcap, .pcapng)"},
    EnumEntry{DriverId::kNatNet, "natnet", "OptiTrack Motive (or facecap natnet-serve) streaming NatNet over UDP"},
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
  }
  return false;
}

}  // namespace facecap::drivers
