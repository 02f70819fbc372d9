#pragma once
// Nearest-neighbour queries for calibration: a k-d tree (nanoflann) over points, and the
// closest point on a triangle mesh's surface (triangle + barycentric coordinates).
// Built off the real-time thread; queries are const, allocation-free and thread-safe.
#include <array>
#include <memory>
#include <vector>

#include <Eigen/Core>

namespace facecap::align {

// k-d tree over the columns of a 3 x N matrix (kept by value).
class PointIndex {
 public:
  explicit PointIndex(Eigen::Matrix3Xd points);
  ~PointIndex();
  PointIndex(const PointIndex&) = delete;
  PointIndex& operator=(const PointIndex&) = delete;

  // Index of the nearest point and its squared distance.
  int nearest(const Eigen::Vector3d& query, double* distance_sq = nullptr) const noexcept;
  // Up to count nearest (count <= 64), nearest first; returns how many were found.
  int nearest_k(const Eigen::Vector3d& query, int count, int* out_indices, double* out_distances_sq) const noexcept;
  const Eigen::Matrix3Xd& points() const { return points_; }

 private:
  struct Tree;
  Eigen::Matrix3Xd points_;
  std::unique_ptr<Tree> tree_;
};

struct SurfacePoint {
  int triangle = -1;
  Eigen::Vector3d barycentric = Eigen::Vector3d(1.0, 0.0, 0.0);  // over the triangle's vertices
  Eigen::Vector3d position = Eigen::Vector3d::Zero();
  double distance = 0.0;
};

// Closest point to p on triangle (a, b, c), with its barycentric coordinates (Ericson,
// Real-Time Collision Detection 5.1.5).
Eigen::Vector3d closest_point_on_triangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                          const Eigen::Vector3d& c, Eigen::Vector3d& barycentric) noexcept;

// Closest surface point of a mesh: the k-d tree finds the nearest vertices, then the
// triangles around them are searched exactly. Exact whenever the closest point lies on a
// triangle touching one of the `vertex_candidates` nearest vertices (always, for a
// query near a mesh with reasonably even triangles).
class SurfaceIndex {
 public:
  SurfaceIndex(const Eigen::Matrix3Xd& vertices, const Eigen::Matrix3Xi& triangles, int vertex_candidates = 8);
  SurfacePoint closest(const Eigen::Vector3d& p) const noexcept;
  // Exhaustive over every triangle: slow, exact, for binding and tests.
  SurfacePoint closest_exhaustive(const Eigen::Vector3d& p) const noexcept;
  const PointIndex& vertex_index() const { return vertex_index_; }
  // Unit normal of triangle t (right-handed winding).
  Eigen::Vector3d triangle_normal(int t) const noexcept;

 private:
  const Eigen::Matrix3Xd& vertices() const { return vertex_index_.points(); }
  Eigen::Matrix3Xi triangles_;
  PointIndex vertex_index_;
  std::vector<int> incident_start_, incident_;  // CSR: triangles around each vertex
  int candidates_;
};

}  // namespace facecap::align
