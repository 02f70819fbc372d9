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
  std::string file;                  // .c3d, .trc or .fcrec
  double speed = 1.0;                // 0: as fast as the loop takes frames
  bool loop = false;
  double start_s = 0.0;              // window into the take, seconds from its first frame
  double end_s = 0.0;                // 0: to the end
  bool source_timestamps = true;     // pace by the file's times, else by its nominal rate
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

struct SourceConfig {
  DriverId driver = DriverId::kSim;
  SimOptions sim;
  ReplayOptions replay;
  MarkerDeviceOptions usb;
  MarkerDeviceOptions hid;
  V4l2Options v4l2;
};

}  // namespace facecap::drivers
