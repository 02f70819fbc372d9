#include "solver/collide/folds.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <span>

#include <Eigen/Geometry>

#include "solver/kernels/kernels.hpp"
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

double fold_tolerance(const Rig& rig) { return kFoldToleranceMm * rig_units_per_mm(rig); }

void FoldDetector::configure(const Eigen::Matrix3Xi& triangles, std::vector<uint8_t> regions, double crease_degrees,
                             double tolerance, const kernels::KernelTable* kernels) {
  kernels_ = kernels ? kernels : &kernels::table(KernelPath::kAuto);
  triangles_ = triangles;
  triangle_count_ = triangles.cols();
  padded_count_ = (triangle_count_ + kernels::kFoldPadding - 1) / kernels::kFoldPadding * kernels::kFoldPadding;
  vertex_count_ = triangle_count_ > 0 ? Eigen::Index(triangles.maxCoeff()) + 1 : 0;
  regions_ = regions.empty() ? std::vector<uint8_t>(std::size_t(triangle_count_), kRegionElsewhere) : std::move(regions);
  crease_radians_ = crease_degrees * std::numbers::pi / 180.0;
  tolerance_ = tolerance;
  // Padding triangles name vertex 0 three times: no area, never flipped or stretched.
  corners_.assign(std::size_t(3 * padded_count_), 0);
  for (Eigen::Index t = 0; t < triangle_count_; ++t)
    for (int j = 0; j < 3; ++j) corners_[std::size_t(j * padded_count_ + t)] = triangles(j, t);
  adjacency_ = TriangleAdjacency(triangles);
  solved_.assign(std::size_t(3 * vertex_count_), 0.0f);
  reference_.assign(std::size_t(3 * vertex_count_), 0.0f);
  solved_normals_.assign(std::size_t(3 * padded_count_), 0.0f);
  reference_normals_.assign(std::size_t(3 * padded_count_), 0.0f);
  flipped_list_.assign(std::size_t(padded_count_), 0);
  turned_list_.assign(std::size_t(padded_count_), 0);
  turned_.assign(std::size_t(padded_count_), 0);
  folded_.assign(std::size_t(triangle_count_), 0);
  folded_list_.assign(std::size_t(triangle_count_), 0);
  report_ = {};
}

void FoldDetector::copy_positions(const Eigen::Matrix3Xd& mesh, std::vector<float>& out) const noexcept {
  const double* p = mesh.data();
  float* x = out.data();
  float* y = x + vertex_count_;
  float* z = y + vertex_count_;
  for (Eigen::Index v = 0; v < vertex_count_; ++v) {
    x[v] = float(p[3 * v]);
    y[v] = float(p[3 * v + 1]);
    z[v] = float(p[3 * v + 2]);
  }
}

Eigen::Vector3d FoldDetector::normal(const std::vector<float>& normals, int t) const noexcept {
  const std::size_t i = std::size_t(t), stride = std::size_t(padded_count_);
  return {normals[i], normals[i + stride], normals[i + 2 * stride]};
}

Eigen::Vector3d FoldDetector::judged_normal(int t) const noexcept {
  const std::size_t stride = std::size_t(vertex_count_);
  for (int j = 0; j < 3; ++j) {
    const std::size_t v = std::size_t(triangles_(j, t));
    const float dx = solved_[v] - reference_[v], dy = solved_[v + stride] - reference_[v + stride],
                dz = solved_[v + 2 * stride] - reference_[v + 2 * stride];
    if (dx * dx + dy * dy + dz * dz > float(tolerance_ * tolerance_)) return normal(solved_normals_, t);
  }
  return normal(reference_normals_, t);
}

const FoldReport& FoldDetector::measure(const Eigen::Matrix3Xd& solved, const Eigen::Matrix3Xd& reference) noexcept {
  copy_positions(reference, reference_);
  copy_positions(solved, solved_);
  return measure_solved(false);
}

const FoldReport& FoldDetector::measure_again(const Eigen::Matrix3Xd& solved) noexcept {
  copy_positions(solved, solved_);
  return measure_solved(true);
}

const FoldReport& FoldDetector::measure_solved(bool reference_known) noexcept {
  for (uint32_t i = 0; i < report_.folded; ++i) folded_[std::size_t(folded_list_[i])] = 0;
  report_ = {};
  if (triangle_count_ == 0) return report_;
  kernels::FoldTrianglesView view;
  view.count = padded_count_;
  for (int j = 0; j < 3; ++j) view.corner[j] = corners_.data() + j * padded_count_;
  view.solved = solved_.data();
  view.reference = reference_.data();
  view.vertex_stride = vertex_count_;
  view.solved_normals = solved_normals_.data();
  view.reference_normals = reference_normals_.data();
  view.normal_stride = padded_count_;
  view.cos_half_crease = float(std::cos(0.5 * crease_radians_));
  view.tolerance_squared = float(tolerance_ * tolerance_);
  view.flipped = flipped_list_.data();
  view.turned = turned_list_.data();
  const kernels::FoldTrianglesResult passed = kernels_->fold_triangles(view, reference_known);
  report_.max_edge_stretch = passed.max_edge_stretch;
  auto fold = [&](int t) {
    if (folded_[std::size_t(t)]) return;
    folded_[std::size_t(t)] = 1;
    folded_list_[report_.folded++] = t;
    ++report_.folded_by_region[regions_[std::size_t(t)]];
  };
  for (int64_t i = 0; i < passed.flipped; ++i) fold(flipped_list_[std::size_t(i)]);
  report_.flipped = report_.folded;
  // A crease: the angle between the solve's normals across an edge exceeds the
  // reference's by more than crease_radians_ (a triangle within the tolerance counted with
  // the reference's normal). Only a pair with a turned triangle can; each such pair is
  // taken once (at its lower turned triangle).
  auto angle = [](const Eigen::Vector3d& n0, const Eigen::Vector3d& n1) {
    const double norms = std::sqrt(n0.squaredNorm() * n1.squaredNorm());
    return norms > 0.0 ? std::acos(std::clamp(n0.dot(n1) / norms, -1.0, 1.0)) : 0.0;
  };
  const std::span<const int32_t> turned(turned_list_.data(), std::size_t(passed.turned));
  for (const int32_t t : turned) turned_[std::size_t(t)] = 1;
  for (const int32_t t : turned) {
    if (t >= triangle_count_) break;  // padding, listed last
    const Eigen::Vector3d solved_t = normal(solved_normals_, t), reference_t = normal(reference_normals_, t);  // turned: visible
    for (const int u : adjacency_.neighbours(t)) {
      if (turned_[std::size_t(u)] && u < t) continue;
      if (angle(solved_t, judged_normal(u)) - angle(reference_t, normal(reference_normals_, u)) > crease_radians_) {
        fold(t);
        fold(u);
      }
    }
  }
  for (const int32_t t : turned) turned_[std::size_t(t)] = 0;
  std::sort(folded_list_.begin(), folded_list_.begin() + report_.folded);
  return report_;
}

}  // namespace facecap
