#include "solver/align/surface.hpp"

#include <algorithm>
#include <limits>

#include <Eigen/Geometry>
#include <nanoflann.hpp>

#include "core/error.hpp"

namespace facecap::align {

namespace {
struct MatrixAdaptor {
  const Eigen::Matrix3Xd* m;
  std::size_t kdtree_get_point_count() const { return std::size_t(m->cols()); }
  double kdtree_get_pt(std::size_t i, std::size_t dim) const { return (*m)(Eigen::Index(dim), Eigen::Index(i)); }
  template <class Box>
  bool kdtree_get_bbox(Box&) const { return false; }
};
using KdTree = nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<double, MatrixAdaptor>, MatrixAdaptor, 3, uint32_t>;
}  // namespace

struct PointIndex::Tree {
  MatrixAdaptor adaptor;
  KdTree tree;
  explicit Tree(const Eigen::Matrix3Xd* m)
      : adaptor{m}, tree(3, adaptor, nanoflann::KDTreeSingleIndexAdaptorParams(10)) {
    tree.buildIndex();
  }
};

PointIndex::PointIndex(Eigen::Matrix3Xd points) : points_(std::move(points)) {
  if (points_.cols() == 0) throw Error("k-d tree: no points");
  if (!points_.allFinite()) throw Error("k-d tree: non-finite coordinates");
  tree_ = std::make_unique<Tree>(&points_);
}
PointIndex::~PointIndex() = default;

int PointIndex::nearest(const Eigen::Vector3d& query, double* distance_sq) const noexcept {
  uint32_t index = 0;
  double d2 = std::numeric_limits<double>::infinity();
  tree_->tree.knnSearch(query.data(), 1, &index, &d2);
  if (distance_sq) *distance_sq = d2;
  return int(index);
}

int PointIndex::nearest_k(const Eigen::Vector3d& query, int count, int* out_indices, double* out_distances_sq) const noexcept {
  std::array<uint32_t, 64> idx{};
  count = std::clamp(count, 1, 64);
  const auto found = tree_->tree.knnSearch(query.data(), std::size_t(count), idx.data(), out_distances_sq);
  for (std::size_t i = 0; i < found; ++i) out_indices[i] = int(idx[i]);
  return int(found);
}

Eigen::Vector3d closest_point_on_triangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                          const Eigen::Vector3d& c, Eigen::Vector3d& bary) noexcept {
  const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0.0 && d2 <= 0.0) { bary = {1, 0, 0}; return a; }
  const Eigen::Vector3d bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0.0 && d4 <= d3) { bary = {0, 1, 0}; return b; }
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) {
    const double v = d1 / (d1 - d3);
    bary = {1 - v, v, 0};
    return a + v * ab;
  }
  const Eigen::Vector3d cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0.0 && d5 <= d6) { bary = {0, 0, 1}; return c; }
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) {
    const double w = d2 / (d2 - d6);
    bary = {1 - w, 0, w};
    return a + w * ac;
  }
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0) {
    const double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    bary = {0, 1 - w, w};
    return b + w * (c - b);
  }
  const double denom = 1.0 / (va + vb + vc);
  const double v = vb * denom, w = vc * denom;
  bary = {1 - v - w, v, w};
  return a + ab * v + ac * w;
}

SurfaceIndex::SurfaceIndex(const Eigen::Matrix3Xd& vertices, const Eigen::Matrix3Xi& triangles, int vertex_candidates)
    : triangles_(triangles), vertex_index_(vertices), candidates_(std::clamp(vertex_candidates, 1, 64)) {
  const Eigen::Index N = vertices.cols();
  if (triangles_.cols() == 0) throw Error("surface index: mesh has no triangles");
  if (triangles_.minCoeff() < 0 || triangles_.maxCoeff() >= N) throw Error("surface index: triangle index out of range");
  incident_start_.assign(std::size_t(N) + 1, 0);
  for (Eigen::Index t = 0; t < triangles_.cols(); ++t)
    for (int k = 0; k < 3; ++k) ++incident_start_[std::size_t(triangles_(k, t)) + 1];
  for (std::size_t v = 0; v < std::size_t(N); ++v) incident_start_[v + 1] += incident_start_[v];
  incident_.resize(std::size_t(incident_start_.back()));
  std::vector<int> fill(incident_start_.begin(), incident_start_.end() - 1);
  for (Eigen::Index t = 0; t < triangles_.cols(); ++t)
    for (int k = 0; k < 3; ++k) incident_[std::size_t(fill[std::size_t(triangles_(k, t))]++)] = int(t);
}

SurfacePoint SurfaceIndex::closest(const Eigen::Vector3d& p) const noexcept {
  std::array<int, 64> near{};
  std::array<double, 64> d2{};
  const int found = vertex_index_.nearest_k(p, candidates_, near.data(), d2.data());
  SurfacePoint best;
  best.distance = std::numeric_limits<double>::infinity();
  const Eigen::Matrix3Xd& V = vertices();
  for (int i = 0; i < found; ++i) {
    const int v = near[std::size_t(i)];
    for (int j = incident_start_[std::size_t(v)]; j < incident_start_[std::size_t(v) + 1]; ++j) {
      const int t = incident_[std::size_t(j)];
      Eigen::Vector3d bary;
      const Eigen::Vector3d q =
          closest_point_on_triangle(p, V.col(triangles_(0, t)), V.col(triangles_(1, t)), V.col(triangles_(2, t)), bary);
      const double d = (q - p).norm();
      if (d < best.distance) best = {t, bary, q, d};
    }
  }
  return best;
}

Eigen::Vector3d SurfaceIndex::triangle_normal(int t) const noexcept {
  const Eigen::Matrix3Xd& V = vertices();
  const Eigen::Vector3d n = (V.col(triangles_(1, t)) - V.col(triangles_(0, t))).cross(V.col(triangles_(2, t)) - V.col(triangles_(0, t)));
  const double len = n.norm();
  return len > 0.0 ? Eigen::Vector3d(n / len) : Eigen::Vector3d::Zero();
}

SurfacePoint SurfaceIndex::closest_exhaustive(const Eigen::Vector3d& p) const noexcept {
  SurfacePoint best;
  best.distance = std::numeric_limits<double>::infinity();
  const Eigen::Matrix3Xd& V = vertices();
  for (Eigen::Index t = 0; t < triangles_.cols(); ++t) {
    Eigen::Vector3d bary;
    const Eigen::Vector3d q =
        closest_point_on_triangle(p, V.col(triangles_(0, t)), V.col(triangles_(1, t)), V.col(triangles_(2, t)), bary);
    const double d = (q - p).norm();
    if (d < best.distance) best = {int(t), bary, q, d};
  }
  return best;
}

}  // namespace facecap::align
