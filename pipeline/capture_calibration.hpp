#pragma once
// An actor's calibration from a captured stretch of markers, as `facecap calibrate
// --auto-neutral` makes it from a take: the most neutral still stretch found, averaged with
// the head motion removed, calibrated (Algorithm 1) with stable markers found for head
// stabilisation (align::calibrate_take). facecapd runs it on a worker thread for the
// control API's POST /calibrate. Not real-time code.
#include <cstddef>
#include <filesystem>
#include <span>
#include <vector>
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
  std::vector<std::string> warnings;  // residual_outliers()
};

// Bound markers whose calibration residual is far above the rest (above 3x the median and
// the median + 2 mm), each as a sentence naming the marker, its residual and its likely
// cause: a head-rig marker when its distances to the stable markers hold as rigidly as
// theirs over the take, else a swapped label or a marker off the rig's face.
std::vector<std::string> residual_outliers(const align::TakeCalibration& result, const std::vector<std::string>& labels,
                                           std::span<const MarkerFrame> frames);

// Saves `calibration` as the profile file `profile` (directories created). An existing
// profile is an Error unless `replace`; then it is kept as a backup beside it
// (NAME.toml.bak, else NAME.toml.bak.2, ... : no earlier backup is lost), whose path is
// returned. The new profile is written completely before the old one moves.
std::optional<std::filesystem::path> save_profile(const std::filesystem::path& profile, const align::Calibration& calibration,
                                                  bool replace);

// The upper median of values; NaN when empty.
double median_of(std::vector<double> values);

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
// min_presence: the fraction of the neutral stretch's frames each marker must be present
// in (align::NeutralSearchOptions). Throws Error when the take cannot be calibrated (too
// few markers, no neutral stretch).
CaptureCalibration calibrate_capture(const Rig& rig, const formats::MarkerTake& take, const std::string& name,
                                     double min_presence);

}  // namespace facecap::pipeline
