#pragma once
// Evaluation metrics of a solved mesh (facecap eval, the tests): triangle pairs that
// touch or cross, new ones against the rest pose, and flipped triangles. Not real-time:
// they allocate and throw Error on misuse.
#include <cstdint>
#include <memory>
#include <vector>

#include <Eigen/Core>

#include "solver/collide/triangle_pair.hpp"

namespace facecap {

// The "intersections" metric frame after frame on one mesh: the tree over every
// triangle is built once and refitted per call. Counts pairs of triangles sharing no
// vertex that touch or cross (triangles_intersect); pairs sharing a vertex always touch
// and are not counted. Not real-time: count() does not allocate, but it is not bounded
// and throws Error on misuse.
class IntersectionCounter {
 public:
  IntersectionCounter();
  ~IntersectionCounter();
  IntersectionCounter(IntersectionCounter&&) noexcept;
  IntersectionCounter& operator=(IntersectionCounter&&) noexcept;

  // triangles: 3 x T; rest_positions: 3 x N, where the tree is built. Allocates.
  void configure(const Eigen::Matrix3Xi& triangles, const Eigen::Matrix3Xd& rest_positions);
  // positions: 3 x N.
  int64_t count(const Eigen::Matrix3Xd& positions);
  std::vector<TrianglePair> pairs(const Eigen::Matrix3Xd& positions);  // sorted

 private:
  template <typename Found>
  void for_each(const Eigen::Matrix3Xd& positions, Found&& found);
  struct State;
  std::unique_ptr<State> state_;
};

// One-off IntersectionCounter::count over the whole mesh (builds a tree per call).
// triangles: 3 x T; positions: 3 x N.
int64_t count_intersecting_pairs(const Eigen::Matrix3Xi& triangles, const Eigen::Matrix3Xd& positions);

// The pairs themselves, sorted; the same set count_intersecting_pairs counts.
std::vector<TrianglePair> intersecting_pairs(const Eigen::Matrix3Xi& triangles, const Eigen::Matrix3Xd& positions);

// Intersecting pairs at `positions` that do not intersect at `rest_positions`: the
// metric for rigs whose neutral already self-intersects (ICT: 124 pairs at the lip
// corners).
int64_t count_new_intersecting_pairs(const Eigen::Matrix3Xi& triangles, const Eigen::Matrix3Xd& rest_positions,
                                     const Eigen::Matrix3Xd& positions);

// The triangles whose normal points against their rest normal (dot product < 0), in
// increasing order. Zero-area triangles (rest or current) are not counted.
std::vector<Eigen::Index> flipped_triangles(const Eigen::Matrix3Xi& triangles, const Eigen::Matrix3Xd& rest_positions,
                                            const Eigen::Matrix3Xd& positions);
// Their count.
int64_t count_flipped_triangles(const Eigen::Matrix3Xi& triangles, const Eigen::Matrix3Xd& rest_positions,
                                const Eigen::Matrix3Xd& positions);

}  // namespace facecap
