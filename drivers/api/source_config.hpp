#pragma once
// The options of every driver, as the [source] section of facecapd.toml sets them
// (config/schema.cpp declares the keys, defaults and ranges).
#include <cstdint>
#include <string>

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

struct SourceConfig {
  DriverId driver = DriverId::kSim;
  SimOptions sim;
  ReplayOptions replay;
};

}  // namespace facecap::drivers
