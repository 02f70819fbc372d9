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

namespace {

bool contains(const std::vector<int>& v, int x) { return std::find(v.begin(), v.end(), x) != v.end(); }

// Step 5: bound markers far off the fitted face whose distances to the stable markers vary
// little more than the stable markers' own.
std::vector<int> find_head_markers(std::span<const MarkerFrame> frames, const std::vector<std::string>& labels,
                                   const TakeCalibration& t, const TakeCalibrationOptions& o) {
  const Calibration& c = t.calibration;
  const double take_mm = c.take_mm_per_unit;
  double own = 0;
  int pairs = 0;
  for (std::size_t i = 0; i < t.stable_slots.size(); ++i)
    for (std::size_t j = i + 1; j < t.stable_slots.size(); ++j)
      own += distance_deviation(frames, t.stable_slots[i], t.stable_slots[j]) * take_mm, ++pairs;
  own /= std::max(pairs, 1);
  std::vector<int> found;
  for (const auto& m : c.markers) {
    if (m.residual_mm * c.face_size_ratio() < o.head_marker_mm) continue;
    const int slot = int(std::find(labels.begin(), labels.end(), m.label) - labels.begin());
    std::vector<double> deviation;
    for (int s : t.stable_slots)
      if (s != slot) deviation.push_back(distance_deviation(frames, slot, s) * take_mm);
    if (deviation.size() < 3) continue;
    std::nth_element(deviation.begin(), deviation.begin() + std::ptrdiff_t(deviation.size() / 2), deviation.end());
    if (deviation[deviation.size() / 2] <= own + o.head_rigidity_mm) found.push_back(slot);
  }
  return found;
}

std::string quoted_labels(const std::vector<std::string>& labels, const std::vector<int>& slots) {
  std::string out;
  for (int s : slots) out += fmt::format("{}'{}'", out.empty() ? "" : ", ", labels[std::size_t(s)]);
  return out;
}

}  // namespace

TakeCalibration calibrate_take(const Rig& rig, const std::vector<std::string>& labels, std::span<const MarkerFrame> frames,
                               const TakeCalibrationOptions& o) {
  if (frames.empty()) throw Error("calibrate: the take has no frames");
  TakeCalibration t;
  const std::vector<uint8_t> frequent = mostly_present_slots(frames);
  for (std::size_t k = 0; k < frequent.size(); ++k)
    if (!frequent[k]) t.ignored_slots.push_back(int(k));
  t.head_slots = o.head_slots;
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
      t.positions = average_positions(frames, t.first, t.count, t.frame, t.stable_slots, o.neutral.min_presence, present);
    } else {
      const MarkerFrame& f = frames[t.frame];
      t.positions.resize(3, Eigen::Index(f.markers.size()));
      present.assign(f.markers.size(), 0);
      for (std::size_t k = 0; k < f.markers.size(); ++k) t.positions.col(Eigen::Index(k)) = f.markers[k].position, present[k] = f.markers[k].present();
    }
    // The fit sees the face markers only: neither rarely present slots nor head markers.
    std::vector<std::string> fit_labels;
    std::vector<uint8_t> fit_present;
    std::vector<int> fit_slots;
    for (std::size_t k = 0; k < labels.size(); ++k)
      if (frequent[k] && !contains(t.head_slots, int(k))) fit_slots.push_back(int(k));
    Eigen::Matrix3Xd fit_positions(3, Eigen::Index(fit_slots.size()));
    for (std::size_t i = 0; i < fit_slots.size(); ++i) {
      fit_labels.push_back(labels[std::size_t(fit_slots[i])]);
      fit_present.push_back(present[std::size_t(fit_slots[i])]);
      fit_positions.col(Eigen::Index(i)) = t.positions.col(fit_slots[i]);
    }
    t.calibration = calibrate(rig, fit_labels, fit_positions, fit_present, o.calibration);
    for (int h : t.head_slots) {
      if (present[std::size_t(h)]) t.calibration.head_markers.push_back({labels[std::size_t(h)], t.positions.col(h)});
      else t.calibration.notes.push_back(fmt::format("head marker '{}' is missing in the calibration frame and is left out", labels[std::size_t(h)]));
    }
  };
  run();
  if (o.find_head_markers) {
    t.found_head_slots = find_head_markers(frames, labels, t, o);
    if (!t.found_head_slots.empty()) {
      t.head_slots.insert(t.head_slots.end(), t.found_head_slots.begin(), t.found_head_slots.end());
      run();
    }
  }
  if (!given_stable) {
    // Candidates: the half of the markers the rig moves least at their bound points, and
    // the head markers, which it does not move at all.
    const auto mobility = marker_mobility(rig, t.calibration);
    std::vector<double> per_slot(labels.size(), std::numeric_limits<double>::infinity());
    for (std::size_t m = 0; m < t.calibration.markers.size(); ++m) {
      const auto it = std::find(labels.begin(), labels.end(), t.calibration.markers[m].label);
      per_slot[std::size_t(it - labels.begin())] = mobility[m];
    }
    for (int h : t.head_slots) per_slot[std::size_t(h)] = 0.0;
    const auto refined = find_stable_markers(frames, o.stable_count, nullptr, per_slot);
    if (refined != t.stable_slots) {
      t.stable_slots = refined;
      run();
    }
  }
  if (!t.ignored_slots.empty())
    t.calibration.notes.push_back(fmt::format("{} present in fewer than half of the take's frames: left out (a ghost or "
                                              "spare slot, or a marker lost for most of the take)",
                                              quoted_labels(labels, t.ignored_slots)));
  if (!t.found_head_slots.empty())
    t.calibration.notes.push_back(fmt::format("{} more than {:.0f} mm off the fitted face and rigid with the head: head "
                                              "markers (head pose only, not bound)",
                                              quoted_labels(labels, t.found_head_slots), o.head_marker_mm));
  for (int s : t.stable_slots)
    if (t.calibration.neutral_of(labels[std::size_t(s)])) t.calibration.stable_markers.push_back(labels[std::size_t(s)]);
  if (t.calibration.stable_markers.size() < 3)
    throw Error(fmt::format("calibrate: only {} stable markers are present in the calibration frame; 3 are needed",
                            t.calibration.stable_markers.size()));
  find_unobserved_shapes(t.calibration, rig);
  return t;
}

}  // namespace facecap::align
