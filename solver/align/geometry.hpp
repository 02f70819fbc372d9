#pragma once
// Rigid and similarity transforms and their least-squares fits (Kabsch / Umeyama), the
// building blocks of calibration (paper Algorithm 1) and head stabilisation.
#include <array>
#include <span>

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace facecap::align {

// y = scale * rotation * x + translation. With scale 1 it is a rigid transform.
struct Similarity {
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();
  double scale = 1.0;
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();

  Eigen::Vector3d apply(const Eigen::Vector3d& x) const noexcept { return scale * (rotation * x) + translation; }
  // Columns mapped one by one. points: 3 x K.
  Eigen::Matrix3Xd apply(const Eigen::Matrix3Xd& points) const;
  // Maps a displacement (no translation).
  Eigen::Vector3d apply_vector(const Eigen::Vector3d& v) const noexcept { return scale * (rotation * v); }
  Similarity inverse() const noexcept;
  // (this * other)(x) = this(other(x)).
  Similarity operator*(const Similarity& other) const noexcept;
};

// Least-squares similarity (or rigid, with_scale = false) taking src to dst:
// argmin sum_k w_k |s R src_k + t - dst_k|^2 (Umeyama 1991), R a proper rotation.
// src, dst: 3 x K; weights: K or empty (all 1). Columns with weight 0 are ignored.
// Returns false (out untouched) with fewer than 3 weighted points or a degenerate
// (collinear) set. Real-time safe: fixed-size 3x3 SVD, no allocation.
bool fit_similarity(const Eigen::Matrix3Xd& src, const Eigen::Matrix3Xd& dst, std::span<const double> weights,
                    bool with_scale, Similarity& out) noexcept;

// The 24 proper rotations that map coordinate axes onto coordinate axes (axis
// permutations with sign flips, determinant +1): the starts that cover Y-up versus
// Z-up and any heading in steps of 90 degrees.
const std::array<Eigen::Matrix3d, 24>& axis_rotations();

// Principal axes of points (columns of the result, largest variance first), made a
// proper rotation (determinant +1). points: 3 x K.
Eigen::Matrix3d principal_axes(const Eigen::Matrix3Xd& points);

// Angle of a rotation matrix, radians in [0, pi].
double rotation_angle(const Eigen::Matrix3d& R) noexcept;

}  // namespace facecap::align
