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

// Step 5: head markers. A head rig is rigid: the distances between its markers stay
// constant over the take, however far it sits from the skin. Candidates are the bound
// markers farther than head_marker_mm off the fitted face. Two or more candidates whose
// pairwise distance deviations are all within head_rigidity_mm of the take's most rigid
// pair (the noise floor) are a rig, judged among themselves: the stable markers may hold
// face markers, whose expressions would hide the rig's rigidity. A candidate whose median
// deviation to that rig is within head_wobble_mm (a marker on a loose stalk) joins it. A
// lone candidate is judged against the stable markers: its median deviation to them at
// most theirs plus head_rigidity_mm.
std::vector<int> find_head_markers(std::span<const MarkerFrame> frames, const std::vector<std::string>& labels,
                                   const std::vector<uint8_t>& frequent, const TakeCalibration& t,
                                   const TakeCalibrationOptions& o) {
  const Calibration& c = t.calibration;
  const double take_mm = c.take_mm_per_unit;
  std::vector<int> candidates;
  for (const auto& m : c.markers) {
    if (m.residual_mm * c.face_size_ratio() < o.head_marker_mm) continue;
    candidates.push_back(int(std::find(labels.begin(), labels.end(), m.label) - labels.begin()));
  }
  if (candidates.empty()) return {};
  double floor = std::numeric_limits<double>::infinity();
  for (std::size_t a = 0; a < frequent.size(); ++a)
    for (std::size_t b = a + 1; b < frequent.size(); ++b)
      if (frequent[a] && frequent[b]) floor = std::min(floor, distance_deviation(frames, int(a), int(b)) * take_mm);
  const std::size_t n = candidates.size();
  std::vector<double> deviation(n * n, 0.0);
  for (std::size_t i = 0; i < n; ++i)
    for (std::size_t j = i + 1; j < n; ++j)
      deviation[i * n + j] = deviation[j * n + i] = distance_deviation(frames, candidates[i], candidates[j]) * take_mm;
  const double rigid = floor + o.head_rigidity_mm;
  // The largest set of candidates rigid pair by pair: grown greedily from each seed (a
  // take holds a handful of candidates).
  std::vector<std::size_t> rig_set;
  for (std::size_t seed = 0; seed < n; ++seed) {
    std::vector<std::size_t> set{seed};
    for (std::size_t i = 0; i < n; ++i)
      if (i != seed && std::all_of(set.begin(), set.end(), [&](std::size_t j) { return deviation[i * n + j] <= rigid; }))
        set.push_back(i);
    if (set.size() > rig_set.size()) rig_set = set;
  }
  std::vector<int> found;
  if (rig_set.size() >= 2) {
    for (std::size_t i = 0; i < n; ++i) {
      std::vector<double> to_rig;
      for (const std::size_t j : rig_set)
        if (j != i) to_rig.push_back(deviation[i * n + j]);
      std::nth_element(to_rig.begin(), to_rig.begin() + std::ptrdiff_t(to_rig.size() / 2), to_rig.end());
      const bool in_rig = std::find(rig_set.begin(), rig_set.end(), i) != rig_set.end();
      if (in_rig || to_rig[to_rig.size() / 2] <= o.head_wobble_mm) found.push_back(candidates[i]);
    }
    std::sort(found.begin(), found.end());
    return found;
  }
  double own = 0;
  int pairs = 0;
  for (std::size_t i = 0; i < t.stable_slots.size(); ++i)
    for (std::size_t j = i + 1; j < t.stable_slots.size(); ++j)
      own += distance_deviation(frames, t.stable_slots[i], t.stable_slots[j]) * take_mm, ++pairs;
  own /= std::max(pairs, 1);
  for (const int slot : candidates) {
    std::vector<double> to_stable;
    for (int s : t.stable_slots)
      if (s != slot) to_stable.push_back(distance_deviation(frames, slot, s) * take_mm);
    if (to_stable.size() < 3) continue;
    std::nth_element(to_stable.begin(), to_stable.begin() + std::ptrdiff_t(to_stable.size() / 2), to_stable.end());
    if (to_stable[to_stable.size() / 2] <= own + o.head_rigidity_mm) found.push_back(slot);
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
    t.found_head_slots = find_head_markers(frames, labels, frequent, t, o);
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
