#include "solver/collide/metrics.hpp"

#include <algorithm>
#include <iterator>
#include <numeric>

#include <Eigen/Geometry>
#include <fmt/format.h>

#include "core/error.hpp"
#include "solver/collide/bvh.hpp"
#include "solver/collide/geometry.hpp"
#include "solver/mesh_topology.hpp"

namespace facecap {

struct IntersectionCounter::State {
  bvh::Tree tree;
  Eigen::Index vertex_count = 0;
};

IntersectionCounter::IntersectionCounter() = default;
IntersectionCounter::~IntersectionCounter() = default;
IntersectionCounter::IntersectionCounter(IntersectionCounter&&) noexcept = default;
IntersectionCounter& IntersectionCounter::operator=(IntersectionCounter&&) noexcept = default;

void IntersectionCounter::configure(const Eigen::Matrix3Xi& triangles, const Eigen::Matrix3Xd& rest_positions) {
  check_triangle_indices(triangles, rest_positions.cols());
  auto state = std::make_unique<State>();
  state->vertex_count = rest_positions.cols();
  std::vector<int32_t> every(std::size_t(triangles.cols()));
  std::iota(every.begin(), every.end(), 0);
  state->tree.build(triangles, rest_positions, every);
  state_ = std::move(state);
}

template <typename Found>
void IntersectionCounter::for_each(const Eigen::Matrix3Xd& positions, Found&& found) {
  if (!state_) throw Error("intersection counter used before configure()");
  if (positions.cols() != state_->vertex_count)
    throw Error(fmt::format("intersection counter configured for {} vertices, given {}", state_->vertex_count,
                            positions.cols()));
  bvh::Tree& tree = state_->tree;
  tree.refit(positions, 0.0);  // touching boxes still overlap
  const auto slot_triangles = tree.slot_triangles();
  tree.for_each_overlapping_pair([&](int32_t slot_a, int32_t slot_b) {
    const auto& va = tree.slot_vertices(slot_a);
    const auto& vb = tree.slot_vertices(slot_b);
    if (!triangles_intersect(positions.col(va[0]), positions.col(va[1]), positions.col(va[2]), positions.col(vb[0]),
                             positions.col(vb[1]), positions.col(vb[2])))
      return;
    const int32_t ta = slot_triangles[std::size_t(slot_a)], tb = slot_triangles[std::size_t(slot_b)];
    found(TrianglePair{std::min(ta, tb), std::max(ta, tb)});
  });
}

int64_t IntersectionCounter::count(const Eigen::Matrix3Xd& positions) {
  int64_t n = 0;
  for_each(positions, [&](const TrianglePair&) { ++n; });
  return n;
}

std::vector<TrianglePair> IntersectionCounter::pairs(const Eigen::Matrix3Xd& positions) {
  std::vector<TrianglePair> out;
  for_each(positions, [&](const TrianglePair& p) { out.push_back(p); });
  std::sort(out.begin(), out.end());
  return out;
}

std::vector<TrianglePair> intersecting_pairs(const Eigen::Matrix3Xi& triangles, const Eigen::Matrix3Xd& positions) {
  IntersectionCounter counter;
  counter.configure(triangles, positions);
  return counter.pairs(positions);
}

int64_t count_intersecting_pairs(const Eigen::Matrix3Xi& triangles, const Eigen::Matrix3Xd& positions) {
  IntersectionCounter counter;
  counter.configure(triangles, positions);
  return counter.count(positions);
}

int64_t count_new_intersecting_pairs(const Eigen::Matrix3Xi& triangles, const Eigen::Matrix3Xd& rest_positions,
                                     const Eigen::Matrix3Xd& positions) {
  if (rest_positions.cols() != positions.cols())
    throw Error(fmt::format("new intersections: rest has {} vertices, positions {}", rest_positions.cols(),
                            positions.cols()));
  IntersectionCounter counter;
  counter.configure(triangles, rest_positions);
  const auto now = counter.pairs(positions);
  const auto at_rest = counter.pairs(rest_positions);
  std::vector<TrianglePair> fresh;
  std::set_difference(now.begin(), now.end(), at_rest.begin(), at_rest.end(), std::back_inserter(fresh));
  return int64_t(fresh.size());
}

int64_t count_flipped_triangles(const Eigen::Matrix3Xi& triangles, const Eigen::Matrix3Xd& rest_positions,
                                const Eigen::Matrix3Xd& positions) {
  return int64_t(flipped_triangles(triangles, rest_positions, positions).size());
}

std::vector<Eigen::Index> flipped_triangles(const Eigen::Matrix3Xi& triangles, const Eigen::Matrix3Xd& rest_positions,
                                            const Eigen::Matrix3Xd& positions) {
  if (rest_positions.cols() != positions.cols())
    throw Error(fmt::format("flipped triangles: rest has {} vertices, positions {}", rest_positions.cols(),
                            positions.cols()));
  check_triangle_indices(triangles, positions.cols());
  std::vector<Eigen::Index> flipped;
  for (Eigen::Index t = 0; t < triangles.cols(); ++t) {
    auto normal = [&](const Eigen::Matrix3Xd& x) {
      const Eigen::Vector3d p0 = x.col(triangles(0, t));
      return Eigen::Vector3d((x.col(triangles(1, t)) - p0).cross(x.col(triangles(2, t)) - p0));
    };
    if (normal(rest_positions).dot(normal(positions)) < 0.0) flipped.push_back(t);
  }
  return flipped;
}

}  // namespace facecap
