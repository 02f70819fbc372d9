#pragma once
// Bright markers in one greyscale IR image: threshold, 8-connected components, then per
// component an intensity-weighted centroid with sub-pixel precision and its second
// moments, so that blobs too small, too large or not round enough (a reflection's streak,
// two markers merged) are left out. docs/cameras.md says how to tune the parameters.
//
// The components are labelled from runs of bright pixels (a union-find over runs that
// touch from one row to the next), not with cv::connectedComponentsWithStats: on a
// 640x480 image of ~50 markers OpenCV's took 2.3 to 7 ms on one core here (it labels and
// keeps statistics for every background pixel), this takes ~0.3 ms (bench/bench_cameras),
// and the budget for a set of two images is 2 ms. tests/test_cameras.cpp checks it against
// OpenCV's labelling.
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
  // once they have grown to an image's runs it does not allocate. Not RT-safe (a busier
  // image grows them), and not thread-safe: one detector per camera.
  void detect(const cv::Mat& grey, std::vector<Blob>& out);

  const BlobParams& params() const noexcept { return params_; }
  // Components the last image had beyond the background, and how many the filters took out.
  int components() const noexcept { return components_; }
  int rejected_size() const noexcept { return rejected_size_; }
  int rejected_shape() const noexcept { return rejected_shape_; }

 private:
  struct Run {
    int y, x0, x1;  // pixels x0..x1 of row y exceed the threshold
  };
  struct Moments {
    double m0 = 0, mx = 0, my = 0, mxx = 0, myy = 0, mxy = 0;
    int area = 0;
  };
  int root(int run) noexcept;

  BlobParams params_;
  std::vector<Run> runs_;
  std::vector<int> parent_;     // union-find over runs_
  std::vector<int> component_;  // per root run: its index into moments_, or -1
  std::vector<Moments> moments_;
  int components_ = 0, rejected_size_ = 0, rejected_shape_ = 0;
};

}  // namespace facecap::drivers::v4l2
