#include "pipeline/source_units.hpp"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>

#include "core/error.hpp"
#include "core/units.hpp"

namespace facecap::pipeline {
namespace {

constexpr std::size_t kFramesSampled = 200;  // spread over the take
constexpr double kUnitsTried[] = {1.0, 10.0, 1000.0};

// RMS distance of points from their centroid.
double spread(const Eigen::Matrix3Xd& points) {
  return std::sqrt((points.colwise() - points.rowwise().mean()).colwise().squaredNorm().mean());
}

}  // namespace

UnitsCheck check_take_units(const formats::MarkerTake& take, std::string_view units, const align::Calibration& calibration) {
  UnitsCheck out;
  out.stated_mm_per_unit = millimetres_per_unit(units.empty() ? std::string_view(take.units) : units)
                               .value_or(calibration.take_mm_per_unit);
  // Per take slot, the calibration's neutral position (take units), if it has the label.
  std::vector<const Eigen::Vector3d*> neutral(take.labels.size(), nullptr);
  for (std::size_t s = 0; s < take.labels.size(); ++s) neutral[s] = calibration.neutral_of(take.labels[s]);

  std::vector<double> ratios;
  const std::size_t step = std::max<std::size_t>(1, take.frames.size() / kFramesSampled);
  Eigen::Matrix3Xd now(3, Eigen::Index(take.labels.size())), then(3, Eigen::Index(take.labels.size()));
  for (std::size_t f = 0; f < take.frames.size(); f += step) {
    Eigen::Index n = 0;
    const MarkerFrame& frame = take.frames[f];
    for (std::size_t s = 0; s < neutral.size() && s < frame.markers.size(); ++s) {
      if (!neutral[s] || !frame.markers[s].present() || !frame.markers[s].position.allFinite()) continue;
      now.col(n) = frame.markers[s].position;
      then.col(n) = *neutral[s];
      ++n;
    }
    if (n < 3) continue;
    const double calibrated = spread(then.leftCols(n)) * calibration.take_mm_per_unit;
    if (calibrated > 0.0) ratios.push_back(spread(now.leftCols(n)) * out.stated_mm_per_unit / calibrated);
  }
  if (ratios.empty()) return out;
  std::nth_element(ratios.begin(), ratios.begin() + std::ptrdiff_t(ratios.size() / 2), ratios.end());
  out.size_ratio = ratios[ratios.size() / 2];
  out.plausible = out.size_ratio >= 1.0 / kMaxSizeRatio && out.size_ratio <= kMaxSizeRatio;
  if (!out.plausible)
    for (const double mm : kUnitsTried) {
      const double ratio = out.size_ratio * mm / out.stated_mm_per_unit;
      if (ratio >= 1.0 / kMaxSizeRatio && ratio <= kMaxSizeRatio) out.looks_like = unit_name(mm);
    }
  return out;
}

void require_plausible_units(const formats::MarkerTake& take, std::string_view units, const align::Calibration& calibration,
                             const std::string& name) {
  const UnitsCheck check = check_take_units(take, units, calibration);
  if (check.plausible) return;
  const std::string_view given = units.empty() ? std::string_view(take.units) : units;
  const std::string read_as = millimetres_per_unit(given)
                                  ? fmt::format("in {} as {}", unit_name(check.stated_mm_per_unit), units.empty() ? "it states" : "given")
                                  : fmt::format("in the calibration's {} ({})", unit_name(check.stated_mm_per_unit),
                                                given.empty() ? "it states no units" : fmt::format("'{}' is not mm, cm or m", given));
  const std::string size = fmt::format("read {}, its face is {:.3g} times the size of the calibrated one", read_as, check.size_ratio);
  if (check.looks_like)
    throw file_error(name, fmt::format("{}: its values look like {}; pass --units {} if they are", size, *check.looks_like,
                                       *check.looks_like));
  throw file_error(name, fmt::format("{}, in no unit within {}x of it: is it the calibration's actor?", size, kMaxSizeRatio));
}

}  // namespace facecap::pipeline
