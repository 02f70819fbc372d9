#include "solver/sparse_ldlt.hpp"

#include <cholmod.h>
#include <fmt/format.h>

#include "core/error.hpp"

namespace facecap {

SparseLdlt::SparseLdlt(const Eigen::SparseMatrix<double>& A) : n_(A.rows()) {
  if (A.rows() != A.cols()) throw Error("SparseLdlt: matrix is not square");
  cholmod_common common;
  cholmod_start(&common);
  common.supernodal = CHOLMOD_SIMPLICIAL;
  common.final_ll = false;
  // Lower triangle, compressed by column, as CHOLMOD wants it.
  Eigen::SparseMatrix<double> lower = A.triangularView<Eigen::Lower>();
  lower.makeCompressed();
  cholmod_sparse view{};
  view.nrow = view.ncol = std::size_t(n_);
  view.nzmax = std::size_t(lower.nonZeros());
  view.p = lower.outerIndexPtr();
  view.i = lower.innerIndexPtr();
  view.x = lower.valuePtr();
  view.stype = -1;  // symmetric, lower triangle stored
  view.itype = CHOLMOD_INT;
  view.xtype = CHOLMOD_REAL;
  view.dtype = CHOLMOD_DOUBLE;
  view.sorted = 1;
  view.packed = 1;
  cholmod_factor* factor = cholmod_analyze(&view, &common);
  const bool factored = factor && cholmod_factorize(&view, factor, &common) &&
                        common.status == CHOLMOD_OK &&
                        cholmod_change_factor(CHOLMOD_REAL, false, false, true, true, factor, &common);
  if (!factored) {
    const auto minor = factor ? factor->minor : 0;
    if (factor) cholmod_free_factor(&factor, &common);
    cholmod_finish(&common);
    throw Error(fmt::format("sparse factorisation failed (status {}, column {}): the system is not positive definite "
                            "(a mesh part without any marker?)", common.status, minor));
  }
  const auto* p = static_cast<const int*>(factor->p);
  const auto* i = static_cast<const int*>(factor->i);
  const auto* x = static_cast<const double*>(factor->x);
  const auto* perm = static_cast<const int*>(factor->Perm);
  perm_.assign(perm, perm + n_);
  col_start_.resize(std::size_t(n_) + 1);
  inv_diagonal_.resize(std::size_t(n_));
  row_.reserve(std::size_t(p[n_]));
  value_.reserve(std::size_t(p[n_]));
  for (Eigen::Index j = 0; j < n_; ++j) {
    col_start_[std::size_t(j)] = int(row_.size());
    inv_diagonal_[std::size_t(j)] = 1.0 / x[p[j]];  // first entry of each column is D_jj
    for (int k = p[j] + 1; k < p[j + 1]; ++k) {
      row_.push_back(i[k]);
      value_.push_back(x[k]);
    }
  }
  col_start_[std::size_t(n_)] = int(row_.size());
  row_start_.assign(std::size_t(n_) + 1, 0);
  for (int r : row_) ++row_start_[std::size_t(r) + 1];
  for (std::size_t r = 0; r < std::size_t(n_); ++r) row_start_[r + 1] += row_start_[r];
  col_.resize(row_.size());
  row_value_.resize(row_.size());
  std::vector<int> fill(row_start_.begin(), row_start_.end() - 1);
  for (Eigen::Index j = 0; j < n_; ++j)
    for (int k = col_start_[std::size_t(j)]; k < col_start_[std::size_t(j) + 1]; ++k) {
      const int at = fill[std::size_t(row_[std::size_t(k)])]++;
      col_[std::size_t(at)] = int(j);
      row_value_[std::size_t(at)] = value_[std::size_t(k)];
    }
  cholmod_free_factor(&factor, &common);
  cholmod_finish(&common);
}

void SparseLdlt::solve_in_place(Eigen::Matrix3Xd& xyz, Eigen::Matrix3Xd& work) const noexcept {
  double* w = work.data();
  const double* b = xyz.data();
  for (Eigen::Index k = 0; k < n_; ++k) {
    const double* src = b + 3 * perm_[std::size_t(k)];
    w[3 * k] = src[0]; w[3 * k + 1] = src[1]; w[3 * k + 2] = src[2];
  }
  const int* rows = row_.data();
  const double* vals = value_.data();
  const int* cols = col_.data();
  const double* row_vals = row_value_.data();
  for (Eigen::Index i = 0; i < n_; ++i) {  // L y = b, row by row
    double s0 = w[3 * i], s1 = w[3 * i + 1], s2 = w[3 * i + 2];
    for (int k = row_start_[std::size_t(i)]; k < row_start_[std::size_t(i) + 1]; ++k) {
      const double* t = w + 3 * cols[k];
      const double l = row_vals[k];
      s0 -= l * t[0]; s1 -= l * t[1]; s2 -= l * t[2];
    }
    w[3 * i] = s0; w[3 * i + 1] = s1; w[3 * i + 2] = s2;
  }
  for (Eigen::Index j = n_ - 1; j >= 0; --j) {  // D z = y, L^T u = z
    const double d = inv_diagonal_[std::size_t(j)];
    double s0 = w[3 * j] * d, s1 = w[3 * j + 1] * d, s2 = w[3 * j + 2] * d;
    for (int k = col_start_[std::size_t(j)]; k < col_start_[std::size_t(j) + 1]; ++k) {
      const double* t = w + 3 * rows[k];
      const double l = vals[k];
      s0 -= l * t[0]; s1 -= l * t[1]; s2 -= l * t[2];
    }
    w[3 * j] = s0; w[3 * j + 1] = s1; w[3 * j + 2] = s2;
  }
  double* out = xyz.data();
  for (Eigen::Index k = 0; k < n_; ++k) {
    double* dst = out + 3 * perm_[std::size_t(k)];
    dst[0] = w[3 * k]; dst[1] = w[3 * k + 1]; dst[2] = w[3 * k + 2];
  }
}

void SparseLdlt::solve_in_place(Eigen::Ref<Eigen::VectorXd> x, Eigen::VectorXd& work) const noexcept {
  double* w = work.data();
  for (Eigen::Index k = 0; k < n_; ++k) w[k] = x[perm_[std::size_t(k)]];
  for (Eigen::Index j = 0; j < n_; ++j) {
    const double y = w[j];
    for (int k = col_start_[std::size_t(j)]; k < col_start_[std::size_t(j) + 1]; ++k) w[row_[std::size_t(k)]] -= value_[std::size_t(k)] * y;
  }
  for (Eigen::Index j = n_ - 1; j >= 0; --j) {
    double s = w[j] * inv_diagonal_[std::size_t(j)];
    for (int k = col_start_[std::size_t(j)]; k < col_start_[std::size_t(j) + 1]; ++k) s -= value_[std::size_t(k)] * w[row_[std::size_t(k)]];
    w[j] = s;
  }
  for (Eigen::Index k = 0; k < n_; ++k) x[perm_[std::size_t(k)]] = w[k];
}

}  // namespace facecap
