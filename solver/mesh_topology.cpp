#include "solver/mesh_topology.hpp"

#include <algorithm>
#include <tuple>

#include <fmt/format.h>

#include "core/error.hpp"

namespace facecap {

void check_triangle_indices(const Eigen::Matrix3Xi& triangles, Eigen::Index vertex_count) {
  if (triangles.size() > 0 && (triangles.minCoeff() < 0 || triangles.maxCoeff() >= vertex_count))
    throw Error(fmt::format("triangle vertex indices must lie in [0, {})", vertex_count));
}

TriangleAdjacency::TriangleAdjacency(const Eigen::Matrix3Xi& triangles) {
  const Eigen::Index T = triangles.cols();
  // (low vertex, high vertex, triangle) for every edge, sorted to pair them.
  std::vector<std::tuple<int, int, int>> edges;
  edges.reserve(std::size_t(T) * 3);
  for (Eigen::Index t = 0; t < T; ++t)
    for (int k = 0; k < 3; ++k) {
      const int a = triangles(k, t), b = triangles((k + 1) % 3, t);
      edges.emplace_back(std::min(a, b), std::max(a, b), int(t));
    }
  std::sort(edges.begin(), edges.end());
  std::vector<std::vector<int>> lists;
  lists.resize(std::size_t(T));
  for (std::size_t i = 0; i < edges.size();) {
    std::size_t j = i;
    while (j < edges.size() && std::get<0>(edges[j]) == std::get<0>(edges[i]) && std::get<1>(edges[j]) == std::get<1>(edges[i])) ++j;
    for (std::size_t a = i; a < j; ++a)
      for (std::size_t b = i; b < j; ++b)
        if (a != b) lists[std::size_t(std::get<2>(edges[a]))].push_back(std::get<2>(edges[b]));
    i = j;
  }
  start_.reserve(std::size_t(T) + 1);
  for (const auto& l : lists) {
    start_.push_back(int(neighbour_.size()));
    neighbour_.insert(neighbour_.end(), l.begin(), l.end());
  }
  start_.push_back(int(neighbour_.size()));
}

}  // namespace facecap
