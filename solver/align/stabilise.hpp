#pragma once
// Per-frame head stabilisation: a robust rigid fit of the stable markers (forehead, nose
// bridge, temples, a head rig) from their calibration-frame positions to the current
// frame. Removing that motion leaves the face's own motion.
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/frame.hpp"
#include "solver/align/geometry.hpp"

namespace facecap::align {

// Which marker slots are present (and finite) in at least half of the frames: the others
// (a ghost or spare slot such as "Unlabeled", a marker lost for most of the take) take no
// part in the neutral search, stable markers or calibration. frames: every frame has the
// same slots. Not real-time.
std::vector<uint8_t> mostly_present_slots(std::span<const MarkerFrame> frames);

// Standard deviation over the frames of the distance between slots a and b (take units),
// over the frames where both are present; infinity with fewer than 2 such frames.
double distance_deviation(std::span<const MarkerFrame> frames, int a, int b);

// The markers whose mutual distances vary least over frames: for each seed marker a set
// grows greedily by a marker whose largest distance deviation (standard deviation over
// the frames where both are present) to the set is within 1.5x the smallest, the one
// farthest from the set (spread pins rotation); the set with the smallest mean pairwise
// deviation wins. frames: every frame has the same marker slots; markers
// present in under half of the frames are not candidates. Returns slot indices (count of
// them, fewer if fewer markers qualify), and each chosen pair deviation's mean in
// `mean_deviation` (take units) when given. Not real-time. Throws Error with fewer than
// 3 candidates or 2 frames.
// mobility (optional, one per slot): how far the rig can move each marker; when given,
// only the less mobile half of the markers (by rank, at least 3) are candidates.
std::vector<int> find_stable_markers(std::span<const MarkerFrame> frames, int count, double* mean_deviation = nullptr,
                                     std::span<const double> mobility = {});

struct StabiliserParams {
  int minimum_markers = 3;             // fewer inliers: hold the last pose
  double outlier_factor = 4.0;         // residual above factor x the others' median is rejected ...
  double outlier_floor = 0.2;          // ... if also above this (take units; set from mm by the caller)
  int iterations = 4;                  // at most this many markers rejected per frame
};

struct HeadPoseResult {
  Similarity pose;          // rigid: current = R reference + t (take units)
  bool held = false;        // too few inliers: previous pose kept
  int inliers = 0;
  double rms = 0.0;         // inlier residual RMS, take units
};

// Real-time safe after construction: process() neither allocates, locks nor throws.
class HeadStabiliser {
 public:
  // slots: the stable markers' indices in each frame's marker list; reference: 3 x S,
  // their positions in the calibration frame (take units). Throws Error if S < 3, sizes
  // disagree or the reference is not finite.
  HeadStabiliser(std::vector<int> slots, Eigen::Matrix3Xd reference, StabiliserParams params = {});

  // Fits the pose for one frame's markers. Marks rejected stable markers kMarkerOutlier
  // in marker_flags (one per frame marker) when it is non-empty. Returns out.held.
  bool process(std::span<const Marker> markers, HeadPoseResult& out, std::span<uint32_t> marker_flags = {}) noexcept;
  void reset() noexcept;
  // What it carries from frame to frame: the last fitted pose, which a frame with too few
  // stable markers holds. RT-safe.
  const Similarity& last_pose() const noexcept { return last_; }
  void restore_last_pose(const Similarity& pose) noexcept { last_ = pose; }

  // After process(): per stable marker, |pose^-1(current) - reference| (take units), or
  // NaN when it was missing; outliers included (their flag says so).
  std::span<const double> residuals() const noexcept { return residual_; }
  std::span<const uint8_t> inlier() const noexcept { return inlier_; }
  std::span<const int> slots() const noexcept { return slots_; }
  const Eigen::Matrix3Xd& reference() const noexcept { return reference_; }

 private:
  std::vector<int> slots_;
  Eigen::Matrix3Xd reference_, current_;
  StabiliserParams params_;
  std::vector<double> weight_, residual_, scratch_;
  std::vector<uint8_t> inlier_, present_;
  Similarity last_;
};

}  // namespace facecap::align
