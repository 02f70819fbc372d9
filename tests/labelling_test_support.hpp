#pragma once
// Label recovery tests: a clean labelled take disturbed as capture systems disturb it
// (a label swap for good, an occlusion while the head moves, a ghost point), fed through
// SolvePipeline's label check (the take's slots) or labelling (an unlabelled cloud), and
// scored frame by frame against the clean take.
#include <algorithm>
#include <cstddef>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/frame.hpp"
#include "pipeline/solve_pipeline.hpp"

namespace facecap::test {

struct LabelEvents {
  std::size_t swap_a = 0, swap_b = 0;  // these two slots' labels exchanged ...
  std::size_t swap_from = 0;           // ... from this frame to the end (check only: a cloud has no labels)
  std::size_t occluded = 0;            // this slot missing ...
  std::size_t occluded_from = 0, occluded_to = 0;  // ... in [from, to), while
  Eigen::Vector3d head_move = Eigen::Vector3d::Zero();  // every marker moves by this (spread over the occlusion; kept)
  std::size_t ghosted = 0;             // a ghost this far from this slot's marker ...
  Eigen::Vector3d ghost_offset = Eigen::Vector3d::Zero();
  std::size_t ghost_from = 0, ghost_to = 0;  // ... in [from, to) (check: the ghost comes labelled as it, its point lost)
};

// Per frame, whether the labelled frame the pipeline solved from was right: every marker
// whose true point the source delivered has exactly that point, every other is missing.
// `labels`: the clean take's slots; `frames`: its frames. `cloud`: label an unlabelled cloud
// (the points shuffled, the ghost one more point) instead of checking the labels.
inline std::vector<bool> labelled_frames_right(const Rig& rig, const align::Calibration& calibration,
                                               const std::vector<std::string>& labels, const std::vector<MarkerFrame>& frames,
                                               const std::string& units, const LabelEvents& e, bool cloud) {
  pipeline::SolveSettings settings;
  settings.method = SolverMethod::kLinear;  // the labelling is under test: the fast solver
  settings.params.collision_region = CollisionRegion::kNone;
  settings.check_labels = !cloud;
  settings.label_markers = cloud;
  std::vector<std::string> slots = labels;
  if (cloud) {
    slots.clear();
    for (std::size_t k = 0; k < labels.size() + 1; ++k) slots.push_back("unlabelled_" + std::to_string(k + 1));
  }
  pipeline::SolvePipeline pipeline(rig, calibration, {slots, units}, settings);
  SolvedFrame solved = pipeline.make_solved_frame(false);
  std::mt19937 rng(23);
  std::vector<bool> right;
  MarkerFrame source = make_marker_frame(slots);
  for (std::size_t f = 0; f < frames.size(); ++f) {
    // The truth this frame: each label's point as delivered, or nothing.
    const double moved = e.occluded_to > e.occluded_from
                             ? std::clamp(double(f) - double(e.occluded_from), 0.0, double(e.occluded_to - e.occluded_from)) /
                                   double(e.occluded_to - e.occluded_from)
                             : 0.0;
    std::vector<std::optional<Eigen::Vector3d>> truth(labels.size());
    for (std::size_t s = 0; s < labels.size(); ++s)
      if (frames[f].markers[s].present()) truth[s] = Eigen::Vector3d(frames[f].markers[s].position + moved * e.head_move);
    const bool occluding = f >= e.occluded_from && f < e.occluded_to, ghosting = f >= e.ghost_from && f < e.ghost_to;
    std::optional<Eigen::Vector3d> ghost;
    if (ghosting && truth[e.ghosted]) ghost = *truth[e.ghosted] + e.ghost_offset;
    if (occluding) truth[e.occluded].reset();
    if (ghosting && !cloud) truth[e.ghosted].reset();  // the source labelled the ghost as it

    if (cloud) {
      std::vector<Eigen::Vector3d> points;
      for (const auto& t : truth)
        if (t) points.push_back(*t);
      if (ghost) points.push_back(*ghost);
      std::shuffle(points.begin(), points.end(), rng);
      for (std::size_t k = 0; k < slots.size(); ++k) {
        source.markers[k].flags = k < points.size() ? kMarkerUnlabelled : kMarkerUnlabelled | kMarkerMissing;
        source.markers[k].position = k < points.size() ? points[k] : Eigen::Vector3d::Zero();
      }
    } else {
      for (std::size_t s = 0; s < slots.size(); ++s) {
        source.markers[s].flags = truth[s] ? 0u : uint32_t(kMarkerMissing);
        source.markers[s].position = truth[s].value_or(Eigen::Vector3d::Zero());
      }
      if (ghost) source.markers[e.ghosted].flags = 0, source.markers[e.ghosted].position = *ghost;
      if (f >= e.swap_from && e.swap_a != e.swap_b) std::swap(source.markers[e.swap_a], source.markers[e.swap_b]);
    }
    source.frame_no = frames[f].frame_no;
    source.source_time_ns = frames[f].source_time_ns;
    pipeline.process(source, solved);

    const MarkerFrame& out = pipeline.labelled_frame();
    bool ok = true;
    for (std::size_t s = 0; s < labels.size(); ++s) {
      const auto it = cloud ? std::find_if(out.markers.begin(), out.markers.end(),
                                           [&](const Marker& m) { return m.label.view() == labels[s]; })
                            : out.markers.begin() + std::ptrdiff_t(s);
      if (it == out.markers.end()) continue;  // not a calibrated marker
      ok &= truth[s] ? it->present() && it->position == *truth[s] : !it->present();
    }
    right.push_back(ok);
  }
  return right;
}

// Frames from `from` until the labelling is right for `settled` frames in a row (the
// remaining frames when it never is).
inline std::size_t frames_to_recover(const std::vector<bool>& right, std::size_t from, std::size_t settled = 10) {
  for (std::size_t f = from; f + settled <= right.size(); ++f)
    if (std::all_of(right.begin() + std::ptrdiff_t(f), right.begin() + std::ptrdiff_t(f + settled), [](bool b) { return b; }))
      return f - from;
  return right.size() - from;
}

}  // namespace facecap::test
