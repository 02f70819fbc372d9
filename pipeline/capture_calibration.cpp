#include "pipeline/capture_calibration.hpp"

#include <algorithm>

#include <fmt/format.h>

#include "core/error.hpp"
#include "core/units.hpp"

namespace facecap::pipeline {

CaptureCalibration calibrate_capture(const Rig& rig, const formats::MarkerTake& take, const std::string& name) {
  if (take.frames.empty()) throw file_error(name, "the capture has no frames");
  if (take.marker_count() < 6) throw file_error(name, fmt::format("{} markers; calibration needs at least 6", take.marker_count()));
  // Units for the neutral search's mm thresholds: stated, or the decade the face's size suggests.
  double take_mm = millimetres_per_unit(take.units).value_or(0.0);
  if (take_mm <= 0.0) {
    Eigen::Matrix3Xd present(3, 0);
    for (const Marker& m : take.frames.front().markers)
      if (m.present()) present.conservativeResize(3, present.cols() + 1), present.col(present.cols() - 1) = m.position;
    take_mm = millimetres_per_unit(guess_face_units(bounding_box(present))).value_or(10.0);
  }
  align::TakeCalibrationOptions options;
  options.calibration.rig_mm_per_unit = 1.0 / rig_units_per_mm(rig);
  if (millimetres_per_unit(take.units)) options.calibration.take_mm_per_unit = take_mm;
  options.neutral.rate_hz = take.rate_hz > 0 ? take.rate_hz : 60.0;
  options.neutral.take_mm_per_unit = take_mm;
  CaptureCalibration out;
  out.result = align::calibrate_take(rig, take.labels, take.frames, options);
  align::Calibration& c = out.result.calibration;
  c.source_take = name;
  c.source_frame = take.frames[out.result.frame].frame_no;
  if (out.result.count > 1)
    c.notes.push_back(fmt::format("neutral positions are the mean of frames {} to {} stabilised onto frame {}",
                                  take.frames[out.result.first].frame_no,
                                  take.frames[out.result.first + out.result.count - 1].frame_no, c.source_frame));
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
