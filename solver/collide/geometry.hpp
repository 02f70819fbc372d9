#pragma once
// Exact triangle-triangle geometry in double precision, for the collision stage
// (DESIGN.md "Collisions") and the evaluation metrics: the distance between two closed
// triangles, whether they touch or cross, and whether they are closer than a threshold.
// Ordinary floating-point predicates (no exact arithmetic): pairs within about 1e-12 of
// a threshold may be classified either way. All real-time safe: noexcept, no allocation.
#include <Eigen/Core>

namespace facecap {

// Euclidean distance between two closed triangles a = (a0, a1, a2) and b = (b0, b1, b2):
// 0 when they touch or cross, otherwise the smallest of the 6 vertex-face and 9
// edge-edge distances. Degenerate (zero-area) triangles are handled as segments/points.
double triangle_distance(const Eigen::Vector3d& a0, const Eigen::Vector3d& a1, const Eigen::Vector3d& a2,
                         const Eigen::Vector3d& b0, const Eigen::Vector3d& b1,
                         const Eigen::Vector3d& b2) noexcept;

// Whether the closed triangles share at least one point (distance exactly 0).
bool triangles_intersect(const Eigen::Vector3d& a0, const Eigen::Vector3d& a1, const Eigen::Vector3d& a2,
                         const Eigen::Vector3d& b0, const Eigen::Vector3d& b1,
                         const Eigen::Vector3d& b2) noexcept;

// triangle_distance(a, b) < epsilon (so always false for epsilon <= 0), with cheap
// separating-axis rejections first.
bool triangles_closer_than(const Eigen::Vector3d& a0, const Eigen::Vector3d& a1, const Eigen::Vector3d& a2,
                           const Eigen::Vector3d& b0, const Eigen::Vector3d& b1, const Eigen::Vector3d& b2,
                           double epsilon) noexcept;

}  // namespace facecap
