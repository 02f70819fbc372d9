#include "solver/collide/folds.hpp"

#include <algorithm>
#include <cmath>
#include <map>
#include <numbers>

#include <Eigen/Geometry>

#include "solver/mesh_topology.hpp"
#include "solver/rig.hpp"

namespace facecap {

std::vector<uint8_t> triangle_regions(const Rig& rig) {
  std::vector<uint8_t> vertex(std::size_t(rig.vertex_count()), kRegionElsewhere);
  auto mark = [&](std::initializer_list<const char*> shapes, FaceRegion region) {
    for (const char* name : shapes) {
      const auto s = rig.shape_index(name);
      if (!s) continue;
      const Eigen::Map<const Eigen::Matrix3Xd> d(rig.deltas.col(*s).data(), 3, rig.vertex_count());
      const Eigen::VectorXd motion = d.colwise().norm().transpose();
      const double cutoff = 0.3 * motion.maxCoeff();
      for (Eigen::Index v = 0; v < rig.vertex_count(); ++v)
        if (motion[v] > 0.0 && motion[v] >= cutoff) vertex[std::size_t(v)] = std::min<uint8_t>(vertex[std::size_t(v)], region);
    }
  };
  mark({"mouthRollLower", "mouthRollUpper"}, kRegionLips);
  mark({"eyeBlink_L", "eyeBlink_R"}, kRegionEyelids);
  std::vector<uint8_t> out(std::size_t(rig.triangle_count()), kRegionElsewhere);
  for (Eigen::Index t = 0; t < rig.triangle_count(); ++t)
    for (int j = 0; j < 3; ++j) out[std::size_t(t)] = std::min(out[std::size_t(t)], vertex[std::size_t(rig.triangles(j, t))]);
  return out;
}

void FoldDetector::configure(const Eigen::Matrix3Xi& triangles, std::vector<uint8_t> regions, double crease_degrees) {
  triangles_ = triangles;
  triangle_count_ = triangles.cols();
  regions_ = regions.empty() ? std::vector<uint8_t>(std::size_t(triangle_count_), kRegionElsewhere) : std::move(regions);
  crease_radians_ = crease_degrees * std::numbers::pi / 180.0;
  // Each edge once, and the pairs of triangles that share one.
  std::map<std::pair<int, int>, int> first_triangle;
  edges_.clear();
  interior_edges_.clear();
  for (Eigen::Index t = 0; t < triangle_count_; ++t)
    for (int j = 0; j < 3; ++j) {
      const int a = triangles(j, t), b = triangles((j + 1) % 3, t);
      const auto key = std::minmax(a, b);
      const auto [it, inserted] = first_triangle.try_emplace(key, int(t));
      if (inserted) edges_.push_back(key);
      else interior_edges_.push_back({it->second, int(t)});
    }
  solved_normals_.resize(3, triangle_count_);
  reference_normals_.resize(3, triangle_count_);
  folded_.assign(std::size_t(triangle_count_), 0);
  folded_list_.assign(std::size_t(triangle_count_), 0);
  report_ = {};
}

const FoldReport& FoldDetector::measure(const Eigen::Matrix3Xd& solved, const Eigen::Matrix3Xd& reference) noexcept {
  for (Eigen::Index t = 0; t < triangle_count_; ++t) {
    const int a = triangles_(0, t), b = triangles_(1, t), c = triangles_(2, t);
    reference_normals_.col(t) = (reference.col(b) - reference.col(a)).cross(reference.col(c) - reference.col(a));
  }
  return measure_again(solved, reference);
}

const FoldReport& FoldDetector::measure_again(const Eigen::Matrix3Xd& solved, const Eigen::Matrix3Xd& reference) noexcept {
  report_ = {};
  for (Eigen::Index t = 0; t < triangle_count_; ++t) {
    const int a = triangles_(0, t), b = triangles_(1, t), c = triangles_(2, t);
    solved_normals_.col(t) = (solved.col(b) - solved.col(a)).cross(solved.col(c) - solved.col(a));
    folded_[std::size_t(t)] = solved_normals_.col(t).dot(reference_normals_.col(t)) < 0.0;
  }
  // A crease past crease_radians_ needs the solve's normals more than crease_radians_
  // apart, tested without square roots (dot < cos |n0| |n1|; for the default 90 degrees a
  // negative dot product); the angles are only taken where it holds.
  const double crease_cos = std::cos(crease_radians_), crease_cos2 = crease_cos * crease_cos;
  auto angle = [](const Eigen::Vector3d& n0, const Eigen::Vector3d& n1) {
    const double norms = std::sqrt(n0.squaredNorm() * n1.squaredNorm());
    return norms > 0.0 ? std::acos(std::clamp(n0.dot(n1) / norms, -1.0, 1.0)) : 0.0;
  };
  for (const auto& [t0, t1] : interior_edges_) {
    const auto n0 = solved_normals_.col(t0), n1 = solved_normals_.col(t1);
    const double dot = n0.dot(n1);
    // At 90 degrees (the default) the bound is 0 and the norms are not needed.
    auto dot2_bound = [&] { return crease_cos2 * n0.squaredNorm() * n1.squaredNorm(); };
    const bool apart = crease_cos >= 0.0 ? (dot < 0.0 || (crease_cos2 > 0.0 && dot * dot < dot2_bound()))
                                         : (dot < 0.0 && dot * dot > dot2_bound());
    if (!apart) continue;
    if (angle(n0, n1) - angle(reference_normals_.col(t0), reference_normals_.col(t1)) <= crease_radians_) continue;
    folded_[std::size_t(t0)] = folded_[std::size_t(t1)] = 1;
  }
  for (Eigen::Index t = 0; t < triangle_count_; ++t) {
    if (!folded_[std::size_t(t)]) continue;
    folded_list_[report_.folded++] = int(t);
    ++report_.folded_by_region[regions_[std::size_t(t)]];
    report_.flipped += solved_normals_.col(t).dot(reference_normals_.col(t)) < 0.0;
  }
  // | |e| - |e_ref| | = |e^2 - e_ref^2| / (|e| + |e_ref|) <= |e^2 - e_ref^2| / max(|e|, |e_ref|):
  // an edge whose bound is within the largest so far is passed over without a square root.
  double stretch = 0.0;
  for (const auto& [a, b] : edges_) {
    const double solved2 = (solved.col(a) - solved.col(b)).squaredNorm(), reference2 = (reference.col(a) - reference.col(b)).squaredNorm();
    const double difference = std::abs(solved2 - reference2);
    if (difference * difference <= stretch * stretch * std::max(solved2, reference2)) continue;
    stretch = std::max(stretch, std::abs(std::sqrt(solved2) - std::sqrt(reference2)));
  }
  report_.max_edge_stretch = stretch;
  return report_;
}

}  // namespace facecap
