#pragma once
// Exact solver for small bound-constrained convex quadratic programs
//   min_w 1/2 w^T H w - g^T w   subject to  lower <= w <= upper
// by a primal active-set method, warm-started from the previous solution (the
// weights of Eq. 2, M up to a few hundred). Workspace is allocated once; solve() is
// real-time safe.
#include <Eigen/Core>

namespace facecap {

class BoxQpSolver {
 public:
  // Allocates workspace (not real-time). max_iterations bounds each solve's iterations
  // (both phases together); 0 gives 10 size + 10, far more than the few it takes.
  explicit BoxQpSolver(Eigen::Index size, int max_iterations = 0);

  struct Result {
    int iterations = 0;
    bool converged = false;  // false: stopped at max_iterations (or a singular subproblem), w feasible
  };

  // H: n x n symmetric positive definite; g: n. w: warm start in (clamped to the box
  // first), solution out. Real-time safe: no allocation.
  Result solve(const Eigen::MatrixXd& H, const Eigen::VectorXd& g, double lower, double upper,
               Eigen::VectorXd& w) noexcept;

  Eigen::Index size() const { return n_; }

 private:
  bool solve_free_subproblem(const Eigen::MatrixXd& H, const Eigen::VectorXd& g, const Eigen::VectorXd& w) noexcept;

  Eigen::Index n_;
  int max_iterations_;
  Eigen::VectorXi state_;      // 0 free, -1 at lower, +1 at upper
  Eigen::VectorXi free_;       // indices of free variables
  Eigen::Index free_count_ = 0;
  Eigen::MatrixXd chol_;       // lower Cholesky factor of H on the free set (column-major, leading f x f)
  Eigen::VectorXd rhs_;        // free-set right-hand side, then solution
  Eigen::VectorXd candidate_;  // full-size candidate point
  Eigen::VectorXd gradient_;
  Eigen::VectorXd bound_product_;  // H w with the free entries of w zeroed
};

}  // namespace facecap
