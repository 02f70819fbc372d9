#pragma once
// How incoming markers relate to the rig: the marker set (face bindings for the solver,
// head markers for stabilisation) and the transform from marker space to rig space.
// Either the default marker set (what the sim produces) or a calibration file.
#include <string>

#include <Eigen/Geometry>

#include "config/daemon_config.hpp"
#include "drivers/marker_set.hpp"
#include "solver/rig.hpp"

namespace facecap::daemon {

struct MarkerCalibration {
  drivers::MarkerSet markers;
  // Marker units to millimetres (0: take the source's units, else assume rig units).
  double marker_mm_per_unit = 0.0;
  // Marker space (after scaling to rig units) to rig space, for a head at rest.
  Eigen::Isometry3d T_rig_marker = Eigen::Isometry3d::Identity();
  std::string origin;  // "default marker set" or the file
};

// The configured calibration. A file is TOML (docs/config.md):
//   version = 1
//   marker_units = "mm"                      # optional
//   rotation_wxyz = [1, 0, 0, 0]             # optional, marker -> rig
//   translation = [0, 0, 0]                  # optional, rig units
//   [[face]]  label = "Chin", vertex = 1234  # or vertices = [a, b, c], barycentric = [u, v, w]
//   [[head]]  label = "HeadFront", position = [x, y, z]   # rig space
// Not RT-safe; throws Error with file:line for a malformed file.
MarkerCalibration load_calibration(const config::CalibrationSection& section, const Rig& rig);

// Scale from the source's marker units to rig units under this calibration.
double marker_to_rig_scale(const MarkerCalibration& calibration, const std::string& source_units, const Rig& rig);

}  // namespace facecap::daemon
