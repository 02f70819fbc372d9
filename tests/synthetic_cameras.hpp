#pragma once
// Synthetic IR camera images for the v4l2 driver's tests and benchmark: calibrated cameras
// around a face, and the sim's markers rendered into them as Gaussian dots through each
// camera's own distortion (cv::projectPoints), with sensor noise, markers hidden from one
// camera, a reflection's streak in one image and a stray round reflection in another.
// SyntheticFeed hands such images to the driver below V4L2, stamped as a camera would. The
// drawing (marker_drawing.hpp) is apart from the projection, so that fake cameras in
// another process draw the same images from the projected spots.
#include <cstdint>
#include <mutex>
#include <random>
#include <span>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "drivers/sim/sim_source.hpp"
#include "drivers/v4l2/camera_calibration.hpp"
#include "drivers/v4l2/camera_feed.hpp"
#include "tests/marker_drawing.hpp"

namespace facecap::test {

// `count` cameras 640x480 on an arc 500 mm in front of `target` (mm), 30 degrees apart in
// yaw, slightly apart in pitch, with OpenCV's 5-coefficient distortion. Units: mm.
drivers::v4l2::CameraCalibration face_cameras(const Eigen::Vector3d& target, int count = 2);

struct RenderOptions {
  double sigma_px = 1.2;     // a 4 mm marker's glow at 500 mm
  double peak = 200;
  double background = 12;
  double noise = 2.0;        // grey levels, standard deviation
  int hidden_per_camera = 2;  // markers occluded in each camera, chosen per frame
  bool reflections = true;   // a streak in camera 0, a stray round spot in camera 1
};

// One set projected: per camera the spots to draw, and the truth.
struct ProjectedSet {
  std::vector<std::vector<Spot>> spots;        // [camera]: visible markers' glows and the reflections
  uint64_t noise_seed = 0;                     // the sensor noise of this set's images (cv::RNG)
  std::vector<Eigen::Vector3d> truth;          // every marker, mm
  std::vector<std::vector<uint8_t>> visible;   // [camera][marker]
};

// What one rendered set holds, for checking what comes back.
struct RenderedSet {
  std::vector<cv::Mat> images;                 // one per camera, CV_8UC1
  std::vector<Eigen::Vector3d> truth;          // every marker, mm
  std::vector<std::vector<uint8_t>> visible;   // [camera][marker]
};

// The sim's frame `frame_no` (its units scaled to mm) rendered into every camera.
class MarkerRenderer {
 public:
  MarkerRenderer(drivers::v4l2::CameraCalibration cameras, const drivers::SimSource& sim, RenderOptions options,
                 uint32_t seed);
  // project() then draw(): the set's images.
  RenderedSet render(int64_t frame_no);
  // Where the markers and reflections fall in each camera, and which are hidden.
  ProjectedSet project(int64_t frame_no);
  // The images of a projected set, with their noise.
  std::vector<cv::Mat> draw(const ProjectedSet& set) const;
  const drivers::v4l2::CameraCalibration& cameras() const noexcept { return cameras_; }
  const RenderOptions& options() const noexcept { return options_; }
  double sim_to_mm() const noexcept { return sim_to_mm_; }

 private:
  drivers::v4l2::CameraCalibration cameras_;
  const drivers::SimSource& sim_;
  RenderOptions options_;
  double sim_to_mm_ = 1.0;
  std::mt19937 rng_;
  MarkerFrame frame_;
};

// The sim's centre of its markers at rest (frame 0), in mm: where the cameras look.
Eigen::Vector3d sim_marker_centre_mm(const drivers::SimSource& sim);

// The points that came out of the cameras against the truth they were drawn from: a point
// within 2 mm of a truth marker is that marker, off by its distance to it; any other is a
// ghost. With two cameras a few points are paired with a marker on their epipolar line
// whose own partner is hidden (docs/cameras.md): the tests bound how many.
class PointErrors {
 public:
  // The tests' bounds on those: at most 1 point in 1000 beyond a test's accuracy bound (and
  // none beyond 1.5 mm), and, where the frames seen depend on timing, 1 ghost in 2000 points.
  static constexpr double kMispairedShare = 0.001, kMispairedWorstMm = 1.5, kGhostShare = 0.0005;

  void add(std::span<const Eigen::Vector3d> points, std::span<const Eigen::Vector3d> truth);
  // The present markers of a frame from the driver.
  void add(const MarkerFrame& frame, std::span<const Eigen::Vector3d> truth);
  std::size_t count() const noexcept { return errors_mm_.size(); }
  std::size_t ghosts() const noexcept { return ghosts_; }
  double median_mm() const;  // infinity with no point
  double worst_mm() const;   // infinity with no point
  std::size_t count_above(double mm) const;  // points further than mm from their marker

 private:
  std::vector<double> errors_mm_;
  std::size_t ghosts_ = 0;
};

// Renders sets of the sim's frames for the driver, one camera image per next() call,
// stamped `period_ns` apart, camera k's image `k * skew_ns` after camera 0's. Frames listed
// in `dropped` (frame number, camera) never arrive, as a camera may drop one. Keeps the
// truth of every set it rendered.
class SyntheticFeed final : public drivers::v4l2::CameraFeed {
 public:
  SyntheticFeed(MarkerRenderer& renderer, int64_t frames, int64_t period_ns, int64_t skew_ns,
                std::vector<std::pair<int64_t, std::size_t>> dropped = {});

  std::size_t cameras() const override;
  void open() override {}
  void start() override;
  bool next(drivers::v4l2::CameraImage& out, int timeout_ms) override;
  void stop() noexcept override {}
  std::string description() const override { return "synthetic cameras"; }

  // When start() was called: frame n's images are stamped start_ns() + n * period.
  int64_t start_ns() const noexcept { return start_ns_; }
  // The truth of set `frame_no` (mm), once rendered.
  std::vector<Eigen::Vector3d> truth(int64_t frame_no) const;
  bool finished() const;

 private:
  MarkerRenderer& renderer_;
  int64_t frames_, period_ns_, skew_ns_;
  std::vector<std::pair<int64_t, std::size_t>> dropped_;
  int64_t start_ns_ = 0;
  int64_t frame_ = 0;
  std::size_t camera_ = 0;
  RenderedSet set_;
  mutable std::mutex mutex_;
  std::vector<std::vector<Eigen::Vector3d>> truths_;
};

}  // namespace facecap::test
