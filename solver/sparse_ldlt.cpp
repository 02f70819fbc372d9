#include "solver/sparse_ldlt.hpp"

#include <cholmod.h>
#include <fmt/format.h>

#include "core/error.hpp"

namespace facecap {

SparseLdlt::SparseLdlt(const Eigen::SparseMatrix<double>& A, const kernels::KernelTable& kernels)
    : n_(A.rows()), kernels_(kernels) {
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
  inverse_perm_.resize(std::size_t(n_));
  for (Eigen::Index k = 0; k < n_; ++k) inverse_perm_[std::size_t(perm_[std::size_t(k)])] = int(k);
  col_start_.resize(std::size_t(n_) + 1);
  inv_diagonal_.resize(std::size_t(n_));
  short_rows_ = n_ <= 65536;
  value_.reserve(std::size_t(p[n_]));
  for (Eigen::Index j = 0; j < n_; ++j) {
    col_start_[std::size_t(j)] = int(value_.size());
    inv_diagonal_[std::size_t(j)] = 1.0 / x[p[j]];  // first entry of each column is D_jj
    for (int k = p[j] + 1; k < p[j + 1]; ++k) {
      if (short_rows_) row16_.push_back(uint16_t(i[k]));
      else row32_.push_back(i[k]);
      value_.push_back(x[k]);
    }
  }
  col_start_[std::size_t(n_)] = int(value_.size());
  cholmod_free_factor(&factor, &common);
  cholmod_finish(&common);
  view_ = {n_, perm_.data(), col_start_.data(), short_rows_ ? row16_.data() : nullptr, short_rows_ ? nullptr : row32_.data(),
           value_.data(), inv_diagonal_.data()};
}

namespace {

// From factor row `first` on (rows before it are zero in P x), a column whose entry is
// still zero is skipped: a unit right-hand side touches only its elimination-tree path.
template <class Row>
void solve_one(Eigen::Index n, const int* perm, const int* col_start, const Row* rows, const double* vals,
               const double* inv_diagonal, Eigen::Ref<Eigen::VectorXd> x, Eigen::VectorXd& work,
               Eigen::Index first = 0) noexcept {
  double* w = work.data();
  for (Eigen::Index k = 0; k < n; ++k) w[k] = x[perm[k]];
  for (Eigen::Index j = first; j < n; ++j) {
    const double y = w[j];
    if (y == 0.0) continue;
    for (int k = col_start[j]; k < col_start[j + 1]; ++k) w[rows[k]] -= vals[k] * y;
  }
  for (Eigen::Index j = n - 1; j >= 0; --j) {
    double s = w[j] * inv_diagonal[j];
    for (int k = col_start[j]; k < col_start[j + 1]; ++k) s -= vals[k] * w[rows[k]];
    w[j] = s;
  }
  for (Eigen::Index k = 0; k < n; ++k) x[perm[k]] = w[k];
}

}  // namespace

void SparseLdlt::solve_in_place(Eigen::Matrix3Xd& xyz, Eigen::Matrix4Xd& work) const noexcept {
  kernels_.ldlt_solve(view_, xyz.data(), work.data());
}

void SparseLdlt::solve_in_place(Eigen::Ref<Eigen::VectorXd> x, Eigen::VectorXd& work) const noexcept {
  if (short_rows_)
    solve_one(n_, perm_.data(), col_start_.data(), row16_.data(), value_.data(), inv_diagonal_.data(), x, work);
  else
    solve_one(n_, perm_.data(), col_start_.data(), row32_.data(), value_.data(), inv_diagonal_.data(), x, work);
}

void SparseLdlt::solve_unit(Eigen::Index i, Eigen::Ref<Eigen::VectorXd> x, Eigen::VectorXd& work) const noexcept {
  x.setZero();
  x[i] = 1.0;
  const Eigen::Index first = inverse_perm_[std::size_t(i)];
  if (short_rows_)
    solve_one(n_, perm_.data(), col_start_.data(), row16_.data(), value_.data(), inv_diagonal_.data(), x, work, first);
  else
    solve_one(n_, perm_.data(), col_start_.data(), row32_.data(), value_.data(), inv_diagonal_.data(), x, work, first);
}

}  // namespace facecap
