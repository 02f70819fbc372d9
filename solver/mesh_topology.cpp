#include "solver/mesh_topology.hpp"

#include <algorithm>
#include <tuple>
#include <unordered_map>

namespace facecap {

TriangleAdjacency::TriangleAdjacency(const Eigen::Matrix3Xi& triangles, Eigen::Index vertex_count) {
  const Eigen::Index T = triangles.cols();
  // (low vertex, high vertex, triangle, directed-from) for every edge, sorted to pair them.
  std::vector<std::tuple<int, int, int, int>> edges;
  edges.reserve(std::size_t(T) * 3);
  for (Eigen::Index t = 0; t < T; ++t)
    for (int k = 0; k < 3; ++k) {
      const int a = triangles(k, t), b = triangles((k + 1) % 3, t);
      edges.emplace_back(std::min(a, b), std::max(a, b), int(t), a);
    }
  std::sort(edges.begin(), edges.end());
  std::vector<std::vector<int>> lists;
  lists.resize(std::size_t(T));
  std::unordered_map<int, int> border_next;  // border edge a -> b, in triangle orientation
  for (std::size_t i = 0; i < edges.size();) {
    std::size_t j = i;
    while (j < edges.size() && std::get<0>(edges[j]) == std::get<0>(edges[i]) && std::get<1>(edges[j]) == std::get<1>(edges[i])) ++j;
    if (j - i == 1) {
      const auto [lo, hi, t, from] = edges[i];
      border_next[from] = from == lo ? hi : lo;
    }
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

  std::vector<uint8_t> visited(std::size_t(vertex_count), 0);
  std::vector<int> starts;
  for (const auto& [from, to] : border_next) starts.push_back(from);
  std::sort(starts.begin(), starts.end());  // deterministic loop order
  for (int s : starts) {
    if (visited[std::size_t(s)]) continue;
    std::vector<int> loop;
    for (int v = s; !visited[std::size_t(v)];) {
      visited[std::size_t(v)] = 1;
      loop.push_back(v);
      const auto it = border_next.find(v);
      if (it == border_next.end()) break;
      v = it->second;
    }
    loops_.push_back(std::move(loop));
  }
}

}  // namespace facecap
