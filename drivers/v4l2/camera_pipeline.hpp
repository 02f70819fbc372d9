#pragma once
// The v4l2 driver's work on one set of frames taken together: blobs in each camera's
// image (BlobDetector), then 3D points (Triangulator); and the matching of frames from
// several cameras into sets by their timestamps. No threads and no V4L2 here: the driver,
// the tests and the benchmark all run this same code.
#include <cstdint>
#include <span>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "drivers/v4l2/blob_detector.hpp"
#include "drivers/v4l2/camera_calibration.hpp"
#include "drivers/v4l2/triangulator.hpp"

namespace facecap::drivers::v4l2 {

class CameraPipeline {
 public:
  // Throws Error (fewer than 2 cameras, more than 8). Not RT-safe.
  CameraPipeline(CameraCalibration calibration, BlobParams blobs, TriangulationParams triangulation);

  // Camera c's image of the set being gathered: its blobs replace that camera's last ones.
  void detect(std::size_t camera, const cv::Mat& grey);
  // 3D points (calibration units) from the blobs detected since the last set.
  void triangulate(std::vector<Eigen::Vector3d>& points);
  // Both, for one image per camera.
  void process(std::span<const cv::Mat> images, std::vector<Eigen::Vector3d>& points);

  std::size_t cameras() const noexcept { return detectors_.size(); }
  std::span<const std::vector<Blob>> blobs() const noexcept { return blobs_; }
  const BlobDetector& detector(std::size_t camera) const noexcept { return detectors_[camera]; }
  const Triangulator& triangulator() const noexcept { return triangulator_; }

 private:
  std::vector<BlobDetector> detectors_;
  std::vector<std::vector<Blob>> blobs_;
  Triangulator triangulator_;
};

// Frames of several cameras that belong together: one per camera, their timestamps within
// `tolerance` of each other. A frame that can no longer be part of a set (a newer one of
// its camera arrived, or the others have moved on past it) is counted as unmatched. RT-safe
// after construction.
class FrameSetMatcher {
 public:
  FrameSetMatcher(std::size_t cameras, int64_t tolerance_ns);

  // Camera c delivered a frame stamped t. True when that completes a set; the set's time
  // is then set_time_ns() (the earliest of its frames) and gathering starts afresh.
  bool add(std::size_t camera, int64_t timestamp_ns) noexcept;
  int64_t set_time_ns() const noexcept { return set_time_ns_; }
  uint64_t unmatched() const noexcept { return unmatched_; }

 private:
  std::vector<int64_t> time_ns_;
  std::vector<uint8_t> held_;
  int64_t tolerance_ns_;
  int64_t set_time_ns_ = 0;
  uint64_t unmatched_ = 0;
};

}  // namespace facecap::drivers::v4l2
