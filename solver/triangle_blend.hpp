#pragma once
// Eq. 3-4 on the right-hand side of Eq. 5: G^T W T(w) for the blended per-triangle
// transforms, T_j(w) = exp(sum_i w_i log R_ij) (I + sum_i w_i (S_ij - I)) for the
// nonlinear solver, I + sum_i w_i (F_ij - I) for deformation transfer. Only T_j Q_j
// reaches the right-hand side (Q_j = area_j [grad phi_1, grad phi_2, grad phi_3], 3 x 3,
// BlendData); it is built block by block from the terms of the active shapes.
// Lifecycle: construct (allocates) -> right_hand_side() per frame (real-time safe).
#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "solver/kernels/kernels.hpp"

namespace facecap {

class SolverModel;

class TriangleBlend {
 public:
  enum class Kind { kNonlinear, kDeformationTransfer };

  // Lays out the rest frames and Q_j per block of BlendData::triangle_blocks. Keeps a
  // reference to model. Allocates; not real-time.
  TriangleBlend(const SolverModel& model, Kind kind);
  TriangleBlend(const TriangleBlend&) = delete;  // streamed_memory() points into it
  TriangleBlend& operator=(const TriangleBlend&) = delete;

  Kind kind() const noexcept { return kind_; }

  // rhs (3 x N) = G^T W T(w), with weights per shape as active_weights() gives them (0:
  // skipped). The terms are read once, front to back: memory bandwidth bounds this.
  // Real-time safe.
  void right_hand_side(const float* weights, Eigen::Matrix3Xd& rhs) const noexcept;

  // The blend's terms and the per-block operators, in the order a frame reads them
  // (FaceSolver::streamed_memory). Valid while this lives.
  std::span<const std::span<const std::byte>> streamed_memory() const noexcept { return streamed_; }

 private:
  static constexpr int kOperatorComponents = 9;

  const SolverModel& model_;
  Kind kind_;
  // Per slot of triangle_blocks, component-major per block: the rest frame's t1 and t2 and
  // (L, u, v) / 2, from which Q_j = t1 q1^T + t2 q2^T (see the constructor).
  std::vector<float> operator_;
  std::vector<std::array<int32_t, 3>> slot_corners_;  // per slot of triangle_blocks: its vertices, -1 for padding
  Eigen::Matrix3Xd identity_rhs_;                     // G^T W G x0: the right-hand side of T = I everywhere
  std::vector<std::span<const std::byte>> streamed_;
  kernels::TriangleBlendView view_;
};

}  // namespace facecap
