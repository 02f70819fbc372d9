#include "pipeline/source_units.hpp"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>

#include "core/error.hpp"
#include "core/units.hpp"

namespace facecap::pipeline {
namespace {

constexpr std::size_t kFramesSampled = 200;  // spread over a take
constexpr double kUnitsTried[] = {1.0, 10.0, 1000.0};

// RMS distance of points from their centroid.
double spread(const Eigen::Matrix3Xd& points) {
  return std::sqrt((points.colwise() - points.rowwise().mean()).colwise().squaredNorm().mean());
}

// The median of values (reordered); values is not empty.
double median(std::span<double> values) {
  std::nth_element(values.begin(), values.begin() + std::ptrdiff_t(values.size() / 2), values.end());
  return values[values.size() / 2];
}

// Median distance of points (3 x n) from their coordinate-wise median; scratch holds n.
double median_spread(const Eigen::Ref<const Eigen::Matrix3Xd>& points, std::span<double> scratch) {
  Eigen::Vector3d centre;
  for (int axis = 0; axis < 3; ++axis) {
    for (Eigen::Index i = 0; i < points.cols(); ++i) scratch[std::size_t(i)] = points(axis, i);
    centre[axis] = median(scratch);
  }
  for (Eigen::Index i = 0; i < points.cols(); ++i) scratch[std::size_t(i)] = (points.col(i) - centre).norm();
  return median(scratch);
}

}  // namespace

FaceSizeGauge::FaceSizeGauge(const std::vector<std::string>& labels, std::string_view units,
                             const align::Calibration& calibration)
    : stated_mm_per_unit_(millimetres_per_unit(units).value_or(calibration.take_mm_per_unit)),
      calibration_mm_per_unit_(calibration.take_mm_per_unit),
      neutral_(labels.size(), nullptr),
      now_(3, Eigen::Index(labels.size())),
      then_(3, Eigen::Index(labels.size())) {
  for (std::size_t s = 0; s < labels.size(); ++s) {
    neutral_[s] = calibration.neutral_of(labels[s]);
    by_label_ = by_label_ || neutral_[s] != nullptr;
  }
  if (by_label_) return;
  Eigen::Matrix3Xd calibrated(3, Eigen::Index(calibration.markers.size() + calibration.head_markers.size()));
  Eigen::Index n = 0;
  for (const auto& m : calibration.markers) calibrated.col(n++) = m.neutral;
  for (const auto& h : calibration.head_markers) calibrated.col(n++) = h.neutral;
  if (n < 3) return;
  std::vector<double> scratch(static_cast<std::size_t>(n));
  calibrated_cloud_mm_ = median_spread(calibrated, scratch) * calibration_mm_per_unit_;
  min_cloud_points_ = std::max<std::size_t>(3, std::size_t(n) / 2);
  scratch_.resize(labels.size());
}

std::optional<double> FaceSizeGauge::cloud_size_ratio(const MarkerFrame& frame) {
  Eigen::Index n = 0;
  for (std::size_t s = 0; s < scratch_.size() && s < frame.markers.size(); ++s)
    if (frame.markers[s].present() && frame.markers[s].position.allFinite()) now_.col(n++) = frame.markers[s].position;
  if (std::size_t(n) < min_cloud_points_ || !(calibrated_cloud_mm_ > 0.0)) return std::nullopt;
  return median_spread(now_.leftCols(n), std::span<double>(scratch_).first(std::size_t(n))) * stated_mm_per_unit_ /
         calibrated_cloud_mm_;
}

std::optional<double> FaceSizeGauge::size_ratio(const MarkerFrame& frame) {
  if (!by_label_) return cloud_size_ratio(frame);
  Eigen::Index n = 0;
  for (std::size_t s = 0; s < neutral_.size() && s < frame.markers.size(); ++s) {
    if (!neutral_[s] || !frame.markers[s].present() || !frame.markers[s].position.allFinite()) continue;
    now_.col(n) = frame.markers[s].position;
    then_.col(n) = *neutral_[s];
    ++n;
  }
  if (n < 3) return std::nullopt;
  const double calibrated = spread(then_.leftCols(n)) * calibration_mm_per_unit_;
  if (!(calibrated > 0.0)) return std::nullopt;
  return spread(now_.leftCols(n)) * stated_mm_per_unit_ / calibrated;
}

UnitsCheck units_verdict(std::vector<double>& ratios, double stated_mm_per_unit) {
  UnitsCheck out;
  out.stated_mm_per_unit = stated_mm_per_unit;
  if (ratios.empty()) return out;
  out.size_ratio = median(ratios);
  out.plausible = out.size_ratio >= 1.0 / kMaxSizeRatio && out.size_ratio <= kMaxSizeRatio;
  if (!out.plausible)
    for (const double mm : kUnitsTried) {
      const double ratio = out.size_ratio * mm / out.stated_mm_per_unit;
      if (ratio >= 1.0 / kMaxSizeRatio && ratio <= kMaxSizeRatio) out.looks_like = unit_name(mm);
    }
  return out;
}

UnitsCheck check_frames_units(std::span<const MarkerFrame> frames, const std::vector<std::string>& labels,
                              std::string_view units, const align::Calibration& calibration) {
  FaceSizeGauge gauge(labels, units, calibration);
  std::vector<double> ratios;
  const std::size_t step = std::max<std::size_t>(1, frames.size() / kFramesSampled);
  for (std::size_t f = 0; f < frames.size(); f += step)
    if (const auto ratio = gauge.size_ratio(frames[f])) ratios.push_back(*ratio);
  return units_verdict(ratios, gauge.stated_mm_per_unit());
}

UnitsCheck check_take_units(const formats::MarkerTake& take, std::string_view units, const align::Calibration& calibration) {
  return check_frames_units(take.frames, take.labels, units.empty() ? std::string_view(take.units) : units, calibration);
}

std::string describe_units(const UnitsCheck& check, std::string_view units, std::string_view stated,
                           std::string_view fix_format) {
  const std::string_view given = units.empty() ? stated : units;
  const std::string read_as = millimetres_per_unit(given)
                                  ? fmt::format("in {} as {}", unit_name(check.stated_mm_per_unit), units.empty() ? "it states" : "given")
                                  : fmt::format("in the calibration's {} ({})", unit_name(check.stated_mm_per_unit),
                                                given.empty() ? "it states no units" : fmt::format("'{}' is not mm, cm or m", given));
  const std::string size = fmt::format("read {}, its face is {:.3g} times the size of the calibrated one", read_as, check.size_ratio);
  if (check.looks_like)
    return fmt::format("{}: its values look like {}{}", size, *check.looks_like,
                       fix_format.empty() ? std::string() : "; " + fmt::format(fmt::runtime(fix_format), *check.looks_like));
  return fmt::format("{}, in no unit within {}x of it: is it the calibration's actor?", size, kMaxSizeRatio);
}

void require_plausible_units(const formats::MarkerTake& take, std::string_view units, const align::Calibration& calibration,
                             const std::string& name, std::string_view fix_format) {
  const UnitsCheck check = check_take_units(take, units, calibration);
  if (!check.plausible) throw file_error(name, describe_units(check, units, take.units, fix_format));
}

LiveUnitsCheck::LiveUnitsCheck(const std::vector<std::string>& labels, std::string_view units,
                               const align::Calibration& calibration)
    : gauge_(labels, units, calibration) {
  ratios_.reserve(kMaxFrames);
}

bool LiveUnitsCheck::add(const MarkerFrame& frame) {
  if (verdict_) return false;
  const auto ratio = gauge_.size_ratio(frame);
  if (!ratio) return false;
  if (ratios_.empty()) first_ns_ = frame.receive_time_ns;
  if (ratios_.size() < kMaxFrames) ratios_.push_back(*ratio);
  if (double(frame.receive_time_ns - first_ns_) < kLiveSeconds * 1e9 || ratios_.size() < kLiveMinFrames) return false;
  verdict_ = units_verdict(ratios_, gauge_.stated_mm_per_unit());
  return true;
}

}  // namespace facecap::pipeline
