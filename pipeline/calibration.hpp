#pragma once
// Where a calibration comes from: a `facecap calibrate` profile, a hand-written file, or
// the default marker set (what the sim produces). All three give the one calibration type
// (solver/align/calibration.hpp) that the marker mapper uses, in facecapd and every tool.
//
// The hand-written file (docs/config.md, "Calibration files"):
//   version = 1
//   marker_units = "mm"                      # optional; default: the rig's units
//   rotation_wxyz = [1, 0, 0, 0]             # optional, marker -> rig
//   translation = [0, 0, 0]                  # optional, rig units
//   [[face]]  label = "Chin", vertex = 1234  # or vertices = [a, b, c], barycentric = [u, v, w]
//   [[head]]  label = "HeadFront", position = [x, y, z]   # rig space, head pose only
// Nothing here is real-time code.
#include <string>
#include <string_view>

#include "solver/align/calibration.hpp"
#include "solver/marker_layout.hpp"
#include "solver/rig.hpp"

namespace facecap::pipeline {

using align::Calibration;

// The [calibration] section: a file, or the default marker set's size.
struct CalibrationSpec {
  std::string file;       // empty: the default marker set
  int face_markers = 48;  // default marker set only
  int head_markers = 4;
};

// The calibration `spec` names, checked against the rig (a profile must have been made
// for it; bindings must index it). Throws Error naming file:line and key.
Calibration load_calibration(const CalibrationSpec& spec, const Rig& rig);

// A profile or a hand-written file held in memory (a recording's embedded calibration);
// `name` labels errors.
Calibration read_calibration(std::string_view text, const std::string& name, const Rig& rig);

// face_markers spread over the rig and head_markers on a headband (default_marker_set),
// in rig units and rig space, the head markers stabilising.
Calibration default_calibration(const Rig& rig, int face_markers, int head_markers);

// The calibration's markers where they sit on the rig at rest, in rig space: what the
// simulated source samples.
MarkerSet rest_marker_set(const Calibration& calibration);

}  // namespace facecap::pipeline
