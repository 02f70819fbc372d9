#pragma once
// Evaluation counts over a whole solved mesh: triangle pairs that intersect and
// triangles that flipped. Exact in the sense of closed triangles (touching counts) with
// ordinary double-precision orientation tests; not real-time (allocates).
//
// The collision module being written for the solver (branch `collide`) brings the same
// counts as intersecting_pairs / count_flipped_triangles (checked equal on 720 built-in
// poses); eval should switch to those once they are on main, and these can go.
#include <cstdint>
#include <utility>
#include <vector>

#include <Eigen/Core>

namespace facecap::tools {

// Pairs of triangles sharing no vertex whose closed triangles share a point (touch or
// cross). Pairs that share a vertex always touch and are not counted. triangles: 3 x T;
// positions: 3 x N. Sweep and prune on the longest axis, then the exact test.
int64_t count_intersecting_triangle_pairs(const Eigen::Matrix3Xi& triangles, const Eigen::Matrix3Xd& positions);

// The pairs themselves (first < second), sorted: the set the count counts.
std::vector<std::pair<int, int>> intersecting_triangle_pairs(const Eigen::Matrix3Xi& triangles,
                                                             const Eigen::Matrix3Xd& positions);

// Whether closed triangles a and b share a point.
bool closed_triangles_intersect(const Eigen::Vector3d& a0, const Eigen::Vector3d& a1, const Eigen::Vector3d& a2,
                                const Eigen::Vector3d& b0, const Eigen::Vector3d& b1, const Eigen::Vector3d& b2);

// Triangles whose normal points against their rest normal (dot product < 0); triangles
// of zero area at rest or now are not counted.
int64_t count_flipped_triangles_against_rest(const Eigen::Matrix3Xi& triangles, const Eigen::Matrix3Xd& rest_positions,
                                             const Eigen::Matrix3Xd& positions);

}  // namespace facecap::tools
