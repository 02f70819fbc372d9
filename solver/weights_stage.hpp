#pragma once
// Eq. 2, the weights, for the per-frame solvers:
//
//   w = argmin_{0<=w<=1} |B~ w - (m - x0~)|^2 + alpha |w - w_prev|^2 + mu |w|^2
//
// on the rows of the present markers (B~: 3K x M, WeightsData), then, for the nonlinear
// solver, Gauss-Newton refinements along the marker paths Eq. 4's rotations move them
// (docs/solver.md, "Weights along the blend's paths"). Warm-started from the last frame.
// Lifecycle: construct (allocates) -> solve() per frame (real-time safe).
#include <cstdint>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "solver/box_qp.hpp"

namespace facecap {

class SolverModel;

class WeightsStage {
 public:
  // Fewer usable markers cannot pin position and orientation: the frame is held.
  static constexpr uint32_t kMinimumMarkers = 3;

  // follow_paths: refine along the marker paths of the nonlinear blend
  // (params.weight_refinements). Keeps a reference to model. Allocates; not real-time.
  WeightsStage(const SolverModel& model, bool follow_paths);

  struct Result {
    uint32_t markers_used = 0;
    bool iteration_cap = false;  // a box QP stopped at params.weight_qp_iteration_cap
  };

  // weights (M) for marker targets (3 x K) and present flags (K; NaN targets count as
  // missing). Real-time safe.
  Result solve(const Eigen::Matrix3Xd& targets, std::span<const uint8_t> present, Eigen::VectorXd& weights) noexcept;

  // Forgets the warm start. Real-time safe.
  void reset() noexcept;

  // The warm start carried from frame to frame: the last weights (Eq. 2's w_prev) and the
  // last Eq. 2 solution before refinement (where the next QP starts).
  struct State {
    Eigen::VectorXd previous, previous_linear;  // M
  };
  State make_state() const { return {previous_, previous_linear_}; }
  // Copies the warm start into `state`; false (nothing copied) when it was not sized for
  // this stage. Real-time safe.
  bool save(State& state) const noexcept;
  // Continues from `state`; false (nothing changed) when its shape count is not this
  // stage's. Real-time safe.
  bool restore(const State& state) noexcept;

  // Whether at least kMinimumMarkers markers are present and finite. Real-time safe.
  bool usable(std::span<const uint8_t> present, const Eigen::Matrix3Xd& targets) const noexcept;

 private:
  // One Gauss-Newton step from w; returns whether its QP converged. Real-time safe.
  bool refine(const Eigen::Matrix3Xd& targets, Eigen::VectorXd& w) noexcept;

  const SolverModel& model_;
  int refinements_;
  BoxQpSolver qp_;
  Eigen::MatrixXd H_, gram_present_;
  Eigen::MatrixXd cross_;                 // M x turning shapes: B~^T D's nonzero columns
  std::vector<int> turning_shapes_;       // shapes with marker paths
  std::vector<int> turning_of_shape_;     // per shape: index into turning_shapes_ or -1
  std::vector<double> path_turn_, path_cos_, path_sin_;  // per marker path: w_shape * angle, its cos and sin
  Eigen::VectorXd g_, previous_;
  Eigen::VectorXd previous_linear_;  // the last Eq. 2 solution before refinement
  Eigen::VectorXd residual_;
  Eigen::Matrix3Xd path_difference_;
  std::vector<int> path_start_, path_of_marker_;  // marker paths grouped by marker (CSR)
  Eigen::Array<bool, Eigen::Dynamic, 1> present_;
};

}  // namespace facecap
