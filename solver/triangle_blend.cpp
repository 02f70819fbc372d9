#include "solver/triangle_blend.hpp"

#include <algorithm>
#include <cmath>

#include "solver/blend_terms.hpp"
#include "solver/solver_model.hpp"

namespace facecap {

TriangleBlend::TriangleBlend(const SolverModel& model, Kind kind) : model_(model), kind_(kind) {
  const SolverModel& m = model_;
  const Eigen::Index T = m.rig.triangle_count(), N = m.vertex_count();
  constexpr std::size_t B = ShapeBlocks::kBlock;
  static_assert(kOperatorComponents == kernels::kOperatorComponents && B == kernels::kBlockSlots);
  operator_.assign(std::size_t(m.blend.triangle_blocks.block_count()) * kOperatorComponents * B, 0.0f);
  slot_corners_.assign(m.blend.triangle_blocks.element_of_slot.size(), {-1, -1, -1});
  // G^T W G x0, the right-hand side of T = I everywhere.
  identity_rhs_.setZero(3, N);
  for (Eigen::Index t = 0; t < T; ++t) {
    const Eigen::Map<const Eigen::Matrix3d> Q(m.blend.triangle_operator.col(t).data());
    const auto corners = m.rig.triangles.col(t);
    for (int k = 0; k < 3; ++k) identity_rhs_.col(corners[k]) += Q.col(k);
    // The rest frame's t1, t2 and half the rest corners' coordinates in it, (0, 0),
    // (L, 0) and (u, v): Q_j = t1 q1^T + t2 q2^T with q1 = (-v, v, 0) / 2 and
    // q2 = (u - L, -u, L) / 2 (area times the hat functions' gradients).
    const Eigen::Map<const Eigen::Matrix3d> frame(m.blend.triangle_frames.col(t).data());
    const Eigen::Vector3d edge = m.rig.neutral.col(corners[1]) - m.rig.neutral.col(corners[0]);
    const Eigen::Vector3d other = m.rig.neutral.col(corners[2]) - m.rig.neutral.col(corners[0]);
    const double values[kOperatorComponents] = {frame(0, 0), frame(1, 0), frame(2, 0), frame(0, 1), frame(1, 1), frame(2, 1),
                                                0.5 * edge.dot(frame.col(0)), 0.5 * other.dot(frame.col(0)),
                                                0.5 * other.dot(frame.col(1))};
    const auto slot = std::size_t(m.blend.triangle_blocks.slot_of_element[std::size_t(t)]);
    for (int c = 0; c < kOperatorComponents; ++c)
      operator_[(slot / B * kOperatorComponents + std::size_t(c)) * B + slot % B] = float(values[c]);
    slot_corners_[slot] = {corners[0], corners[1], corners[2]};
  }
  const BlendTerms& terms = kind_ == Kind::kNonlinear ? m.blend.triangle_nonlinear : m.blend.triangle_gradient;
  static_assert(sizeof(slot_corners_[0]) == 3 * sizeof(int32_t));
  view_ = {terms.view(), m.blend.triangle_blocks.block_count(), kind_ == Kind::kNonlinear, operator_.data(),
           reinterpret_cast<const int32_t(*)[3]>(slot_corners_.data())};
  streamed_ = {std::as_bytes(std::span(terms.values)), std::as_bytes(std::span(terms.scales)),
               std::as_bytes(std::span(terms.offsets)), std::as_bytes(std::span(operator_))};
}

// Block by block (the kernels' triangle_rhs): sums the active shapes' terms in vector
// registers, turns each sum into T_j - I (Eq. 4 for nonlinear, sum w_i (F_ij - I) for
// dt), multiplies by Q_j and adds that to rhs, which starts as the T = I right-hand side.
// The terms are read once, front to back: memory bandwidth is what bounds the stage.
void TriangleBlend::right_hand_side(const float* weights, Eigen::Matrix3Xd& rhs) const noexcept {
  rhs = identity_rhs_;
  model_.kernels->triangle_rhs(view_, weights, rhs.data());
}

}  // namespace facecap
