#pragma once
// An actor's calibration from a captured stretch of markers, as `facecap calibrate
// --auto-neutral` makes it from a take: the most neutral still stretch found, averaged with
// the head motion removed, calibrated (Algorithm 1) with stable markers found for head
// stabilisation (align::calibrate_take). facecapd runs it on a worker thread for the
// control API's POST /calibrate. Not real-time code.
#include <cstddef>
#include <optional>
#include <string>

#include "formats/take.hpp"
#include "solver/align/calibrate_take.hpp"
#include "solver/rig.hpp"

namespace facecap::pipeline {

struct CaptureCalibration {
  align::TakeCalibration result;  // result.calibration: what to solve with
  double residual_median_mm = 0.0;  // of the markers' calibration residuals
  double residual_max_mm = 0.0;
};

// What `facecap calibrate` and calibrate_capture share. Each throws Error naming `name`.
// A take calibration needs frames and at least 6 markers.
void check_calibration_take(const formats::MarkerTake& take, const std::string& name);
// mm per take unit for the neutral search's thresholds: given, else stated by the take,
// else the decade the size of the face in its first frame suggests (cm when it cannot tell).
double neutral_search_mm_per_unit(const formats::MarkerTake& take, std::optional<double> given);
// Names the take and frame the calibration came from, and notes the frames averaged.
void describe_calibration_source(align::Calibration& calibration, const align::TakeCalibration& result,
                                 const formats::MarkerTake& take, const std::string& name);

// name: what the take is called in the calibration (its source_take) and in errors.
// Throws Error when the take cannot be calibrated (too few markers, no neutral stretch).
CaptureCalibration calibrate_capture(const Rig& rig, const formats::MarkerTake& take, const std::string& name);

}  // namespace facecap::pipeline
