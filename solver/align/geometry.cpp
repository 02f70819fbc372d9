#include "solver/align/geometry.hpp"

#include <algorithm>
#include <cmath>

#include <Eigen/Eigenvalues>
#include <Eigen/SVD>

namespace facecap::align {

Eigen::Matrix3Xd Similarity::apply(const Eigen::Matrix3Xd& points) const {
  Eigen::Matrix3Xd out = (scale * rotation) * points;
  out.colwise() += translation;
  return out;
}

Similarity Similarity::inverse() const noexcept {
  Similarity inv;
  inv.rotation = rotation.transpose();
  inv.scale = 1.0 / scale;
  inv.translation = -inv.scale * (inv.rotation * translation);
  return inv;
}

Similarity Similarity::operator*(const Similarity& other) const noexcept {
  Similarity c;
  c.rotation = rotation * other.rotation;
  c.scale = scale * other.scale;
  c.translation = scale * (rotation * other.translation) + translation;
  return c;
}

bool fit_similarity(const Eigen::Matrix3Xd& src, const Eigen::Matrix3Xd& dst, std::span<const double> weights,
                    bool with_scale, Similarity& out) noexcept {
  const Eigen::Index K = src.cols();
  if (dst.cols() != K || (!weights.empty() && Eigen::Index(weights.size()) != K)) return false;
  double total = 0.0;
  int used = 0;
  Eigen::Vector3d mean_src = Eigen::Vector3d::Zero(), mean_dst = Eigen::Vector3d::Zero();
  for (Eigen::Index k = 0; k < K; ++k) {
    const double w = weights.empty() ? 1.0 : weights[std::size_t(k)];
    if (!(w > 0.0)) continue;
    total += w;
    ++used;
    mean_src += w * src.col(k);
    mean_dst += w * dst.col(k);
  }
  if (used < 3 || !(total > 0.0)) return false;
  mean_src /= total;
  mean_dst /= total;
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  double var_src = 0.0;
  for (Eigen::Index k = 0; k < K; ++k) {
    const double w = weights.empty() ? 1.0 : weights[std::size_t(k)];
    if (!(w > 0.0)) continue;
    const Eigen::Vector3d a = src.col(k) - mean_src, b = dst.col(k) - mean_dst;
    cov.noalias() += w * b * a.transpose();
    var_src += w * a.squaredNorm();
  }
  cov /= total;
  var_src /= total;
  if (!(var_src > 0.0) || !cov.allFinite()) return false;
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(cov, Eigen::ComputeFullU | Eigen::ComputeFullV);
  const Eigen::Vector3d sv = svd.singularValues();
  // Collinear points leave the rotation about their line undetermined.
  if (!(sv[1] > 1e-12 * std::max(sv[0], 1e-300))) return false;
  Eigen::Vector3d d(1.0, 1.0, 1.0);
  if ((svd.matrixU() * svd.matrixV().transpose()).determinant() < 0.0) d[2] = -1.0;
  out.rotation = svd.matrixU() * d.asDiagonal() * svd.matrixV().transpose();
  out.scale = with_scale ? sv.dot(d) / var_src : 1.0;
  out.translation = mean_dst - out.scale * (out.rotation * mean_src);
  return std::isfinite(out.scale) && out.scale > 0.0;
}

const std::array<Eigen::Matrix3d, 24>& axis_rotations() {
  static const std::array<Eigen::Matrix3d, 24> rotations = [] {
    std::array<Eigen::Matrix3d, 24> r;
    std::size_t n = 0;
    std::array<int, 3> perm = {0, 1, 2};
    do {
      for (int signs = 0; signs < 8; ++signs) {
        Eigen::Matrix3d m = Eigen::Matrix3d::Zero();
        for (int row = 0; row < 3; ++row) m(row, perm[std::size_t(row)]) = (signs >> row & 1) ? -1.0 : 1.0;
        if (m.determinant() > 0.0) r[n++] = m;
      }
    } while (std::next_permutation(perm.begin(), perm.end()));
    return r;
  }();
  return rotations;
}

Eigen::Matrix3d principal_axes(const Eigen::Matrix3Xd& points) {
  const Eigen::Vector3d mean = points.rowwise().mean();
  const Eigen::Matrix3Xd centred = points.colwise() - mean;
  const Eigen::Matrix3d cov = centred * centred.transpose();
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov);
  Eigen::Matrix3d axes;
  for (int i = 0; i < 3; ++i) axes.col(i) = eig.eigenvectors().col(2 - i);  // descending variance
  if (axes.determinant() < 0.0) axes.col(2) = -axes.col(2);
  return axes;
}

double rotation_angle(const Eigen::Matrix3d& R) noexcept {
  return std::acos(std::clamp((R.trace() - 1.0) * 0.5, -1.0, 1.0));
}

}  // namespace facecap::align
