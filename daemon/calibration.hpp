#pragma once
// How incoming markers relate to the rig: the marker set (face bindings for the solver,
// head markers for stabilisation) and the transform from marker space to rig space.
// Either the default marker set (what the sim produces) or a calibration file.
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "config/daemon_config.hpp"
#include "solver/marker_layout.hpp"
#include "solver/rig.hpp"

namespace facecap::daemon {

struct MarkerCalibration {
  MarkerSet markers;
  // Marker units to millimetres (0: take the source's units, else assume rig units).
  double marker_mm_per_unit = 0.0;
  // Marker units to rig units when a calibration measured it (an actor's face is not the
  // rig's size); 0: from the units alone.
  double marker_scale = 0.0;
  // Marker space (after scaling to rig units) to rig space, for a head at rest.
  Eigen::Isometry3d T_rig_marker = Eigen::Isometry3d::Identity();
  // Per face marker, rig space: where the actor's marker sits at rest relative to its
  // bound rig point (identity mismatch), taken off every target so that the actor at
  // rest gives the rig's neutral. Empty: no offsets.
  std::vector<Eigen::Vector3d> face_offsets;
  std::string origin;  // "default marker set" or the file
};

// The configured calibration: the default marker set, or a file, either a profile
// written by `facecap calibrate` (docs/alignment.md; it must have been made for this
// rig) or a hand-written TOML (docs/config.md):
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
