#pragma once
// MeshIK baseline (Sumner, Zwicker, Gotsman, Popovic 2005): weights and vertices
// optimised together on the energy the nonlinear solver minimises over x alone,
//
//   E(x, w) = sum_j area_j |(X_j grad_j^T - T_j(w)) P_j|_F^2 + beta sum_k |c_k x - b_k|^2
//             + beta sum_v h_v |x_v - (x0 + B w)_v|^2,
//   T_j(w)  = exp(sum_i w_i log R_ij) (I + sum_i w_i (S_ij - I))            (Eq. 4)
//
// where X_j grad_j^T is triangle j's deformation gradient from the vertices, P_j projects
// onto the rest triangle's plane (the only part of T_j that Eq. 5's right-hand side
// sees; the part along the normal does not depend on x and would keep a shape from
// being a minimum of its own markers), c_k x is marker k's surface point and v runs over
// CollisionData::held_vertices, weights h_v (the tangles and the outer boundary, held to
// the linear blend as in the real-time solvers).
//
// By variable projection: for fixed w,
// x(w) = A^-1 (G^T W T(w) + beta C^T b + beta H^T D H (x0 + B w)), H selecting the
// held vertices and D their weights h_v, with the model's factor (missing markers by the same low-rank correction the real-time solvers
// use), and Levenberg-damped Gauss-Newton on w over the box 0 <= w <= 1, starting from
// the Eq. 2 weights. The Jacobian column of shape i needs d T_j / d w_i on the triangles
// shape i touches (the rotation exponential by central differences) and one
// back-substitution. An offline baseline: solve() is not real-time safe (it allocates a
// little per frame and takes M back-substitutions per iteration).
#include <memory>

#include "solver/face_solver.hpp"

namespace facecap {

struct MeshIkOptions {
  int max_iterations = 10;           // Gauss-Newton steps per frame
  double relative_tolerance = 1e-6;  // stop when a step lowers E by less than this fraction
  double difference_step = 1e-5;     // central-difference step (in weight) for d exp / d w
};

// What the last solve() did: for tests and for the bench's notes.
struct MeshIkReport {
  int iterations = 0;           // accepted Gauss-Newton steps
  int energy_evaluations = 0;   // x(w) solves, trial steps included
  double initial_energy = 0.0;  // E(x(w0), w0) at the Eq. 2 weights
  double final_energy = 0.0;
};

class MeshIkSolver final : public FaceSolver {
 public:
  // Allocates every workspace (Jacobian: (6 T + 3 K) x M doubles). Not real-time.
  MeshIkSolver(std::shared_ptr<const SolverModel> model, const MeshIkOptions& options);
  ~MeshIkSolver() override;

  std::string_view name() const noexcept override { return "meshik"; }
  // Offline: noexcept, but allocates (the small Woodbury system and Eigen's product
  // blocking) and may take tens of milliseconds.
  void solve(const Eigen::Matrix3Xd& targets, std::span<const uint8_t> present, SolveResult& out) noexcept override;
  // x(w) for the given weights: the nonlinear solver's mesh, without collisions.
  void solve_with_weights(const Eigen::VectorXd& weights, const Eigen::Matrix3Xd& targets,
                          std::span<const uint8_t> present, SolveResult& out) noexcept override;
  void reset() noexcept override;
  // Eq. 2's warm start, which starts Gauss-Newton.
  FaceSolver::State make_state() const override;
  bool save_state(FaceSolver::State& state) const noexcept override;
  bool restore_state(const FaceSolver::State& state) noexcept override;

  const MeshIkReport& last_report() const noexcept;

  // E(x(w), w) for weights (M), targets (3 x K) and present flags (K). Not real-time.
  double energy(const Eigen::VectorXd& weights, const Eigen::Matrix3Xd& targets, std::span<const uint8_t> present);

 private:
  struct State;
  std::unique_ptr<State> state_;
};

std::unique_ptr<FaceSolver> make_meshik_solver(std::shared_ptr<const SolverModel> model);
std::unique_ptr<FaceSolver> make_meshik_solver(std::shared_ptr<const SolverModel> model, const MeshIkOptions& options);

}  // namespace facecap
