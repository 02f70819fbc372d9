#include "drivers/v4l2/blob_detector.hpp"

#include <algorithm>
#include <cmath>

namespace facecap::drivers::v4l2 {

int BlobDetector::root(int run) noexcept {
  while (parent_[std::size_t(run)] != run) {
    parent_[std::size_t(run)] = parent_[std::size_t(parent_[std::size_t(run)])];  // path halving
    run = parent_[std::size_t(run)];
  }
  return run;
}

void BlobDetector::detect(const cv::Mat& grey, std::vector<Blob>& out) {
  out.clear();
  CV_Assert(grey.type() == CV_8UC1);
  const auto threshold = uint8_t(std::clamp(params_.threshold, 0, 255));
  runs_.clear();
  parent_.clear();
  // Runs of bright pixels, each joined to the runs of the row above it touches (8-connected:
  // diagonal neighbours count).
  std::size_t above_begin = 0, above_end = 0;
  for (int y = 0; y < grey.rows; ++y) {
    const uint8_t* row = grey.ptr<uint8_t>(y);
    const std::size_t row_begin = runs_.size();
    std::size_t above = above_begin;
    for (int x = 0; x < grey.cols;) {
      if (row[x] <= threshold) {
        ++x;
        continue;
      }
      const int x0 = x;
      while (x < grey.cols && row[x] > threshold) ++x;
      const int index = int(runs_.size());
      runs_.push_back({y, x0, x - 1});
      parent_.push_back(index);
      while (above < above_end && runs_[above].x1 < x0 - 1) ++above;
      for (std::size_t a = above; a < above_end && runs_[a].x0 <= x; ++a) {
        const int ra = root(int(a)), rb = root(index);
        if (ra != rb) parent_[std::size_t(std::max(ra, rb))] = std::min(ra, rb);
      }
    }
    above_begin = row_begin;
    above_end = runs_.size();
  }

  // Each component's moments, weighted by (grey - threshold): the weights fall to zero at
  // its edge, so a symmetric spot's centroid is unbiased. Pixel coordinates relative to the
  // component's first run keep the sums well conditioned.
  component_.assign(runs_.size(), -1);
  moments_.clear();
  for (std::size_t r = 0; r < runs_.size(); ++r) {
    const auto top = std::size_t(root(int(r)));
    if (component_[top] < 0) {
      component_[top] = int(moments_.size());
      moments_.emplace_back();
    }
    Moments& m = moments_[std::size_t(component_[top])];
    const Run& run = runs_[r];
    const Run& first_run = runs_[top];  // the root: the component's first run
    const uint8_t* row = grey.ptr<uint8_t>(run.y);
    const double dy = run.y - first_run.y;
    for (int x = run.x0; x <= run.x1; ++x) {
      const double w = double(row[x] - threshold), dx = x - first_run.x0;
      m.m0 += w;
      m.mx += w * dx;
      m.my += w * dy;
      m.mxx += w * dx * dx;
      m.myy += w * dy * dy;
      m.mxy += w * dx * dy;
    }
    m.area += run.x1 - run.x0 + 1;
  }
  components_ = int(moments_.size());
  rejected_size_ = rejected_shape_ = 0;
  for (std::size_t r = 0; r < runs_.size(); ++r) {
    if (component_[r] < 0) continue;  // not a root
    const Moments& m = moments_[std::size_t(component_[r])];
    if (m.area < params_.min_area_px || m.area > params_.max_area_px) {
      ++rejected_size_;
      continue;
    }
    Blob b;
    const double cx = m.mx / m.m0, cy = m.my / m.m0;
    b.x = runs_[r].x0 + cx;
    b.y = runs_[r].y + cy;
    b.area_px = m.area;
    b.mass = m.m0;
    // Axes of the intensity ellipse from the central second moments' eigenvalues.
    const double cxx = m.mxx / m.m0 - cx * cx, cyy = m.myy / m.m0 - cy * cy, cxy = m.mxy / m.m0 - cx * cy;
    const double mean = 0.5 * (cxx + cyy), spread = std::sqrt(0.25 * (cxx - cyy) * (cxx - cyy) + cxy * cxy);
    const double major = mean + spread, minor = std::max(mean - spread, 0.0);
    b.roundness = major > 0 ? std::sqrt(minor / major) : 1.0;
    if (b.roundness < params_.min_roundness) {
      ++rejected_shape_;
      continue;
    }
    out.push_back(b);
  }
  if (int(out.size()) > params_.max_blobs) {
    std::nth_element(out.begin(), out.begin() + params_.max_blobs, out.end(),
                     [](const Blob& a, const Blob& b) { return a.mass > b.mass; });
    out.resize(std::size_t(params_.max_blobs));
  }
}

}  // namespace facecap::drivers::v4l2
