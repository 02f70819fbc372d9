#pragma once
// From a captured marker frame to solver targets in rig space, per frame:
//   1. head stabilisation (robust rigid fit of the stable markers to the calibration frame);
//   2. each marker's offset from its own neutral position (in the stabilised head frame),
//      mapped into rig space by the calibration's similarity;
//   3. target = the marker's bound surface point + that offset.
// Step 2-3 handle identity mismatch: the actor at rest gives exactly the bound points, so
// the rig's neutral, whatever the actor's face looks like.
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "core/frame.hpp"
#include "solver/align/calibrate.hpp"
#include "solver/align/stabilise.hpp"

namespace facecap::align {

struct MappedFrame {
  Eigen::Matrix3Xd targets;      // 3 x K (calibration marker order), rig space; NaN when missing
  std::vector<uint8_t> present;  // K
  // Head pose relative to the calibration frame, in rig axes and rig units: a point
  // fixed to the head at x (rig space, calibration frame) is at R x + t now.
  Eigen::Quaterniond head_rotation = Eigen::Quaterniond::Identity();
  Eigen::Vector3d head_translation = Eigen::Vector3d::Zero();
  Similarity head_in_take;       // the stabiliser's rigid pose, take units
  bool head_held = false;        // too few stable markers: last pose reused
  int stable_inliers = 0;
  double stable_rms_mm = 0.0;    // inlier residual RMS of the stable markers, actor mm
};

class MarkerMapper {
 public:
  // frame_labels: the label of each marker slot of the frames to come (a take's labels,
  // or the labeller's marker order). Throws Error when fewer than 3 of the calibration's
  // stable markers, or fewer than 3 markers at all, are among them.
  MarkerMapper(const Calibration& calibration, std::span<const std::string> frame_labels, StabiliserParams params = {});

  MappedFrame make_output() const;
  // Real-time safe. marker_flags (one per frame slot, may be empty) gains kMarkerOutlier
  // for stable markers the stabiliser rejected.
  void process(const MarkerFrame& frame, MappedFrame& out, std::span<uint32_t> marker_flags = {}) noexcept;

  Eigen::Index marker_count() const { return Eigen::Index(slots_.size()); }
  std::span<const int> slots() const { return slots_; }          // per calibration marker: frame slot or -1
  std::span<const uint8_t> is_stable() const { return stable_; }  // per calibration marker
  const HeadStabiliser& stabiliser() const { return stabiliser_; }
  const Calibration& calibration() const { return calibration_; }
  void reset() noexcept { stabiliser_.reset(); }

 private:
  static HeadStabiliser make_stabiliser(const Calibration& c, std::span<const std::string> labels, StabiliserParams p);
  Calibration calibration_;
  std::vector<int> slots_;
  std::vector<uint8_t> stable_;
  HeadStabiliser stabiliser_;
  HeadPoseResult pose_;
};

}  // namespace facecap::align
