#include "pipeline/capture_calibration.hpp"

#include <algorithm>
#include <limits>

#include <fmt/format.h>

#include "core/error.hpp"
#include "core/units.hpp"
#include "solver/align/profile.hpp"
#include "solver/align/stabilise.hpp"

namespace facecap::pipeline {

double median_of(std::vector<double> values) {
  if (values.empty()) return std::numeric_limits<double>::quiet_NaN();
  std::nth_element(values.begin(), values.begin() + std::ptrdiff_t(values.size() / 2), values.end());
  return values[values.size() / 2];
}

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

std::vector<std::string> residual_outliers(const align::TakeCalibration& result, const std::vector<std::string>& labels,
                                           std::span<const MarkerFrame> frames) {
  const align::Calibration& c = result.calibration;
  std::vector<double> residuals;
  for (const auto& m : c.markers) residuals.push_back(m.residual_mm);
  if (residuals.size() < 4) return {};
  const double median = median_of(residuals);
  const double limit = std::max(3.0 * median, median + 2.0);
  // How rigidly the stable markers hold together over the take (mm): the head's own.
  auto slot_of = [&](const std::string& label) { return int(std::find(labels.begin(), labels.end(), label) - labels.begin()); };
  std::vector<double> own;
  for (std::size_t i = 0; i < result.stable_slots.size(); ++i)
    for (std::size_t j = i + 1; j < result.stable_slots.size(); ++j)
      own.push_back(align::distance_deviation(frames, result.stable_slots[i], result.stable_slots[j]) * c.take_mm_per_unit);
  const double head_rigidity_mm = own.empty() ? 0.0 : median_of(own);
  std::vector<std::string> out;
  for (const auto& m : c.markers) {
    if (m.residual_mm <= limit) continue;
    const int slot = slot_of(m.label);
    std::vector<double> deviation;
    for (int s : result.stable_slots)
      if (s != slot) deviation.push_back(align::distance_deviation(frames, slot, s) * c.take_mm_per_unit);
    const bool rigid = deviation.size() >= 3 && median_of(deviation) <= head_rigidity_mm + 0.5;
    out.push_back(fmt::format("marker '{}' is {:.1f} mm off the fitted face (the markers' median is {:.1f} mm): {}", m.label,
                              m.residual_mm, median,
                              rigid ? "it moves rigidly with the head, so it is likely on a head rig: calibrate it as a head "
                                      "marker (facecap calibrate --head) or take it off the face list"
                                    : "likely a swapped label or a marker placed off the rig's face: check it on the actor"));
  }
  return out;
}

std::optional<std::filesystem::path> save_profile(const std::filesystem::path& profile, const align::Calibration& calibration,
                                                  bool replace) {
  namespace fs = std::filesystem;
  std::error_code ec;
  const bool exists = fs::exists(profile, ec);
  if (exists && !replace) throw file_error(profile.string(), "exists (facecap calibrate --force, or \"replace\": true in the control API, replaces it and keeps the old one as a backup)");
  if (profile.has_parent_path()) fs::create_directories(profile.parent_path());
  if (!exists) {
    align::save_calibration_profile(profile, calibration);
    return std::nullopt;
  }
  fs::path backup = profile.string() + ".bak";
  for (int n = 2; fs::exists(backup, ec); ++n) backup = fmt::format("{}.bak.{}", profile.string(), n);
  const fs::path fresh = profile.string() + ".new";
  align::save_calibration_profile(fresh, calibration);
  fs::rename(profile, backup);
  fs::rename(fresh, profile);
  return backup;
}

CaptureCalibration calibrate_capture(const Rig& rig, const formats::MarkerTake& take, const std::string& name,
                                     double min_presence) {
  check_calibration_take(take, name);
  const double take_mm = neutral_search_mm_per_unit(take, std::nullopt);
  align::TakeCalibrationOptions options;
  options.calibration.rig_mm_per_unit = 1.0 / rig_units_per_mm(rig);
  if (millimetres_per_unit(take.units)) options.calibration.take_mm_per_unit = take_mm;
  options.neutral.rate_hz = take.rate_hz > 0 ? take.rate_hz : 60.0;
  options.neutral.take_mm_per_unit = take_mm;
  options.neutral.min_presence = min_presence;
  CaptureCalibration out;
  out.result = align::calibrate_take(rig, take.labels, take.frames, options);
  align::Calibration& c = out.result.calibration;
  describe_calibration_source(c, out.result, take, name);
  std::vector<double> residuals;
  for (const auto& m : c.markers) residuals.push_back(m.residual_mm);
  if (!residuals.empty()) {
    out.residual_median_mm = median_of(residuals);
    out.residual_max_mm = *std::max_element(residuals.begin(), residuals.end());
  }
  out.warnings = residual_outliers(out.result, take.labels, take.frames);
  return out;
}

}  // namespace facecap::pipeline
