#pragma once
// Mesh sanity counts for evaluating solves without ground truth: triangle pairs that
// intersect, and triangles flipped relative to the neutral mesh. Offline (eval), not
// real-time.
#include <cstdint>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace facecap::tools {

class IntersectionCounter {
 public:
  explicit IntersectionCounter(const Eigen::Matrix3Xi& triangles);
  // Pairs of triangles sharing no vertex whose surfaces cross (an edge of one passes
  // through the other). vertices: 3 x N.
  int64_t count(const Eigen::Matrix3Xd& vertices);

 private:
  Eigen::Matrix3Xi triangles_;
  std::vector<int> order_;
  std::vector<Eigen::Vector3d> lo_, hi_;
};

// Triangles whose normal turned more than 90 degrees from the neutral's.
int64_t count_flipped_triangles(const Eigen::Matrix3Xi& triangles, const Eigen::Matrix3Xd& neutral,
                                const Eigen::Matrix3Xd& vertices);

}  // namespace facecap::tools
