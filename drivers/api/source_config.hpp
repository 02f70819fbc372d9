#pragma once
// The options of every driver, as the [source] section of facecapd.toml sets them
// (config/schema.cpp declares the keys, defaults and ranges).
#include <array>
#include <cstdint>
#include <string>

#include "core/enum_table.hpp"
#include "drivers/api/driver_id.hpp"

namespace facecap::drivers {

struct SimOptions {
  double rate_hz = 0.0;              // frames per second
  std::string motion;                // "builtin" or a Live Link Face CSV path
  double noise_mm = 0.0;             // standard deviation per coordinate
  double dropout_probability = 0.0;  // per marker and frame
  double head_motion_degrees = 0.0;  // amplitude of the head's sway
  double head_motion_mm = 0.0;
  int64_t seed = 0;
};

struct ReplayOptions {
  std::string file;                  // .c3d, .trc, .fcrec, or a NatNet capture (with NatNetOptions' selection)
  double speed = 1.0;                // 0: as fast as the loop takes frames
  bool loop = false;
  double start_s = 0.0;              // window into the take, seconds from its first frame
  double end_s = 0.0;                // 0: to the end
  bool source_timestamps = true;     // pace by the file's times, else by its nominal rate
};

enum class NatNetTransport : uint8_t { kAuto, kMulticast, kUnicast };
inline constexpr EnumTable kNatNetTransports{std::array{
    EnumEntry{NatNetTransport::kAuto, "auto", "as the server's NAT_SERVERINFO says"},
    EnumEntry{NatNetTransport::kMulticast, "multicast", "frames to a multicast group, joined on local_interface"},
    EnumEntry{NatNetTransport::kUnicast, "unicast",
              "frames to this host: to the command socket (4.x servers, kept alive) or to data_port (3.x style)"},
}};

// The layout frames are read as: the server's NatNet version, or one asked for.
enum class NatNetBitstream : uint8_t { kServer, k30, k31, k40, k41, k42 };
inline constexpr EnumTable kNatNetBitstreams{std::array{
    EnumEntry{NatNetBitstream::kServer, "server", "the server's NatNet version"},
    EnumEntry{NatNetBitstream::k30, "3.0", "Motive 2.x"},
    EnumEntry{NatNetBitstream::k31, "3.1", "Motive 2.x (3.0's layout)"},
    EnumEntry{NatNetBitstream::k40, "4.0", "Motive 3.0"},
    EnumEntry{NatNetBitstream::k41, "4.1", "Motive 3.1: byte counts, assets, precision timestamps"},
    EnumEntry{NatNetBitstream::k42, "4.2", "later Motive 3.x"},
}};

struct NatNetOptions {
  std::string server_address;        // IPv4; empty: discover by broadcast
  std::string discovery_address;     // where the discovery broadcast goes
  int64_t command_port = 0;          // the server's
  int64_t data_port = 0;             // multicast and 3.x-style unicast frames
  std::string local_interface;       // IPv4 address or interface name; empty: the system's choice
  NatNetTransport transport = NatNetTransport::kAuto;
  std::string multicast_group;       // empty: the server's
  std::string marker_set;            // whose markers are the frame's slots; empty: none
  int64_t unlabelled_markers = 0;    // slots for unlabelled points after them
  NatNetBitstream bitstream = NatNetBitstream::kServer;
  double connect_timeout_s = 0.0;    // open() waits this long for the server's answers
  double silence_timeout_s = 0.0;    // no frame for this long: reported, and reconnecting
  int64_t timecode_rate_hz = 0;      // SMPTE rate of the server's timecode
};

struct SourceConfig {
  DriverId driver = DriverId::kSim;
  SimOptions sim;
  ReplayOptions replay;
  NatNetOptions natnet;
};

}  // namespace facecap::drivers
