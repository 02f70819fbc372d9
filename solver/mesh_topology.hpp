#pragma once
// Triangle adjacency of a triangle mesh, and the check of its vertex indices
// (precomputation only: these allocate or throw).
#include <span>
#include <utility>
#include <vector>

#include <Eigen/Core>

namespace facecap {

// Throws Error unless every index of `triangles` (3 x T) lies in [0, vertex_count).
void check_triangle_indices(const Eigen::Matrix3Xi& triangles, Eigen::Index vertex_count);

// Edges (low vertex, high vertex) used by one triangle only: the mesh's open borders.
std::vector<std::pair<int, int>> boundary_edges(const Eigen::Matrix3Xi& triangles);

// The vertices of the longest connected run of boundary edges, by length at `vertices`
// (3 x N), ascending: a face mesh's outer edge, where the eyes' and mouth's openings are
// shorter loops. Empty for a closed mesh.
std::vector<int> outer_boundary_vertices(const Eigen::Matrix3Xi& triangles, const Eigen::Matrix3Xd& vertices);

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
