#include "solver/align/calibrate_take.hpp"

#include <algorithm>
#include <limits>

#include <fmt/format.h>

#include "core/error.hpp"
#include "solver/align/stabilise.hpp"

namespace facecap::align {

std::vector<double> marker_mobility(const Rig& rig, const Calibration& calibration) {
  std::vector<double> out;
  for (const auto& m : calibration.markers) {
    double largest = 0.0;
    for (Eigen::Index s = 0; s < rig.shape_count(); ++s) {
      Eigen::Vector3d d = Eigen::Vector3d::Zero();
      for (int i = 0; i < 3; ++i) d += m.binding.barycentric[i] * rig.deltas.block<3, 1>(3 * m.binding.vertices[std::size_t(i)], s);
      largest = std::max(largest, d.norm());
    }
    out.push_back(largest);
  }
  return out;
}

TakeCalibration calibrate_take(const Rig& rig, const std::vector<std::string>& labels, std::span<const MarkerFrame> frames,
                               const TakeCalibrationOptions& o) {
  if (frames.empty()) throw Error("calibrate: the take has no frames");
  TakeCalibration t;
  const bool given_stable = !o.stable_slots.empty();
  t.stable_slots = given_stable ? o.stable_slots : find_stable_markers(frames, o.stable_count);
  if (o.frame) {
    if (*o.frame >= frames.size()) throw Error(fmt::format("calibrate: frame index {} outside the take's {}", *o.frame, frames.size()));
    t.frame = *o.frame;
  } else {
    t.neutral = find_neutral_frame(frames, t.stable_slots, o.neutral);
    t.frame = t.neutral->frame_index;
  }
  if (o.average > 0) {
    t.count = std::min<std::size_t>(std::size_t(o.average), frames.size());
    t.first = t.frame >= t.count / 2 ? t.frame - t.count / 2 : 0;
    t.first = std::min(t.first, frames.size() - t.count);
  } else if (t.neutral) {
    t.first = t.neutral->window_start;
    t.count = t.neutral->window_frames;
  } else {
    t.first = t.frame;
    t.count = 1;
  }
  auto run = [&] {
    std::vector<uint8_t> present;
    if (t.count > 1) {
      t.positions = average_positions(frames, t.first, t.count, t.frame, t.stable_slots, present);
    } else {
      const MarkerFrame& f = frames[t.frame];
      t.positions.resize(3, Eigen::Index(f.markers.size()));
      present.assign(f.markers.size(), 0);
      for (std::size_t k = 0; k < f.markers.size(); ++k) t.positions.col(Eigen::Index(k)) = f.markers[k].position, present[k] = f.markers[k].present();
    }
    t.calibration = calibrate(rig, labels, t.positions, present, o.calibration);
  };
  run();
  if (!given_stable) {
    // Candidates: the half of the markers the rig moves least at their bound points.
    const auto mobility = marker_mobility(rig, t.calibration);
    std::vector<double> per_slot(labels.size(), std::numeric_limits<double>::infinity());
    for (std::size_t m = 0; m < t.calibration.markers.size(); ++m) {
      const auto it = std::find(labels.begin(), labels.end(), t.calibration.markers[m].label);
      per_slot[std::size_t(it - labels.begin())] = mobility[m];
    }
    const auto refined = find_stable_markers(frames, o.stable_count, nullptr, per_slot);
    if (refined != t.stable_slots) {
      t.stable_slots = refined;
      run();
    }
  }
  for (int s : t.stable_slots)
    if (t.calibration.find(labels[std::size_t(s)]) >= 0) t.calibration.stable_markers.push_back(labels[std::size_t(s)]);
  if (t.calibration.stable_markers.size() < 3)
    throw Error(fmt::format("calibrate: only {} stable markers are present in the calibration frame; 3 are needed",
                            t.calibration.stable_markers.size()));
  find_unobserved_shapes(t.calibration, rig);
  return t;
}

}  // namespace facecap::align
