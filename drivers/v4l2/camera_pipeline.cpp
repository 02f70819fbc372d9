#include "drivers/v4l2/camera_pipeline.hpp"

#include <algorithm>

#include <fmt/format.h>

#include "core/error.hpp"

namespace facecap::drivers::v4l2 {

CameraPipeline::CameraPipeline(CameraCalibration calibration, BlobParams blobs, TriangulationParams triangulation)
    : detectors_(calibration.cameras.size(), BlobDetector(blobs)),
      blobs_(calibration.cameras.size()),
      triangulator_(std::move(calibration), triangulation) {
  for (auto& list : blobs_) list.reserve(std::size_t(blobs.max_blobs) * 2);
}

void CameraPipeline::detect(std::size_t camera, const cv::Mat& grey) { detectors_[camera].detect(grey, blobs_[camera]); }

void CameraPipeline::triangulate(std::vector<Eigen::Vector3d>& points) {
  triangulator_.triangulate(blobs_, points);
  for (auto& list : blobs_) list.clear();
}

void CameraPipeline::process(std::span<const cv::Mat> images, std::vector<Eigen::Vector3d>& points) {
  if (images.size() != cameras()) throw Error(fmt::format("{} images for {} cameras", images.size(), cameras()));
  for (std::size_t c = 0; c < images.size(); ++c) detect(c, images[c]);
  triangulate(points);
}

FrameSetMatcher::FrameSetMatcher(std::size_t cameras, int64_t tolerance_ns)
    : time_ns_(cameras, 0), held_(cameras, 0), tolerance_ns_(tolerance_ns) {}

bool FrameSetMatcher::add(std::size_t camera, int64_t timestamp_ns) noexcept {
  if (held_[camera]) ++unmatched_;  // replaced before its set was complete
  time_ns_[camera] = timestamp_ns;
  held_[camera] = 1;
  bool complete = true;
  for (std::size_t k = 0; k < held_.size(); ++k) {
    if (!held_[k]) {
      complete = false;
      continue;
    }
    // A frame far older than the newest can never join it: dropped. (The newest is the one
    // just added, unless cameras' clocks disagree.)
    const int64_t gap = timestamp_ns - time_ns_[k];
    if (k != camera && -gap > tolerance_ns_) {  // the one just added is already too old
      held_[camera] = 0;
      ++unmatched_;
      return false;
    }
    if (gap > tolerance_ns_) {
      held_[k] = 0;
      ++unmatched_;
      complete = false;
    }
  }
  if (!complete) return false;
  set_time_ns_ = *std::min_element(time_ns_.begin(), time_ns_.end());
  std::fill(held_.begin(), held_.end(), uint8_t{0});
  return true;
}

}  // namespace facecap::drivers::v4l2
