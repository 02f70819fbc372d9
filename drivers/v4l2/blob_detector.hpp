#pragma once
// Bright markers in one greyscale IR image: threshold, connected components (OpenCV's
// connectedComponentsWithStats), then per component an intensity-weighted centroid with
// sub-pixel precision and its second moments, so that blobs too small, too large or not
// round enough (a reflection's streak, two markers merged) are left out. docs/cameras.md
// says how to tune the parameters.
#include <cstdint>
#include <vector>

#include <opencv2/core.hpp>

namespace facecap::drivers::v4l2 {

struct BlobParams {
  int threshold = 80;          // grey level a marker's pixels exceed
  int min_area_px = 4;
  int max_area_px = 400;
  double min_roundness = 0.6;  // minor / major axis of the blob's intensity ellipse; 1 for a disc
  int max_blobs = 256;         // per image; the brightest are kept beyond that
};

struct Blob {
  double x = 0, y = 0;     // intensity-weighted centroid, pixels (pixel centres at integers)
  int area_px = 0;
  double roundness = 0.0;  // minor / major axis
  double mass = 0.0;       // sum of (grey - threshold) over the blob
};

class BlobDetector {
 public:
  explicit BlobDetector(BlobParams params = {}) : params_(params) {}

  // Blobs of `grey` (CV_8UC1, any stride) into `out` (cleared first). Reuses its buffers:
  // after the first image of a size it does not allocate. Not RT-safe (OpenCV may
  // allocate on a new size), and not thread-safe: one detector per camera.
  void detect(const cv::Mat& grey, std::vector<Blob>& out);

  const BlobParams& params() const noexcept { return params_; }
  // Components the last image had beyond the background, and how many the filters took out.
  int components() const noexcept { return components_; }
  int rejected_size() const noexcept { return rejected_size_; }
  int rejected_shape() const noexcept { return rejected_shape_; }

 private:
  BlobParams params_;
  cv::Mat binary_, labels_, stats_, centroids_;
  int components_ = 0, rejected_size_ = 0, rejected_shape_ = 0;
};

}  // namespace facecap::drivers::v4l2
