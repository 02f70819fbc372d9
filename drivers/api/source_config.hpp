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

// The units a replayed take's values are read in.
enum class TakeUnits : uint8_t { kStated, kMm, kCm, kM };
inline constexpr EnumTable kTakeUnits{std::array{
    EnumEntry{TakeUnits::kStated, "stated", "as the take states them (the calibration's when it states none)"},
    EnumEntry{TakeUnits::kMm, "mm", "millimetres, whatever the take states"},
    EnumEntry{TakeUnits::kCm, "cm", "centimetres, whatever the take states"},
    EnumEntry{TakeUnits::kM, "m", "metres, whatever the take states"},
}};

struct ReplayOptions {
  std::string file;                  // .c3d, .trc, .fcrec, or a NatNet capture (with NatNetOptions' selection)
  double speed = 1.0;                // 0: as fast as the loop takes frames
  bool loop = false;
  double start_s = 0.0;              // window into the take, seconds from its first frame
  double end_s = 0.0;                // 0: to the end
  bool source_timestamps = true;     // pace by the file's times, else by its nominal rate
  TakeUnits units = TakeUnits::kStated;
};

// A marker device speaking the facecap marker-device protocol (docs/usb-hid-protocol.md),
// on USB bulk transfers (source.usb) or HID reports (source.hid).
struct MarkerDeviceOptions {
  int64_t vendor_id = 0;          // 0: any vendor
  int64_t product_id = 0;         // 0: any product
  std::string serial;             // empty: any serial number
  double rate_hz = 0.0;           // frame rate to ask for; 0: the device's own
  bool wait_for_device = false;   // absent at start: wait for it, else refuse to start
};

enum class PixelFormat : uint8_t { kAuto, kGrey, kYuyv, kMjpeg };
inline constexpr EnumTable kPixelFormats{std::array{
    EnumEntry{PixelFormat::kAuto, "auto", "the first the camera offers of GREY, YUYV, MJPEG"},
    EnumEntry{PixelFormat::kGrey, "grey", "8-bit greyscale (V4L2_PIX_FMT_GREY), as IR cameras send"},
    EnumEntry{PixelFormat::kYuyv, "yuyv", "YUYV 4:2:2, of which the luma is used"},
    EnumEntry{PixelFormat::kMjpeg, "mjpeg", "motion JPEG, decoded to greyscale"},
}};

// Calibrated IR cameras over V4L2 (source.v4l2): docs/cameras.md.
struct V4l2Options {
  std::string calibration;          // OpenCV-style YAML: intrinsics, distortion, extrinsics per camera
  std::string devices;              // one device per calibrated camera, in order, comma-separated
  PixelFormat pixel_format = PixelFormat::kAuto;
  double frame_rate_hz = 0.0;       // 0: the camera's current rate
  int64_t threshold = 0;            // grey level a marker's pixels exceed
  int64_t min_blob_area_px = 0;
  int64_t max_blob_area_px = 0;
  double min_roundness = 0.0;       // minor / major axis of a blob, 1 for a disc
  double epipolar_tolerance_px = 0.0;
  double sync_tolerance_ms = 0.0;   // cameras' frames this close in time make one set
  int64_t max_points = 0;           // 3D points per frame at most (the frame's slots)
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
  MarkerDeviceOptions usb;
  MarkerDeviceOptions hid;
  V4l2Options v4l2;
  NatNetOptions natnet;
};

}  // namespace facecap::drivers
