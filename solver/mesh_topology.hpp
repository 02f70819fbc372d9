#pragma once
// Triangle adjacency of a triangle mesh (precomputation only).
#include <span>
#include <vector>

#include <Eigen/Core>

namespace facecap {

class TriangleAdjacency {
 public:
  explicit TriangleAdjacency(const Eigen::Matrix3Xi& triangles);

  // Triangles sharing an edge with triangle t.
  std::span<const int> neighbours(int t) const {
    return {neighbour_.data() + start_[std::size_t(t)], neighbour_.data() + start_[std::size_t(t) + 1]};
  }

 private:
  std::vector<int> start_, neighbour_;
};

}  // namespace facecap
