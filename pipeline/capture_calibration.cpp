#include "pipeline/capture_calibration.hpp"

#include <algorithm>

#include <fmt/format.h>

#include "core/error.hpp"
#include "core/units.hpp"

namespace facecap::pipeline {

void check_calibration_take(const formats::MarkerTake& take, const std::string& name) {
  if (take.frames.empty()) throw file_error(name, "the take has no frames");
  if (take.marker_count() < 6) throw file_error(name, fmt::format("{} markers; calibration needs at least 6", take.marker_count()));
}

double neutral_search_mm_per_unit(const formats::MarkerTake& take, std::optional<double> given) {
  if (given) return *given;
  if (const auto stated = millimetres_per_unit(take.units)) return *stated;
  Eigen::Matrix3Xd present(3, 0);
  for (const Marker& m : take.frames.front().markers)
    if (m.present()) present.conservativeResize(3, present.cols() + 1), present.col(present.cols() - 1) = m.position;
  return millimetres_per_unit(guess_face_units(bounding_box(present))).value_or(10.0);
}

void describe_calibration_source(align::Calibration& calibration, const align::TakeCalibration& result,
                                 const formats::MarkerTake& take, const std::string& name) {
  calibration.source_take = name;
  calibration.source_frame = take.frames[result.frame].frame_no;
  if (result.count > 1)
    calibration.notes.push_back(fmt::format("neutral positions are the mean of frames {} to {} stabilised onto frame {}",
                                            take.frames[result.first].frame_no,
                                            take.frames[result.first + result.count - 1].frame_no,
                                            calibration.source_frame));
}

CaptureCalibration calibrate_capture(const Rig& rig, const formats::MarkerTake& take, const std::string& name) {
  check_calibration_take(take, name);
  const double take_mm = neutral_search_mm_per_unit(take, std::nullopt);
  align::TakeCalibrationOptions options;
  options.calibration.rig_mm_per_unit = 1.0 / rig_units_per_mm(rig);
  if (millimetres_per_unit(take.units)) options.calibration.take_mm_per_unit = take_mm;
  options.neutral.rate_hz = take.rate_hz > 0 ? take.rate_hz : 60.0;
  options.neutral.take_mm_per_unit = take_mm;
  CaptureCalibration out;
  out.result = align::calibrate_take(rig, take.labels, take.frames, options);
  align::Calibration& c = out.result.calibration;
  describe_calibration_source(c, out.result, take, name);
  std::vector<double> residuals;
  for (const auto& m : c.markers) residuals.push_back(m.residual_mm);
  if (!residuals.empty()) {
    std::nth_element(residuals.begin(), residuals.begin() + std::ptrdiff_t(residuals.size() / 2), residuals.end());
    out.residual_median_mm = residuals[residuals.size() / 2];
    out.residual_max_mm = *std::max_element(residuals.begin(), residuals.end());
  }
  return out;
}

}  // namespace facecap::pipeline
