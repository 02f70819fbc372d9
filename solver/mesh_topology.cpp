#include "solver/mesh_topology.hpp"

#include <algorithm>
#include <numeric>
#include <tuple>

#include <fmt/format.h>

#include "core/error.hpp"

namespace facecap {

void check_triangle_indices(const Eigen::Matrix3Xi& triangles, Eigen::Index vertex_count) {
  if (triangles.size() > 0 && (triangles.minCoeff() < 0 || triangles.maxCoeff() >= vertex_count))
    throw Error(fmt::format("triangle vertex indices must lie in [0, {})", vertex_count));
}

std::vector<std::pair<int, int>> boundary_edges(const Eigen::Matrix3Xi& triangles) {
  std::vector<std::pair<int, int>> edges;
  edges.reserve(std::size_t(triangles.cols()) * 3);
  for (Eigen::Index t = 0; t < triangles.cols(); ++t)
    for (int k = 0; k < 3; ++k) {
      const int a = triangles(k, t), b = triangles((k + 1) % 3, t);
      edges.emplace_back(std::min(a, b), std::max(a, b));
    }
  std::sort(edges.begin(), edges.end());
  std::vector<std::pair<int, int>> once;
  for (std::size_t i = 0; i < edges.size();) {
    std::size_t j = i;
    while (j < edges.size() && edges[j] == edges[i]) ++j;
    if (j - i == 1) once.push_back(edges[i]);
    i = j;
  }
  return once;
}

std::vector<int> outer_boundary_vertices(const Eigen::Matrix3Xi& triangles, const Eigen::Matrix3Xd& vertices) {
  const std::vector<std::pair<int, int>> edges = boundary_edges(triangles);
  if (edges.empty()) return {};
  // Union-find over the boundary edges' vertices; each run's length summed at its root.
  std::vector<int> parent(std::size_t(vertices.cols()));
  std::iota(parent.begin(), parent.end(), 0);
  auto root = [&](int v) {
    while (parent[std::size_t(v)] != v) v = parent[std::size_t(v)] = parent[std::size_t(parent[std::size_t(v)])];
    return v;
  };
  for (const auto& [a, b] : edges) parent[std::size_t(root(a))] = root(b);
  std::vector<double> length(parent.size(), 0.0);
  for (const auto& [a, b] : edges) length[std::size_t(root(a))] += (vertices.col(a) - vertices.col(b)).norm();
  const int longest = int(std::max_element(length.begin(), length.end()) - length.begin());
  std::vector<int> loop;
  for (const auto& [a, b] : edges)
    if (root(a) == longest) loop.insert(loop.end(), {a, b});
  std::sort(loop.begin(), loop.end());
  loop.erase(std::unique(loop.begin(), loop.end()), loop.end());
  return loop;
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
