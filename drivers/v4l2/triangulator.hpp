#pragma once
// From blobs seen by calibrated cameras to 3D points, for one set of frames taken at the
// same moment:
//   1. every blob is undistorted to normalised image coordinates (cv::undistortPoints,
//      iterated to 1e-9);
//   2. for each pair of cameras, blobs are paired where each lies within
//      epipolar_tolerance_px of the other's epipolar line (x_j^T E_ij x_i = 0); the pairs
//      of all cameras are taken cheapest first, each blob once, so that of two markers on
//      nearly the same epipolar line each keeps its own partner;
//   3. a pair is triangulated (linear DLT), must lie in front of both cameras and reproject
//      within max_reprojection_px; the other cameras' nearest unused blobs within that
//      distance of its projection join it, and the point is triangulated again from all
//      its views;
//      its views; the views that then reproject too far (a blob two markers merged into)
//      are left out again;
//   4. a pair is ambiguous when one of its blobs has another unused partner nearly as
//      cheap (within ambiguity_margin_px): two markers on one epipolar plane pair up both
//      ways, and one way gives two ghosts tens of mm off the face. An ambiguous pair is
//      taken only when a third camera confirms it or it lies within track_radius_mm of a
//      point of the recent sets; otherwise both markers are left out of this set rather
//      than guessed;
//   5. a point only two cameras see, and that is new (no point of the last memory_sets
//      sets within track_radius_mm of it), is held back one set and given only when the next
//      set has it again: a reflection one camera sees that happens to lie on the epipolar
//      line of a marker the other camera alone sees makes a ghost no geometry can tell
//      from a marker, but a ghost does not stay where it was. The first set gives only
//      the points a third camera confirms.
// A blob no other camera confirms gives no point: a reflection one camera sees is dropped.
// The DLT is written out (Eigen) because cv::triangulatePoints takes two views only; for
// two views the test checks it against OpenCV's.
#include <cstdint>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "drivers/v4l2/blob_detector.hpp"
#include "drivers/v4l2/camera_calibration.hpp"

namespace facecap::drivers::v4l2 {

inline constexpr std::size_t kMaxCameras = 8;

struct TriangulationParams {
  double epipolar_tolerance_px = 1.0;
  double max_reprojection_px = 1.5;
  double ambiguity_margin_px = 0.3;
  double track_radius_mm = 5.0;  // how far a marker may move between sets and still be known
  int memory_sets = 30;         // how long a marker hidden from a camera stays known
};

struct TriangulationStats {
  int points = 0;
  int multi_view_points = 0;   // seen by more than two cameras
  int pairs_rejected = 0;      // within the epipolar band but behind a camera or reprojecting too far
  int pairs_ambiguous = 0;     // left out: another pairing as good, and neither a third view nor the last sets to tell
  int points_held = 0;         // new two-view points held back until the next set has them too
  int blobs_unmatched = 0;     // blobs no point took (reflections, markers one camera alone saw)
};

// One view of a point: a camera's projection [R | t] and the normalised image point.
struct PointView {
  Eigen::Matrix<double, 3, 4> projection;
  Eigen::Vector2d normalised;
};

// Linear (DLT) triangulation from two or more views: the null vector of the 2N x 4 system
// u p3 - p1 = 0, v p3 - p2 = 0 (Hartley & Zisserman 12.2). 2 <= N <= kMaxCameras. RT-safe.
Eigen::Vector3d triangulate_dlt(std::span<const PointView> views) noexcept;

class Triangulator {
 public:
  // Throws Error for fewer than 2 cameras or more than kMaxCameras. Not RT-safe.
  Triangulator(CameraCalibration calibration, TriangulationParams params = {});

  // blobs[c]: camera c's blobs in pixels (one entry per camera, maybe empty). `out` gets
  // the points in the calibration's units (cleared first). Not RT-safe (OpenCV's undistortion
  // may allocate), but its own buffers are reused.
  void triangulate(std::span<const std::vector<Blob>> blobs, std::vector<Eigen::Vector3d>& out);

  const TriangulationStats& stats() const noexcept { return stats_; }
  const CameraCalibration& calibration() const noexcept { return calibration_; }
  const TriangulationParams& params() const noexcept { return params_; }
  // Normalised image point of a world point in camera c (no distortion). RT-safe.
  Eigen::Vector2d project_normalised(std::size_t camera, const Eigen::Vector3d& world) const noexcept;

 private:
  struct Candidate {
    double cost;
    uint8_t i, j;  // cameras
    int a, b;      // their blobs
  };
  // Pixels of camera c between two normalised points.
  double pixels(std::size_t camera, const Eigen::Vector2d& a, const Eigen::Vector2d& b) const noexcept;
  bool in_front(std::size_t camera, const Eigen::Vector3d& world) const noexcept;
  bool near(const std::vector<Eigen::Vector3d>& points, const Eigen::Vector3d& world) const noexcept;
  bool known(const Eigen::Vector3d& world) const noexcept;
  void remember(std::span<const Eigen::Vector3d> points);

  CameraCalibration calibration_;
  TriangulationParams params_;
  std::vector<Eigen::Matrix<double, 3, 4>> projections_;  // per camera [R | t]
  std::vector<std::vector<Eigen::Matrix3d>> essential_;   // [i][j], j > i: x_j^T E x_i = 0
  // Per frame, reused.
  std::vector<std::vector<Eigen::Vector2d>> normalised_;
  std::vector<std::vector<uint8_t>> used_;
  std::vector<Candidate> candidates_;
  struct Remembered {
    Eigen::Vector3d point;
    int64_t set;  // the last set that had it
  };
  std::vector<Remembered> recent_;         // points of the last memory_sets sets
  std::vector<Eigen::Vector3d> held_, holding_;  // new points held back by the last set, and by this one
  int64_t set_ = 0;
  double track_radius_ = 0;  // in the calibration's units
  std::vector<PointView> views_;
  std::vector<std::pair<std::size_t, std::size_t>> confirming_;  // (camera, blob) of a point's other views
  std::vector<cv::Point2d> pixel_scratch_, undistorted_;
  TriangulationStats stats_;
};

}  // namespace facecap::drivers::v4l2
