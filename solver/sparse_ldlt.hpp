#pragma once
// A sparse symmetric positive definite factorisation A = P^T L D L^T P, computed once by
// CHOLMOD (fill-reducing ordering, simplicial LDL^T) and back-substituted by our own
// loops: three right-hand sides (x, y, z) interleaved per vertex, no allocation, so the
// per-frame solve is real-time safe.
#include <cstdint>
#include <memory>
#include <vector>

#include <Eigen/Core>
#include <Eigen/SparseCore>

#include "core/huge_pages.hpp"
#include "solver/kernels/kernels.hpp"

namespace facecap {

class SparseLdlt {
 public:
  // Factors A (symmetric; both triangles or the lower one given); the three-column solve
  // runs the kernels of `kernels`. Throws Error if A is not positive definite. Not
  // real-time.
  SparseLdlt(const Eigen::SparseMatrix<double>& A, const kernels::KernelTable& kernels);

  Eigen::Index size() const { return n_; }
  Eigen::Index factor_nonzeros() const { return Eigen::Index(value_.size()); }

  // x = A^-1 b for the 3 x N interleaved right-hand sides, in place; work is 4 x N
  // scratch owned by the caller (so one factor serves several solvers). Real-time safe.
  void solve_in_place(Eigen::Matrix3Xd& xyz, Eigen::Matrix4Xd& work) const noexcept;
  // x = A^-1 b for one right-hand side, in place; work has N entries. Real-time safe.
  void solve_in_place(Eigen::Ref<Eigen::VectorXd> x, Eigen::VectorXd& work) const noexcept;
  // x = A^-1 e_i, a column of the inverse: the forward substitution starts where e_i's
  // one is and skips the zeros below it (a pin's column; much cheaper than a general
  // solve). x and work have N entries. Real-time safe.
  void solve_unit(Eigen::Index i, Eigen::Ref<Eigen::VectorXd> x, Eigen::VectorXd& work) const noexcept;

 private:
  Eigen::Index n_ = 0;
  std::vector<int> perm_;            // factor row i is A's row perm_[i]
  std::vector<int> inverse_perm_;    // A's row r is factor row inverse_perm_[r]
  // Strictly-lower entries of the unit L, by column. Their rows are 16-bit when N allows
  // (short_rows_: a sixth fewer bytes streamed per solve), otherwise 32-bit.
  bool short_rows_ = true;
  HugePageVector<int> col_start_;
  HugePageVector<uint16_t> row16_;
  HugePageVector<int> row32_;
  HugePageVector<double> value_;
  std::vector<double> inv_diagonal_; // 1 / D
  const kernels::KernelTable& kernels_;
  kernels::LdltView view_;
};

}  // namespace facecap
