#pragma once
// Triangle adjacency and border loops of a triangle mesh (precomputation only).
#include <span>
#include <vector>

#include <Eigen/Core>

namespace facecap {

class TriangleAdjacency {
 public:
  TriangleAdjacency(const Eigen::Matrix3Xi& triangles, Eigen::Index vertex_count);

  // Triangles sharing an edge with triangle t.
  std::span<const int> neighbours(int t) const {
    return {neighbour_.data() + start_[std::size_t(t)], neighbour_.data() + start_[std::size_t(t) + 1]};
  }
  // Closed loops of border edges (edges used by one triangle), as vertex sequences.
  const std::vector<std::vector<int>>& border_loops() const { return loops_; }

 private:
  std::vector<int> start_, neighbour_;
  std::vector<std::vector<int>> loops_;
};

}  // namespace facecap
