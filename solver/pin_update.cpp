#include "solver/pin_update.hpp"

#include <algorithm>
#include <cmath>
#include <type_traits>

namespace facecap {

void PinColumns::set_column(Eigen::Index c, const Eigen::Ref<const Eigen::VectorXd>& column) {
  const double largest = column.cwiseAbs().maxCoeff();
  const double step = largest > 0.0 ? largest / 32767.0 : 1.0;
  scale[std::size_t(c)] = float(step);
  int16_t* q = values.data() + std::size_t(c * rows);
  for (Eigen::Index r = 0; r < rows; ++r)
    q[r] = int16_t(std::clamp(std::lround(column[r] / double(float(step))), -32767L, 32767L));
}

PinUpdate::PinUpdate(Eigen::Index vertex_count, Eigen::Index capacity)
    : vertex_count_(vertex_count), changes_(std::size_t(capacity)) {
  pin_changes_.resize(std::size_t(capacity));
  small_.resize(capacity, capacity);
  small_rhs_.resize(capacity, 3);
  correction_.resize(vertex_count, 3);
}

bool PinUpdate::add(const std::array<int, 3>& vertices, const Eigen::Vector3d& weights, const double* column,
                    double scale, const Eigen::Vector3d& target) noexcept {
  if (count_ == capacity()) return false;
  changes_[std::size_t(count_++)] = {vertices, weights, column, nullptr, 0.0f, scale, target};
  return true;
}

bool PinUpdate::add(int vertex, const int16_t* column, float column_scale, double scale,
                    const Eigen::Vector3d& target) noexcept {
  if (count_ == capacity()) return false;
  changes_[std::size_t(count_++)] = {{vertex, vertex, vertex}, Eigen::Vector3d(1.0, 0.0, 0.0), nullptr, column,
                                     column_scale, scale, target};
  return true;
}

bool PinUpdate::apply(const Eigen::Matrix3Xd& y, Eigen::Matrix3Xd& x) noexcept {
  x = y;
  const Eigen::Index s = count_;
  if (s == 0) return true;
  auto u_dot = [](const Change& u, const Change& z) {
    double sum = 0.0;  // a pin has one vertex (weights 1, 0, 0), a marker up to three
    for (int a = 0; a < 3; ++a)
      if (u.weights[a] != 0.0) sum += u.weights[a] * z.column_at(u.vertices[a]);
    return sum;
  };
  // U^T Z = U^T A0^-1 U is symmetric: its lower triangle, mirrored.
  for (Eigen::Index i = 0; i < s; ++i)
    for (Eigen::Index j = 0; j <= i; ++j)
      small_(i, j) = small_(j, i) = u_dot(changes_[std::size_t(i)], changes_[std::size_t(j)]);
  for (Eigen::Index i = 0; i < s; ++i) {
    const Change& ci = changes_[std::size_t(i)];
    Eigen::Vector3d uy = Eigen::Vector3d::Zero();
    for (int a = 0; a < 3; ++a) uy += ci.weights[a] * y.col(ci.vertices[a]);
    for (Eigen::Index j = 0; j < s; ++j) {
      const Change& cj = changes_[std::size_t(j)];
      uy += small_(i, j) * cj.scale * cj.target;
    }
    small_(i, i) += 1.0 / ci.scale;
    small_rhs_.row(i) = uy.transpose();
  }
  // Gaussian elimination with partial pivoting (the system is symmetric indefinite).
  for (Eigen::Index c = 0; c < s; ++c) {
    Eigen::Index p = c;
    for (Eigen::Index r = c + 1; r < s; ++r)
      if (std::abs(small_(r, c)) > std::abs(small_(p, c))) p = r;
    if (p != c) { small_.row(c).head(s).swap(small_.row(p).head(s)); small_rhs_.row(c).swap(small_rhs_.row(p)); }
    const double d = small_(c, c);
    if (d == 0.0) return false;  // singular: keep the uncorrected solve
    for (Eigen::Index r = c + 1; r < s; ++r) {
      const double f = small_(r, c) / d;
      if (f == 0.0) continue;
      for (Eigen::Index k = c; k < s; ++k) small_(r, k) -= f * small_(c, k);
      small_rhs_.row(r) -= f * small_rhs_.row(c);
    }
  }
  for (Eigen::Index c = s - 1; c >= 0; --c) {
    Eigen::RowVector3d v = small_rhs_.row(c);
    for (Eigen::Index k = c + 1; k < s; ++k) v -= small_(c, k) * small_rhs_.row(k);
    small_rhs_.row(c) = v / small_(c, c);
  }
  for (Eigen::Index i = 0; i < s; ++i) {
    const Change& ci = changes_[std::size_t(i)];
    small_rhs_.row(i) = ci.scale * ci.target.transpose() - small_rhs_.row(i);
  }
  add_columns(x);
  return true;
}

void PinUpdate::add_columns(Eigen::Matrix3Xd& x) noexcept {
  // Summed coordinate by coordinate (contiguous, so vectorised) into sums that stay in
  // L2 while each column streams through once, front to back.
  const Eigen::Index N = vertex_count_, s = count_;
  correction_.setZero();
  double* __restrict sx = correction_.col(0).data();
  double* __restrict sy = correction_.col(1).data();
  double* __restrict sz = correction_.col(2).data();
  // Double columns first (markers, pins solved this frame), then the 16-bit ones.
  std::size_t pins = 0;
  for (Eigen::Index i = 0; i < s; ++i) {
    const double* __restrict z = changes_[std::size_t(i)].column;
    if (!z) {
      pin_changes_[pins++] = i;
      continue;
    }
    const double cx = small_rhs_(i, 0), cy = small_rhs_(i, 1), cz = small_rhs_(i, 2);
    for (Eigen::Index j = 0; j < N; ++j) {
      sx[j] += cx * z[j];
      sy[j] += cy * z[j];
      sz[j] += cz * z[j];
    }
  }
  // Float sums of eight 16-bit columns at a time: one pass over the sums per eight
  // columns (four measured 20% slower, sixteen no faster).
  std::size_t next = 0;
  auto add_pins = [&]<int Count>(std::integral_constant<int, Count>) {
    const int16_t* __restrict z[Count];
    float cx[Count], cy[Count], cz[Count];
    for (int k = 0; k < Count; ++k) {
      const Eigen::Index i = pin_changes_[next + std::size_t(k)];
      const Change& ck = changes_[std::size_t(i)];
      z[k] = ck.pin_column;
      cx[k] = float(ck.column_scale * small_rhs_(i, 0));
      cy[k] = float(ck.column_scale * small_rhs_(i, 1));
      cz[k] = float(ck.column_scale * small_rhs_(i, 2));
    }
    for (Eigen::Index j = 0; j < N; ++j) {
      float x_sum = 0.0f, y_sum = 0.0f, z_sum = 0.0f;
      for (int k = 0; k < Count; ++k) {
        const float zj = float(z[k][j]);
        x_sum += cx[k] * zj;
        y_sum += cy[k] * zj;
        z_sum += cz[k] * zj;
      }
      sx[j] += x_sum;
      sy[j] += y_sum;
      sz[j] += z_sum;
    }
    next += Count;
  };
  while (next + 8 <= pins) add_pins(std::integral_constant<int, 8>{});
  while (next < pins) add_pins(std::integral_constant<int, 1>{});
  x += correction_.transpose();
}

}  // namespace facecap
