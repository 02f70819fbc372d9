#include "drivers/v4l2/blob_detector.hpp"

#include <algorithm>
#include <cmath>

#include <opencv2/imgproc.hpp>

namespace facecap::drivers::v4l2 {

void BlobDetector::detect(const cv::Mat& grey, std::vector<Blob>& out) {
  out.clear();
  CV_Assert(grey.type() == CV_8UC1);
  cv::threshold(grey, binary_, params_.threshold, 255, cv::THRESH_BINARY);
  const int count = cv::connectedComponentsWithStats(binary_, labels_, stats_, centroids_, 8, CV_32S);
  components_ = count - 1;
  rejected_size_ = rejected_shape_ = 0;
  const double threshold = params_.threshold;
  for (int label = 1; label < count; ++label) {
    const int* s = stats_.ptr<int>(label);
    const int area = s[cv::CC_STAT_AREA];
    if (area < params_.min_area_px || area > params_.max_area_px) {
      ++rejected_size_;
      continue;
    }
    // Intensity-weighted moments over the component's own pixels: the weights (grey -
    // threshold) fall to zero at its edge, so a symmetric spot's centroid is unbiased.
    double m0 = 0, mx = 0, my = 0, mxx = 0, myy = 0, mxy = 0;
    const int x0 = s[cv::CC_STAT_LEFT], y0 = s[cv::CC_STAT_TOP];
    for (int y = y0; y < y0 + s[cv::CC_STAT_HEIGHT]; ++y) {
      const uint8_t* g = grey.ptr<uint8_t>(y);
      const int* l = labels_.ptr<int>(y);
      for (int x = x0; x < x0 + s[cv::CC_STAT_WIDTH]; ++x) {
        if (l[x] != label) continue;
        const double w = g[x] - threshold;
        m0 += w;
        mx += w * x;
        my += w * y;
        mxx += w * x * x;
        myy += w * y * y;
        mxy += w * x * y;
      }
    }
    if (m0 <= 0) continue;
    Blob b;
    b.x = mx / m0;
    b.y = my / m0;
    b.area_px = area;
    b.mass = m0;
    // Axes of the intensity ellipse from the central second moments' eigenvalues.
    const double cxx = mxx / m0 - b.x * b.x, cyy = myy / m0 - b.y * b.y, cxy = mxy / m0 - b.x * b.y;
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
