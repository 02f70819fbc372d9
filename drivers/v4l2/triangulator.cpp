#include "drivers/v4l2/triangulator.hpp"

#include <algorithm>
#include <cmath>

#include <Eigen/Geometry>
#include <Eigen/SVD>
#include <fmt/format.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>

#include "core/error.hpp"

namespace facecap::drivers::v4l2 {
namespace {

Eigen::Matrix3d skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d s;
  s << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return s;
}

// Distance (normalised units) of x from the line l (a x + b y + c = 0).
double line_distance(const Eigen::Vector3d& l, const Eigen::Vector2d& x) {
  return std::abs(l.x() * x.x() + l.y() * x.y() + l.z()) / std::hypot(l.x(), l.y());
}

}  // namespace

Eigen::Vector3d triangulate_dlt(std::span<const PointView> views) noexcept {
  Eigen::Matrix<double, Eigen::Dynamic, 4, 0, 16, 4> a(2 * Eigen::Index(views.size()), 4);
  for (std::size_t v = 0; v < views.size(); ++v) {
    const auto& p = views[v].projection;
    a.row(2 * Eigen::Index(v)) = views[v].normalised.x() * p.row(2) - p.row(0);
    a.row(2 * Eigen::Index(v) + 1) = views[v].normalised.y() * p.row(2) - p.row(1);
  }
  // The right singular vector of the smallest singular value (of A itself: its normal
  // matrix would square the conditioning). Bounded sizes: no allocation.
  const Eigen::JacobiSVD<decltype(a)> svd(a, Eigen::ComputeFullV);
  const Eigen::Vector4d x = svd.matrixV().col(3);
  return x.head<3>() / x.w();
}

Triangulator::Triangulator(CameraCalibration calibration, TriangulationParams params)
    : calibration_(std::move(calibration)), params_(params) {
  const std::size_t n = calibration_.cameras.size();
  if (n < 2 || n > kMaxCameras)
    throw Error(fmt::format("triangulation takes 2 to {} calibrated cameras, not {}", kMaxCameras, n));
  for (const CameraModel& c : calibration_.cameras) {
    Eigen::Matrix<double, 3, 4> p;
    p << c.rotation, c.translation;
    projections_.push_back(p);
  }
  essential_.assign(n, std::vector<Eigen::Matrix3d>(n, Eigen::Matrix3d::Zero()));
  for (std::size_t i = 0; i < n; ++i)
    for (std::size_t j = i + 1; j < n; ++j) {
      const CameraModel &ci = calibration_.cameras[i], &cj = calibration_.cameras[j];
      const Eigen::Matrix3d r = cj.rotation * ci.rotation.transpose();  // camera i to camera j
      const Eigen::Vector3d t = cj.translation - r * ci.translation;
      essential_[i][j] = skew(t) * r;
    }
  normalised_.resize(n);
  used_.resize(n);
  const double unit_mm = calibration_.units == "m" ? 1000.0 : calibration_.units == "cm" ? 10.0 : 1.0;
  track_radius_ = params_.track_radius_mm / unit_mm;
}

Eigen::Vector2d Triangulator::project_normalised(std::size_t camera, const Eigen::Vector3d& world) const noexcept {
  const Eigen::Vector3d x = projections_[camera] * world.homogeneous();
  return x.head<2>() / x.z();
}

double Triangulator::pixels(std::size_t camera, const Eigen::Vector2d& a, const Eigen::Vector2d& b) const noexcept {
  return (a - b).norm() * calibration_.cameras[camera].focal_px();
}

bool Triangulator::near(const std::vector<Eigen::Vector3d>& points, const Eigen::Vector3d& world) const noexcept {
  const double r2 = track_radius_ * track_radius_;
  return std::any_of(points.begin(), points.end(), [&](const Eigen::Vector3d& p) { return (p - world).squaredNorm() <= r2; });
}

bool Triangulator::known(const Eigen::Vector3d& world) const noexcept {
  const double r2 = track_radius_ * track_radius_;
  return std::any_of(recent_.begin(), recent_.end(),
                     [&](const Remembered& r) { return (r.point - world).squaredNorm() <= r2; });
}

// Each point renews the memory nearest it (a marker moves) or is added; memories older than
// memory_sets go.
void Triangulator::remember(std::span<const Eigen::Vector3d> points) {
  const double r2 = track_radius_ * track_radius_;
  for (const Eigen::Vector3d& p : points) {
    Remembered* nearest = nullptr;
    double best = r2;
    for (Remembered& r : recent_)
      if (const double d = (r.point - p).squaredNorm(); d <= best && r.set != set_) {
        best = d;
        nearest = &r;
      }
    if (nearest) *nearest = {p, set_};
    else recent_.push_back({p, set_});
  }
  std::erase_if(recent_, [&](const Remembered& r) { return set_ - r.set >= params_.memory_sets; });
}

bool Triangulator::in_front(std::size_t camera, const Eigen::Vector3d& world) const noexcept {
  return (projections_[camera] * world.homogeneous()).z() > 0;
}

