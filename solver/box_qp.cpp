#include "solver/box_qp.hpp"

#include <cmath>

namespace facecap {

BoxQpSolver::BoxQpSolver(Eigen::Index size, int max_iterations)
    : n_(size), max_iterations_(max_iterations > 0 ? max_iterations : int(10 * size + 10)), state_(size), free_(size),
      chol_(size, size), rhs_(size), candidate_(size), gradient_(size), bound_product_(size) {}

// Solves H_FF w_F = g_F - H_FA w_A for the free set into candidate_. False if H_FF is
// not positive definite (cannot happen for the ridge-regularised weights problem).
bool BoxQpSolver::solve_free_subproblem(const Eigen::MatrixXd& H, const Eigen::VectorXd& g,
                                        const Eigen::VectorXd& w) noexcept {
  free_count_ = 0;
  for (Eigen::Index i = 0; i < n_; ++i)
    if (state_[i] == 0) free_[free_count_++] = int(i);
  candidate_ = w;
  const Eigen::Index f = free_count_;
  if (f == 0) return true;
  // H_FA w_A as one product: w with its free entries zeroed.
  for (Eigen::Index a = 0; a < f; ++a) candidate_[free_[a]] = 0.0;
  bound_product_.noalias() = H * candidate_;
  for (Eigen::Index a = 0; a < f; ++a) {
    const Eigen::Index i = free_[a];
    rhs_[a] = g[i] - bound_product_[i];
    for (Eigen::Index b = a; b < f; ++b) chol_(b, a) = H(free_[b], i);
  }
  // In-place Cholesky, right-looking: each column, once final, updates the columns after
  // it by contiguous (vectorised) column updates; then forward and back substitution.
  const Eigen::Index stride = chol_.outerStride();
  double* L = chol_.data();
  for (Eigen::Index j = 0; j < f; ++j) {
    double* __restrict column = L + j * stride;
    if (!(column[j] > 0.0)) return false;
    const double d = std::sqrt(column[j]);
    column[j] = d;
    for (Eigen::Index i = j + 1; i < f; ++i) column[i] /= d;
    for (Eigen::Index k = j + 1; k < f; ++k) {
      double* __restrict target = L + k * stride;
      const double l = column[k];
      for (Eigen::Index i = k; i < f; ++i) target[i] -= l * column[i];
    }
  }
  double* __restrict x = rhs_.data();
  for (Eigen::Index j = 0; j < f; ++j) {
    const double* __restrict column = L + j * stride;
    const double xj = x[j] / column[j];
    x[j] = xj;
    for (Eigen::Index i = j + 1; i < f; ++i) x[i] -= column[i] * xj;
  }
  for (Eigen::Index j = f - 1; j >= 0; --j) {
    const double* __restrict column = L + j * stride;
    double s = x[j];
    for (Eigen::Index i = j + 1; i < f; ++i) s -= column[i] * x[i];
    x[j] = s / column[j];
  }
  for (Eigen::Index a = 0; a < f; ++a) candidate_[free_[a]] = rhs_[a];
  return true;
}

BoxQpSolver::Result BoxQpSolver::solve(const Eigen::MatrixXd& H, const Eigen::VectorXd& g, double lower,
                                       double upper, Eigen::VectorXd& w) noexcept {
  Result result;
  constexpr double kBoundTolerance = 1e-12;
  for (Eigen::Index i = 0; i < n_; ++i) w[i] = std::fmin(std::fmax(w[i], lower), upper);
  // Phase 1, primal-dual active set (Hintermueller, Ito, Kunisch): moves many bounds per
  // iteration and usually ends in two or three. Its answer is accepted only if it meets
  // the KKT conditions; otherwise phase 2 (primal active set, finite) finishes from it.
  constexpr int kPrimalDualIterations = 8;
  gradient_.noalias() = H * w;
  gradient_ -= g;
  for (int it = 0; it < kPrimalDualIterations && result.iterations < max_iterations_; ++it) {
    bool changed = false;
    for (Eigen::Index i = 0; i < n_; ++i) {
      const double trial = w[i] - gradient_[i] / H(i, i);
      const int state = trial <= lower ? -1 : (trial >= upper ? 1 : 0);
      changed |= state != state_[i] || it == 0;
      state_[i] = state;
      if (state < 0) w[i] = lower;
      if (state > 0) w[i] = upper;
    }
    if (!changed) break;
    ++result.iterations;
    if (!solve_free_subproblem(H, g, w)) break;
    w = candidate_;
    gradient_.noalias() = H * w;
    gradient_ -= g;
  }
  bool optimal = true;
  for (Eigen::Index i = 0; i < n_ && optimal; ++i) {
    if (w[i] < lower - kBoundTolerance || w[i] > upper + kBoundTolerance) optimal = false;
    else if (state_[i] < 0) optimal = gradient_[i] >= -1e-12;
    else if (state_[i] > 0) optimal = gradient_[i] <= 1e-12;
  }
  if (optimal) {
    result.converged = true;
    return result;
  }
  for (Eigen::Index i = 0; i < n_; ++i) {
    w[i] = std::fmin(std::fmax(w[i], lower), upper);
    state_[i] = w[i] <= lower ? -1 : (w[i] >= upper ? 1 : 0);
  }
  while (result.iterations < max_iterations_) {
    ++result.iterations;
    if (!solve_free_subproblem(H, g, w)) return result;
    // Step from the feasible w towards the candidate, stopping at the first bound hit.
    double step = 1.0;
    Eigen::Index blocking = -1;
    for (Eigen::Index a = 0; a < free_count_; ++a) {
      const Eigen::Index i = free_[a];
      const double target = candidate_[i], from = w[i];
      if (target < lower - kBoundTolerance) {
        const double t = (from - lower) / (from - target);
        if (t < step) { step = t; blocking = i; }
      } else if (target > upper + kBoundTolerance) {
        const double t = (upper - from) / (target - from);
        if (t < step) { step = t; blocking = i; }
      }
    }
    if (blocking >= 0) {
      for (Eigen::Index a = 0; a < free_count_; ++a) {
        const Eigen::Index i = free_[a];
        w[i] += step * (candidate_[i] - w[i]);
      }
      w[blocking] = candidate_[blocking] < lower ? lower : upper;
      state_[blocking] = candidate_[blocking] < lower ? -1 : 1;
      continue;
    }
    for (Eigen::Index a = 0; a < free_count_; ++a) {
      const Eigen::Index i = free_[a];
      w[i] = std::fmin(std::fmax(candidate_[i], lower), upper);
    }
    // Optimal on this face: check the multipliers of the bound variables.
    gradient_.noalias() = H * w;
    gradient_ -= g;
    Eigen::Index worst = -1;
    double worst_violation = 1e-12;
    for (Eigen::Index i = 0; i < n_; ++i) {
      const double violation = state_[i] < 0 ? -gradient_[i] : (state_[i] > 0 ? gradient_[i] : 0.0);
      if (violation > worst_violation) { worst_violation = violation; worst = i; }
    }
    if (worst < 0) {
      result.converged = true;
      return result;
    }
    state_[worst] = 0;
  }
  return result;
}

}  // namespace facecap
