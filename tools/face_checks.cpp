#include "tools/face_checks.hpp"

#include <algorithm>
#include <cmath>

namespace facecap::tools {
namespace {

// Does segment pq cross triangle abc (Moller-Trumbore restricted to the segment)?
bool segment_hits_triangle(const Eigen::Vector3d& p, const Eigen::Vector3d& q, const Eigen::Vector3d& a,
                           const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  const Eigen::Vector3d dir = q - p, e1 = b - a, e2 = c - a;
  const Eigen::Vector3d h = dir.cross(e2);
  const double det = e1.dot(h);
  const double scale = e1.norm() * e2.norm() * dir.norm();
  if (std::abs(det) <= 1e-12 * scale) return false;  // parallel: touching, not crossing
  const double inv = 1.0 / det;
  const Eigen::Vector3d s = p - a;
  const double u = inv * s.dot(h);
  if (u < 0.0 || u > 1.0) return false;
  const Eigen::Vector3d qv = s.cross(e1);
  const double v = inv * dir.dot(qv);
  if (v < 0.0 || u + v > 1.0) return false;
  const double t = inv * e2.dot(qv);
  return t > 0.0 && t < 1.0;
}

}  // namespace

IntersectionCounter::IntersectionCounter(const Eigen::Matrix3Xi& triangles) : triangles_(triangles) {
  order_.resize(std::size_t(triangles.cols()));
  lo_.resize(order_.size());
  hi_.resize(order_.size());
}

int64_t IntersectionCounter::count(const Eigen::Matrix3Xd& V) {
  const Eigen::Index T = triangles_.cols();
  for (Eigen::Index t = 0; t < T; ++t) {
    const Eigen::Vector3d a = V.col(triangles_(0, t)), b = V.col(triangles_(1, t)), c = V.col(triangles_(2, t));
    lo_[std::size_t(t)] = a.cwiseMin(b).cwiseMin(c);
    hi_[std::size_t(t)] = a.cwiseMax(b).cwiseMax(c);
    order_[std::size_t(t)] = int(t);
  }
  // Sweep along x: only boxes overlapping in x are compared.
  std::sort(order_.begin(), order_.end(), [&](int i, int j) { return lo_[std::size_t(i)].x() < lo_[std::size_t(j)].x(); });
  int64_t pairs = 0;
  for (std::size_t i = 0; i < order_.size(); ++i) {
    const int ti = order_[i];
    for (std::size_t j = i + 1; j < order_.size(); ++j) {
      const int tj = order_[j];
      if (lo_[std::size_t(tj)].x() > hi_[std::size_t(ti)].x()) break;
      if ((lo_[std::size_t(tj)].array() > hi_[std::size_t(ti)].array()).any() ||
          (lo_[std::size_t(ti)].array() > hi_[std::size_t(tj)].array()).any())
        continue;
      bool shared = false;
      for (int a = 0; a < 3 && !shared; ++a)
        for (int b = 0; b < 3; ++b) shared |= triangles_(a, ti) == triangles_(b, tj);
      if (shared) continue;
      bool hit = false;
      for (int e = 0; e < 3 && !hit; ++e) {
        hit = segment_hits_triangle(V.col(triangles_(e, ti)), V.col(triangles_((e + 1) % 3, ti)), V.col(triangles_(0, tj)),
                                    V.col(triangles_(1, tj)), V.col(triangles_(2, tj))) ||
              segment_hits_triangle(V.col(triangles_(e, tj)), V.col(triangles_((e + 1) % 3, tj)), V.col(triangles_(0, ti)),
                                    V.col(triangles_(1, ti)), V.col(triangles_(2, ti)));
      }
      pairs += hit;
    }
  }
  return pairs;
}

int64_t count_flipped_triangles(const Eigen::Matrix3Xi& F, const Eigen::Matrix3Xd& X0, const Eigen::Matrix3Xd& X) {
  int64_t flipped = 0;
  for (Eigen::Index t = 0; t < F.cols(); ++t) {
    const Eigen::Vector3d n0 = (X0.col(F(1, t)) - X0.col(F(0, t))).cross(X0.col(F(2, t)) - X0.col(F(0, t)));
    const Eigen::Vector3d n = (X.col(F(1, t)) - X.col(F(0, t))).cross(X.col(F(2, t)) - X.col(F(0, t)));
    flipped += n0.dot(n) < 0.0;
  }
  return flipped;
}

}  // namespace facecap::tools
