#pragma once
// From a source's marker frame to solver targets in rig space; the one mapper facecapd
// and every tool use. Per frame:
//   1. head stabilisation: a robust rigid fit of the stable markers from their
//      calibration-frame positions to this frame (align::HeadStabiliser);
//   2. each bound marker's offset from its own calibration-frame position, in the
//      stabilised head frame, mapped into rig space by the calibration's similarity;
//   3. target = the marker's bound surface point + that offset;
//   4. plausibility gate: a target that moved faster than options.max_marker_speed_mm_s
//      (rig space, after stabilisation) from where that marker was last accepted is left
//      out of this frame, so that one glitch costs one frame.
// Steps 2-3 handle identity mismatch: the actor at rest gives exactly the bound points,
// so the rig's neutral, whatever the actor's face looks like. Frames in other units than
// the calibration's are converted on the way in.
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "core/frame.hpp"
#include "solver/align/calibration.hpp"
#include "solver/align/stabilise.hpp"

namespace facecap::pipeline {

struct MappedFrame {
  Eigen::Matrix3Xd targets;      // 3 x K (calibration marker order), rig space; NaN when missing
  std::vector<uint8_t> present;  // K
  uint32_t markers_present = 0;
  uint32_t markers_implausible = 0;  // left out by the plausibility gate this frame
  // Head pose relative to the calibration frame, in rig axes and rig units: a point
  // fixed to the head at x (rig space, calibration frame) is at R x + t now.
  Eigen::Quaterniond head_rotation = Eigen::Quaterniond::Identity();
  Eigen::Vector3d head_translation = Eigen::Vector3d::Zero();
  bool head_held = false;        // too few stable markers: the last pose reused
  int stable_inliers = 0;
  double stable_rms_mm = 0.0;    // inlier residual RMS of the stable markers, actor mm
};

struct MapperOptions {
  // Fit the head's rigid motion to the calibration's stable markers each frame. Without
  // it (or with fewer than 3 stable markers in the frames) the head stays at rest.
  bool stabilise_head = true;
  // A stable marker off the rigid fit by more than this (and 4x the others' median) is
  // left out of the head pose.
  double outlier_floor_mm = 1.0;
  // A marker target (rig space, head stabilised) that moved faster than this since the
  // marker was last accepted is left out of the frame; 0 turns the gate off. The allowed
  // distance grows with the time since that acceptance, so a marker back from an
  // occlusion (or rejected a while) is taken again once it is within reach.
  double max_marker_speed_mm_s = 1000.0;
};

class MarkerMapper {
 public:
  // frame_labels: the label of each marker slot of the frames to come (a take's labels,
  // a source's SourceInfo::labels); source_units: their units ("mm", "cm", "m"; empty:
  // the calibration's). Throws Error when fewer than 3 of the calibration's markers are
  // among the labels. Not RT-safe.
  MarkerMapper(const align::Calibration& calibration, std::span<const std::string> frame_labels,
               std::string_view source_units, MapperOptions options = {});

  MappedFrame make_output() const;
  // marker_flags (one per frame slot, may be empty) gains kMarkerOutlier for stable
  // markers the stabiliser rejected and for markers the plausibility gate left out
  // (timed by frame.source_time_ns; a frame whose time does not advance is not gated).
  // RT-safe.
  void process(const MarkerFrame& frame, MappedFrame& out, std::span<uint32_t> marker_flags = {}) noexcept;
  // Forgets the head pose held from earlier frames and where markers were last accepted.
  // RT-safe.
  void reset() noexcept;

  // What the mapper carries from one frame to the next: the head pose a frame with too few
  // stable markers holds, and the plausibility gate's last accepted targets.
  struct State {
    align::Similarity head_pose;       // source units (identity when not stabilising)
    Eigen::Matrix3Xd accepted_targets;  // 3 x K, rig units
    std::vector<int64_t> accepted_ns;   // K
  };
  // A state sized for this mapper. Not RT-safe.
  State make_state() const;
  // Copies the mapper's state into `state`; false (nothing copied) when it was not sized
  // for this mapper. RT-safe.
  bool save(State& state) const noexcept;
  // Continues from `state`; false (nothing changed) when its marker count is not this
  // mapper's. RT-safe.
  bool restore(const State& state) noexcept;

  Eigen::Index marker_count() const { return Eigen::Index(slots_.size()); }
  std::span<const int> slots() const { return slots_; }          // per calibration marker: frame slot or -1
  std::span<const uint8_t> is_stable() const { return stable_; }  // per calibration marker
  std::size_t markers_found() const noexcept { return found_; }
  // Stable markers among the frame labels (bound and head markers), and whether the head
  // is stabilised (options.stabilise_head and at least 3 of them).
  std::size_t stable_markers_found() const noexcept { return stable_found_; }
  bool stabilising() const noexcept { return stabilising_; }
  // Per stable marker found, its distance from the rigid fit in the last frame, in mm
  // (NaN when missing). RT-safe.
  double stable_residual_mm(std::size_t i) const noexcept { return stabiliser_->residuals()[i] * source_mm_; }
  std::size_t stable_residual_count() const noexcept { return stabiliser_ ? stabiliser_->residuals().size() : 0; }
  // Source units to calibration take units (1 when they agree or either is unknown).
  double source_to_take() const noexcept { return source_to_take_; }
  const align::Calibration& calibration() const noexcept { return calibration_; }

 private:
  align::Calibration calibration_;
  std::vector<int> slots_;
  std::vector<uint8_t> stable_;
  std::size_t found_ = 0, stable_found_ = 0;
  bool stabilising_ = false;
  double source_to_take_ = 1.0;
  double source_mm_ = 1.0;  // millimetres per source unit
  // Whether marker k's new target is within reach of where it was last accepted (and
  // finite); if so it becomes the last accepted. RT-safe.
  bool plausible(std::size_t k, const Eigen::Vector3d& target, int64_t time_ns) noexcept;
  // Every marker back to "never accepted", at its rest target. RT-safe.
  void forget_accepted() noexcept;

  std::optional<align::HeadStabiliser> stabiliser_;  // when stabilising
  align::HeadPoseResult pose_;
  // The plausibility gate: per calibration marker, its last accepted target (rig units)
  // and that frame's source time (kNeverAccepted before the first, the target then being
  // the marker's bound point).
  double max_speed_rig_per_ns_ = 0.0;  // 0: no gate
  Eigen::Matrix3Xd accepted_targets_;
  std::vector<int64_t> accepted_ns_;
};

}  // namespace facecap::pipeline
