#pragma once
// Calibration of a whole take, as `facecap calibrate` runs it:
//   0. marker slots present in fewer than half of the frames (a ghost or spare slot such
//      as "Unlabeled") are left out of everything below, with a note;
//   1. provisional stable markers from the take alone (mutual distances vary least);
//   2. the calibration frame: given, or the most neutral stretch (find_neutral_frame);
//   3. the mean of a still stretch around it, head motion removed (average_positions);
//   4. calibrate() on that mean, head markers left out of the fit;
//   5. head markers found: bound markers farther than head_marker_mm (actor mm) from the
//      fitted face that are rigid with one another (a headband, a cap, a helmet; a lone
//      one: rigid with the stable markers) become head markers (head pose only, never
//      bound), then step 4 again without them;
//   6. final stable markers: the same search restricted to the markers the rig's shapes
//      move least at their bound points (a jaw moves rigidly too, but it is not the
//      skull) and the head markers, then steps 3-4 again with them when they changed;
//   7. the shapes the bound markers cannot observe (find_unobserved_shapes).
// Not real-time.
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "core/frame.hpp"
#include "solver/align/calibrate.hpp"
#include "solver/align/neutral.hpp"
#include "solver/rig.hpp"

namespace facecap::align {

struct TakeCalibrationOptions {
  CalibrationOptions calibration;
  NeutralSearchOptions neutral;          // rate and provisional units for the neutral search
  std::optional<std::size_t> frame;      // index into frames; nullopt: auto-neutral
  int average = 0;                       // frames averaged around the frame; 0: the neutral stretch, or 1 with frame
  std::vector<int> stable_slots;         // given stable markers (skip the search), else empty
  int stable_count = 6;
  std::vector<int> head_slots;           // given head markers: head pose only, never bound
  bool find_head_markers = true;         // step 5
  double head_marker_mm = 20.0;          // actor mm off the fitted face, beyond any face marker on real takes (AnimFace: 13)
  double head_rigidity_mm = 0.5;         // a rig's pairwise distance deviation may exceed the take's most rigid pair's by this
  double head_wobble_mm = 2.0;           // a candidate's median deviation to a rig found, for it to join (a loose marker)
};

struct TakeCalibration {
  Calibration calibration;          // stable_markers filled in
  std::vector<int> stable_slots;
  std::vector<int> head_slots;      // given and found
  std::vector<int> found_head_slots;  // found by step 5
  std::vector<int> ignored_slots;   // present in fewer than half of the frames
  std::optional<NeutralFrame> neutral;  // when auto-neutral ran
  std::size_t frame = 0;            // index of the calibration frame
  std::size_t first = 0, count = 1; // frames averaged
  Eigen::Matrix3Xd positions;       // 3 x K (take slot order) the calibration used
};

// Throws Error (from the steps above) on unusable takes.
TakeCalibration calibrate_take(const Rig& rig, const std::vector<std::string>& labels, std::span<const MarkerFrame> frames,
                               const TakeCalibrationOptions& options);

// How far the rig's shapes move each calibrated marker's bound point: the largest shape
// delta there (rig units), in calibration marker order.
std::vector<double> marker_mobility(const Rig& rig, const Calibration& calibration);

}  // namespace facecap::align
