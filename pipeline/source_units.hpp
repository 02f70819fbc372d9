#pragma once
// Whether a take's or a live source's values are in the units they state. The marker
// mapper converts frames from the units they state to the calibration's; a take whose
// header says mm while its values are cm would be solved 10 times too small (a face frozen
// at the neutral, a head metres away) with no warning. The calibration knows the actor's
// face in its own units (the markers' neutral positions), so frames of the same actor must
// be about that size once converted: one read in the wrong units is off by a factor of 10
// or more. A take is checked whole before it is solved (check_take_units); a live source
// from its first seconds of frames (LiveUnitsCheck). Both measure a frame's size with
// FaceSizeGauge. Not real-time code.
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include "core/frame.hpp"
#include "formats/take.hpp"
#include "solver/align/calibration.hpp"

namespace facecap::pipeline {

struct UnitsCheck {
  double stated_mm_per_unit = 0.0;  // the units the frames are read in (the calibration's when unstated or unknown)
  // The frames' face size over the calibration's, both in mm, for the markers they share
  // (median over frames of the RMS distance from their centre); 0 when no frame has 3 of them.
  double size_ratio = 0.0;
  // When the size is implausible: the unit (mm, cm or m) that gives the calibration's size,
  // if one does within the band.
  std::optional<std::string> looks_like;
  bool plausible = true;
};

// Frames may be kMaxSizeRatio times larger or smaller than the calibrated face
// (expressions, a different actor on the same profile); a wrong unit is a factor of 10.
inline constexpr double kMaxSizeRatio = 2.0;

// One frame's face size against the calibration's, for frames with `labels` slots read in
// `units` (empty or unknown: the calibration's).
class FaceSizeGauge {
 public:
  FaceSizeGauge(const std::vector<std::string>& labels, std::string_view units, const align::Calibration& calibration);
  // The frame's face size over the calibration's, both in mm; nullopt when the frame has
  // too few markers to say. Labelled slots: the RMS distance from their centre of the
  // frame's markers that the calibration has, over the same of its neutral positions (3 at
  // least). When no slot carries a calibrated label (an unlabelled point cloud: cameras,
  // calibration.label_markers): the median distance of the present points from their
  // coordinate-wise median, over the same of every calibrated marker (face and head), with
  // at least half as many points as those markers; the medians let a few ghosts or another
  // actor's stray markers pass. Allocates nothing.
  std::optional<double> size_ratio(const MarkerFrame& frame);
  double stated_mm_per_unit() const noexcept { return stated_mm_per_unit_; }
  bool by_label() const noexcept { return by_label_; }

 private:
  std::optional<double> cloud_size_ratio(const MarkerFrame& frame);

  double stated_mm_per_unit_;
  double calibration_mm_per_unit_;
  std::vector<const Eigen::Vector3d*> neutral_;  // per slot, the calibration's position (its units) or nullptr
  bool by_label_ = false;                        // some slot has a calibrated label
  Eigen::Matrix3Xd now_, then_;                  // 3 x slots, scratch
  double calibrated_cloud_mm_ = 0.0;             // unlabelled: the calibrated markers' median distance, mm
  std::size_t min_cloud_points_ = 3;
  std::vector<double> scratch_;                  // slots: distances for the medians
};

// The verdict on frames' size ratios (FaceSizeGauge), their median against kMaxSizeRatio;
// reorders `ratios`.
UnitsCheck units_verdict(std::vector<double>& ratios, double stated_mm_per_unit);

// Recorded frames with `labels` slots, read in `units`, against the calibration: a sample
// of up to 200 frames spread over them.
UnitsCheck check_frames_units(std::span<const MarkerFrame> frames, const std::vector<std::string>& labels,
                              std::string_view units, const align::Calibration& calibration);
// A take read in `units` (empty: as it states them) against the calibration.
UnitsCheck check_take_units(const formats::MarkerTake& take, std::string_view units, const align::Calibration& calibration);

// For a person: "<read in cm as it states>, its face is 10 times the size of the calibrated
// one: its values look like mm; <fix>", fix_format's {} replaced by the unit it looks like
// (e.g. "pass --units {} if they are"). `units`: the units given, empty when the frames'
// own were used (`stated`).
std::string describe_units(const UnitsCheck& check, std::string_view units, std::string_view stated,
                           std::string_view fix_format);

// Throws Error naming `name` when check_take_units finds the take implausible, saying the
// units it looks like and how to say so: fix_format as describe_units takes it.
void require_plausible_units(const formats::MarkerTake& take, std::string_view units, const align::Calibration& calibration,
                             const std::string& name, std::string_view fix_format = "pass --units {} if they are");

// A live source's units, judged from its first frames: frames are added (off the solve
// thread) until kLiveSeconds of them, by their arrival, have had 3 of the calibration's
// markers, and at least kLiveMinFrames such frames; then the verdict stands.
class LiveUnitsCheck {
 public:
  static constexpr double kLiveSeconds = 2.0;
  static constexpr std::size_t kLiveMinFrames = 30;
  static constexpr std::size_t kMaxFrames = 2000;  // the ratios kept, whatever the rate

  LiveUnitsCheck(const std::vector<std::string>& labels, std::string_view units, const align::Calibration& calibration);
  // Adds a frame; true when this frame settled the verdict. Not RT-safe.
  bool add(const MarkerFrame& frame);
  // Set once decided.
  const std::optional<UnitsCheck>& verdict() const noexcept { return verdict_; }

 private:
  FaceSizeGauge gauge_;
  std::vector<double> ratios_;
  int64_t first_ns_ = 0;
  std::optional<UnitsCheck> verdict_;
};

}  // namespace facecap::pipeline