void Triangulator::triangulate(std::span<const std::vector<Blob>> blobs, std::vector<Eigen::Vector3d>& out) {
  const std::size_t n = calibration_.cameras.size();
  if (blobs.size() != n) throw Error(fmt::format("{} cameras' blobs for {} calibrated cameras", blobs.size(), n));
  out.clear();
  stats_ = {};
  for (std::size_t c = 0; c < n; ++c) {
    const CameraModel& camera = calibration_.cameras[c];
    normalised_[c].resize(blobs[c].size());
    used_[c].assign(blobs[c].size(), 0);
    if (blobs[c].empty()) continue;
    std::vector<cv::Point2d>& pixels = pixel_scratch_;
    pixels.resize(blobs[c].size());
    for (std::size_t b = 0; b < blobs[c].size(); ++b) pixels[b] = {blobs[c][b].x, blobs[c][b].y};
    cv::Mat k;
    cv::eigen2cv(camera.camera_matrix, k);
    undistorted_.resize(pixels.size());
    cv::undistortPoints(pixels, undistorted_, k, camera.distortion, cv::noArray(), cv::noArray(),
                        cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 50, 1e-10));
    for (std::size_t b = 0; b < blobs[c].size(); ++b) normalised_[c][b] = {undistorted_[b].x, undistorted_[b].y};
  }

  // Every camera pair's candidates, cheapest first across all pairs: a marker two cameras
  // see well is taken before a reflection near its image in a third can claim it.
  candidates_.clear();
  for (std::size_t i = 0; i < n; ++i) {
    for (std::size_t j = i + 1; j < n; ++j) {
      const Eigen::Matrix3d& e = essential_[i][j];
      const double fi = calibration_.cameras[i].focal_px(), fj = calibration_.cameras[j].focal_px();
      for (std::size_t a = 0; a < normalised_[i].size(); ++a) {
        if (used_[i][a]) continue;
        const Eigen::Vector3d line_j = e * normalised_[i][a].homogeneous();
        for (std::size_t b = 0; b < normalised_[j].size(); ++b) {
          if (used_[j][b]) continue;
          const double dj = line_distance(line_j, normalised_[j][b]) * fj;
          if (dj > params_.epipolar_tolerance_px) continue;
          const double di = line_distance(e.transpose() * normalised_[j][b].homogeneous(), normalised_[i][a]) * fi;
          if (di > params_.epipolar_tolerance_px) continue;
          candidates_.push_back({std::max(di, dj), uint8_t(i), uint8_t(j), int(a), int(b)});
        }
      }
    }
  }
  std::sort(candidates_.begin(), candidates_.end(), [](const Candidate& x, const Candidate& y) { return x.cost < y.cost; });
  for (const Candidate& pair : candidates_) {
    const std::size_t i = pair.i, j = pair.j;
    const auto a = std::size_t(pair.a), b = std::size_t(pair.b);
    if (used_[i][a] || used_[j][b]) continue;
    views_.clear();
    views_.push_back({projections_[i], normalised_[i][a]});
    views_.push_back({projections_[j], normalised_[j][b]});
    Eigen::Vector3d x = triangulate_dlt(views_);
    const bool valid = in_front(i, x) && in_front(j, x) &&
                       pixels(i, project_normalised(i, x), views_[0].normalised) <= params_.max_reprojection_px &&
                       pixels(j, project_normalised(j, x), views_[1].normalised) <= params_.max_reprojection_px;
    if (!valid) {
      ++stats_.pairs_rejected;
      continue;
    }
    const bool ambiguous = std::any_of(candidates_.begin(), candidates_.end(), [&](const Candidate& other) {
      return other.i == pair.i && other.j == pair.j && (other.a == pair.a) != (other.b == pair.b) && !used_[i][std::size_t(other.a)] &&
             !used_[j][std::size_t(other.b)] && other.cost < pair.cost + params_.ambiguity_margin_px;
    });
    // The other cameras' confirmation: their nearest unused blob at the projection.
    confirming_.clear();
    for (std::size_t k = 0; k < n; ++k) {
      if (k == i || k == j || !in_front(k, x)) continue;
      const Eigen::Vector2d seen = project_normalised(k, x);
      int best = -1;
      double best_px = params_.max_reprojection_px;
      for (std::size_t c = 0; c < normalised_[k].size(); ++c) {
        if (used_[k][c]) continue;
        if (const double px = pixels(k, seen, normalised_[k][c]); px <= best_px) {
          best_px = px;
          best = int(c);
        }
      }
      if (best >= 0) confirming_.push_back({k, std::size_t(best)});
    }
    if (ambiguous && confirming_.empty() && !known(x) && !near(held_, x)) {
      ++stats_.pairs_ambiguous;
      continue;
    }
    used_[i][a] = used_[j][b] = 1;
    if (!confirming_.empty()) {
      // All views together, unless one of them then reprojects too far (it saw another
      // marker, or two merged): then the pair's point alone.
      for (const auto& [k, c] : confirming_) views_.push_back({projections_[k], normalised_[k][c]});
      const Eigen::Vector3d all = triangulate_dlt(views_);
      bool consistent = pixels(i, project_normalised(i, all), views_[0].normalised) <= params_.max_reprojection_px &&
                        pixels(j, project_normalised(j, all), views_[1].normalised) <= params_.max_reprojection_px;
      for (std::size_t v = 0; consistent && v < confirming_.size(); ++v) {
        const std::size_t k = confirming_[v].first;
        consistent = pixels(k, project_normalised(k, all), views_[v + 2].normalised) <= params_.max_reprojection_px;
      }
      if (consistent) {
        for (const auto& [k, c] : confirming_) used_[k][c] = 1;
        ++stats_.multi_view_points;
        out.push_back(all);
        continue;
      }
    }
    if (!known(x) && !near(held_, x)) {
      holding_.push_back(x);
      ++stats_.points_held;
      continue;
    }
    out.push_back(x);
  }
  remember(out);
  held_.swap(holding_);
  holding_.clear();
  ++set_;
  stats_.points = int(out.size());
  for (std::size_t c = 0; c < n; ++c)
    stats_.blobs_unmatched += int(std::count(used_[c].begin(), used_[c].end(), uint8_t{0}));
}

}  // namespace facecap::drivers::v4l2
