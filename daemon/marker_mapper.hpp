#pragma once
// From a source's marker frame to the solver's input: picks each bound marker out of the
// frame by label, scales and transforms it into rig space, (with head markers) fits the
// head's rigid pose and moves the face markers into head space, and takes off each
// marker's calibrated offset.
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "core/frame.hpp"
#include "daemon/calibration.hpp"
#include "solver/align/stabilise.hpp"

namespace facecap::daemon {

struct MappedFrame {
  uint32_t face_markers_present = 0;
  uint32_t head_markers_present = 0;
  bool head_pose_held = false;                                 // too few head markers: last pose reused
  Eigen::Isometry3d T_world_head = Eigen::Isometry3d::Identity();  // head in rig-scaled world space
};

class MarkerMapper {
 public:
  // source_labels: the source's marker slots (SourceInfo::labels). outlier_floor: rig
  // units; a head marker off the fit by more than this (and than 4x the others' median)
  // is left out of the head pose (align::HeadStabiliser, as `facecap solve` fits it).
  // Throws Error when no face marker of the calibration is among them. Not RT-safe.
  MarkerMapper(const MarkerCalibration& calibration, const std::vector<std::string>& source_labels, double scale,
               bool stabilise_head, double outlier_floor);

  // targets: 3 x K (K face markers) in rig (head) space; present: K flags. Missing
  // markers keep their previous target (the solver ignores them). RT-safe.
  MappedFrame map(const MarkerFrame& frame, Eigen::Matrix3Xd& targets, std::span<uint8_t> present) noexcept;

  std::size_t face_marker_count() const noexcept { return face_slot_.size(); }
  std::size_t matched_face_markers() const noexcept { return matched_face_; }
  std::size_t head_marker_count() const noexcept { return head_slot_.size(); }
  bool stabilising() const noexcept { return stabilise_; }

 private:
  std::vector<int> face_slot_;  // K: source slot of each face binding, -1 when the source lacks it
  std::vector<int> head_slot_;  // H: source slot of each head marker, -1 when absent
  Eigen::Matrix3Xd face_offset_;     // 3 x K, rig space, taken off each target
  std::size_t matched_face_ = 0;
  double scale_ = 1.0;
  Eigen::Isometry3d T_rig_marker_ = Eigen::Isometry3d::Identity();
  bool stabilise_ = false;
  // With stabilisation: the head markers in rig space each frame (H), fitted robustly to
  // their rest positions.
  std::optional<align::HeadStabiliser> stabiliser_;
  std::vector<Marker> head_markers_;
  align::HeadPoseResult head_pose_;
};

}  // namespace facecap::daemon
