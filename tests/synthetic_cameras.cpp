#include "tests/synthetic_cameras.hpp"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <thread>

#include <Eigen/Geometry>
#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>

#include "core/time.hpp"

namespace facecap::test {
namespace {

using drivers::v4l2::CameraCalibration;
using drivers::v4l2::CameraModel;

constexpr double kPi = 3.14159265358979323846;

// World to camera for a camera at `centre` looking at `target`, image y pointing down the
// world's -Y (OpenCV's camera axes: x right, y down, z forward).
void look_at(CameraModel& camera, const Eigen::Vector3d& centre, const Eigen::Vector3d& target) {
  const Eigen::Vector3d z = (target - centre).normalized();
  const Eigen::Vector3d down(0, -1, 0);
  const Eigen::Vector3d y = (down - down.dot(z) * z).normalized();
  const Eigen::Vector3d x = y.cross(z);
  camera.rotation.row(0) = x;
  camera.rotation.row(1) = y;
  camera.rotation.row(2) = z;
  camera.translation = -camera.rotation * centre;
}

}  // namespace

CameraCalibration face_cameras(const Eigen::Vector3d& target, int count) {
  CameraCalibration rig;
  rig.units = "mm";
  for (int i = 0; i < count; ++i) {
    CameraModel& c = rig.cameras.emplace_back();
    c.name = count == 2 ? (i == 0 ? "left" : "right") : "camera " + std::to_string(i + 1);
    c.width = 640;
    c.height = 480;
    const double fx = 820 + 7 * i, fy = 818 + 7 * i;
    c.camera_matrix << fx, 0, 322.5 - 3 * i, 0, fy, 238.0 + 2 * i, 0, 0, 1;
    c.distortion = {-0.09 + 0.01 * i, 0.03, 0.0006, -0.0004, -0.004};
    const double yaw = (double(i) - 0.5 * (count - 1)) * 30.0 * kPi / 180.0;
    const double pitch = (i % 2 ? -4.0 : 5.0) * kPi / 180.0;
    const Eigen::Vector3d offset(500 * std::sin(yaw) * std::cos(pitch), 500 * std::sin(pitch),
                                 500 * std::cos(yaw) * std::cos(pitch));
    look_at(c, target + offset, target);
  }
  return rig;
}

Eigen::Vector3d sim_marker_centre_mm(const drivers::SimSource& sim) {
  MarkerFrame frame = make_marker_frame(sim.info().labels);
  sim.render_frame(0, frame);
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  int n = 0;
  for (const Marker& m : frame.markers)
    if (m.present()) {
      sum += m.position;
      ++n;
    }
  const double mm = sim.info().units == "m" ? 1000 : sim.info().units == "cm" ? 10 : 1;
  return sum / std::max(n, 1) * mm;
}

MarkerRenderer::MarkerRenderer(CameraCalibration cameras, const drivers::SimSource& sim, RenderOptions options,
                               uint32_t seed)
    : cameras_(std::move(cameras)), sim_(sim), options_(options), rng_(seed),
      frame_(make_marker_frame(sim.info().labels)) {
  sim_to_mm_ = sim.info().units == "m" ? 1000 : sim.info().units == "cm" ? 10 : 1;
}

RenderedSet MarkerRenderer::render(int64_t frame_no) {
  ProjectedSet projected = project(frame_no);
  return {draw(projected), std::move(projected.truth), std::move(projected.visible)};
}

ProjectedSet MarkerRenderer::project(int64_t frame_no) {
  sim_.render_frame(frame_no, frame_);
  ProjectedSet set;
  for (const Marker& m : frame_.markers) set.truth.push_back(m.position * sim_to_mm_);
  const std::size_t markers = set.truth.size();
  std::vector<cv::Point3d> object;
  for (const Eigen::Vector3d& p : set.truth) object.emplace_back(p.x(), p.y(), p.z());
  set.noise_seed = rng_();
  for (std::size_t c = 0; c < cameras_.cameras.size(); ++c) {
    const CameraModel& camera = cameras_.cameras[c];
    cv::Mat k, r, rvec, tvec;
    cv::eigen2cv(camera.camera_matrix, k);
    cv::eigen2cv(camera.rotation, r);
    cv::Rodrigues(r, rvec);
    cv::eigen2cv(camera.translation, tvec);
    std::vector<cv::Point2d> pixels;
    cv::projectPoints(object, rvec, tvec, k, camera.distortion, pixels);

    std::vector<uint8_t>& visible = set.visible.emplace_back(markers, 1);
    for (std::size_t m = 0; m < markers; ++m) visible[m] = frame_.markers[m].present();
    std::vector<std::size_t> order(markers);
    std::iota(order.begin(), order.end(), 0);
    std::shuffle(order.begin(), order.end(), rng_);
    for (int h = 0; h < options_.hidden_per_camera && h < int(markers); ++h) visible[order[std::size_t(h)]] = 0;

    const double sigma = options_.sigma_px;
    std::vector<Spot>& spots = set.spots.emplace_back();
    for (std::size_t m = 0; m < markers; ++m)
      if (visible[m]) spots.push_back({pixels[m].x, pixels[m].y, sigma, sigma, 0, options_.peak});
    if (options_.reflections && c == 0) {  // a streak: too long to be a marker
      spots.push_back({120.5, 400.25, 7.0, 1.0, 0.4, 230});
    } else if (options_.reflections && c == 1) {  // a round stray spot no other camera sees
      std::uniform_real_distribution<double> x(250, 390), y(150, 330);
      const double u = x(rng_), v = y(rng_);
      spots.push_back({u, v, sigma, sigma, 0, options_.peak});
    }
  }
  return set;
}

std::vector<cv::Mat> MarkerRenderer::draw(const ProjectedSet& set) const {
  cv::RNG noise(set.noise_seed);
  std::vector<cv::Mat> images;
  for (std::size_t c = 0; c < set.spots.size(); ++c) {
    const CameraModel& camera = cameras_.cameras[c];
    cv::Mat image(camera.height, camera.width, CV_32FC1), grain(camera.height, camera.width, CV_32FC1);
    draw_spots(set.spots[c], float(options_.background), image.cols, image.rows, image.ptr<float>());
    noise.fill(grain, cv::RNG::NORMAL, 0.0, options_.noise);
    cv::Mat& grey = images.emplace_back(camera.height, camera.width, CV_8UC1);
    to_grey(image.ptr<float>(), {grain.ptr<float>(), grain.total()}, image.cols, image.rows, grey.ptr<uint8_t>(),
            int(grey.step));
  }
  return images;
}

void PointErrors::add(std::span<const Eigen::Vector3d> points, std::span<const Eigen::Vector3d> truth) {
  for (const Eigen::Vector3d& p : points) {
    double nearest = INFINITY;
    for (const Eigen::Vector3d& t : truth)
      if (t.allFinite()) nearest = std::min(nearest, (p - t).norm());
    if (nearest < 2.0) errors_mm_.push_back(nearest);
    else ++ghosts_;
  }
}

void PointErrors::add(const MarkerFrame& frame, std::span<const Eigen::Vector3d> truth) {
  for (const Marker& m : frame.markers)
    if (m.present()) add(std::span(&m.position, 1), truth);
}

double PointErrors::median_mm() const {
  if (errors_mm_.empty()) return INFINITY;
  std::vector<double> sorted = errors_mm_;
  std::nth_element(sorted.begin(), sorted.begin() + std::ptrdiff_t(sorted.size() / 2), sorted.end());
  return sorted[sorted.size() / 2];
}

std::size_t PointErrors::count_above(double mm) const {
  return std::size_t(std::count_if(errors_mm_.begin(), errors_mm_.end(), [&](double e) { return e > mm; }));
}

double PointErrors::worst_mm() const {
  return errors_mm_.empty() ? INFINITY : *std::max_element(errors_mm_.begin(), errors_mm_.end());
}

SyntheticFeed::SyntheticFeed(MarkerRenderer& renderer, int64_t frames, int64_t period_ns, int64_t skew_ns,
                             std::vector<std::pair<int64_t, std::size_t>> dropped)
    : renderer_(renderer), frames_(frames), period_ns_(period_ns), skew_ns_(skew_ns), dropped_(std::move(dropped)) {}

std::size_t SyntheticFeed::cameras() const { return renderer_.cameras().cameras.size(); }

void SyntheticFeed::start() { start_ns_ = monotonic_now_ns(); }

bool SyntheticFeed::next(drivers::v4l2::CameraImage& out, int timeout_ms) {
  while (true) {
    if (frame_ >= frames_) {
      std::this_thread::sleep_for(std::chrono::milliseconds(timeout_ms));
      return false;
    }
    const int64_t due_ns = start_ns_ + frame_ * period_ns_ + int64_t(camera_) * skew_ns_;
    if (due_ns - monotonic_now_ns() > int64_t(timeout_ms) * kNsPerMs) {
      sleep_until(monotonic_now_ns() + int64_t(timeout_ms) * kNsPerMs);
      return false;
    }
    sleep_until(due_ns);
    if (camera_ == 0) {
      set_ = renderer_.render(frame_);
      std::lock_guard lock(mutex_);
      truths_.push_back(set_.truth);
    }
    const std::size_t camera = camera_;
    const int64_t frame = frame_;
    if (++camera_ == cameras()) {
      camera_ = 0;
      ++frame_;
    }
    if (std::find(dropped_.begin(), dropped_.end(), std::pair{frame, camera}) != dropped_.end()) continue;
    out.camera = camera;
    out.timestamp_ns = due_ns;
    out.sequence = frame;
    out.grey = set_.images[camera];
    return true;
  }
}

std::vector<Eigen::Vector3d> SyntheticFeed::truth(int64_t frame_no) const {
  std::lock_guard lock(mutex_);
  return frame_no < int64_t(truths_.size()) ? truths_[std::size_t(frame_no)] : std::vector<Eigen::Vector3d>{};
}

bool SyntheticFeed::finished() const {
  std::lock_guard lock(mutex_);
  return int64_t(truths_.size()) >= frames_ && camera_ == 0;
}

}  // namespace facecap::test
