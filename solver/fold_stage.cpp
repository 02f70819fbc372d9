#include "solver/fold_stage.hpp"

#include <algorithm>

#include "solver/blend_terms.hpp"
#include "solver/solver_model.hpp"

namespace facecap {

FoldStage::FoldStage(const SolverModel& model)
    : model_(model), blend_(*model.kernels, model.blend.vertex_blocks, model.blend.vertex_deltas, model.rig.neutral) {
  const SolverModel& m = model_;
  detector_.configure(m.rig.triangles, triangle_regions(m.rig), m.params.fold_crease_degrees, fold_tolerance(m.rig), m.kernels);
  reference_.resize(3, m.vertex_count());
  pin_capacity_ = std::min<Eigen::Index>(m.vertex_count(), m.params.fold_max_pins);
  pin_columns_.resize(m.vertex_count(), pin_capacity_);
  column_vertex_.assign(std::size_t(pin_capacity_), -1);
  vertex_column_.assign(std::size_t(m.vertex_count()), -1);
  column_used_frame_.assign(std::size_t(pin_capacity_), 0);
  pin_work_.resize(m.vertex_count());
  pin_stamp_.assign(std::size_t(m.vertex_count()), 0);
  fold_vertex_stamp_.assign(std::size_t(m.vertex_count()), 0);
}

const FoldReport& FoldStage::mark_fold_vertices() noexcept {
  if (++measure_stamp_ == 0) {  // wrapped
    std::fill(fold_vertex_stamp_.begin(), fold_vertex_stamp_.end(), 0u);
    measure_stamp_ = 1;
  }
  for (const int t : detector_.folded_triangles())
    for (int j = 0; j < 3; ++j) fold_vertex_stamp_[std::size_t(model_.rig.triangles(j, t))] = measure_stamp_;
  return detector_.report();
}

const FoldReport& FoldStage::measure(const float* weights, const Eigen::Matrix3Xd& vertices) noexcept {
  blend_.all(weights, reference_);
  detector_.measure(vertices, reference_);
  return mark_fold_vertices();
}

const FoldReport& FoldStage::measure_again(const Eigen::Matrix3Xd& vertices) noexcept {
  detector_.measure_again(vertices);
  return mark_fold_vertices();
}

void FoldStage::begin_frame() noexcept {
  pins_ = 0;
  ++frame_;
}

const double* FoldStage::pin_column(int v) noexcept {
  int slot = vertex_column_[std::size_t(v)];
  if (slot < 0) {
    // A frame pins at most pin_capacity_ vertices, so some slot is not this frame's.
    slot = 0;
    for (int c = 1; c < int(pin_capacity_); ++c)
      if (column_used_frame_[std::size_t(c)] < column_used_frame_[std::size_t(slot)]) slot = c;
    if (const int old = column_vertex_[std::size_t(slot)]; old >= 0) vertex_column_[std::size_t(old)] = -1;
    model_.poisson.factor->solve_unit(v, pin_columns_.col(slot), pin_work_);
    column_vertex_[std::size_t(slot)] = v;
    vertex_column_[std::size_t(v)] = slot;
  }
  column_used_frame_[std::size_t(slot)] = frame_;
  return pin_columns_.col(slot).data();
}

// Each call is a round: a corner still on a fold is pinned again (its hold adds up), once
// per round. A pinned vertex gains beta e_v e_v^T in A0 and beta e_v (x0 + B w)_v^T in the
// right-hand side, as a collision pin: A0^-1 e_v from the collision stage's precomputed
// columns where the vertex has one, else from pin_column(): back-substituted once and
// kept while it is used (a frame's cost is bounded by fold_max_pins).
uint32_t FoldStage::add_pins(PinUpdate& update, bool with_neighbours) noexcept {
  const SolverModel& m = model_;
  uint32_t added = 0;
  if (++pin_stamp_now_ == 0) {  // wrapped: forget every old stamp
    std::fill(pin_stamp_.begin(), pin_stamp_.end(), 0u);
    pin_stamp_now_ = 1;
  }
  auto pin_corners = [&](int t) {
    for (int j = 0; j < 3; ++j) {
      const int v = m.rig.triangles(j, t);
      if (pin_stamp_[std::size_t(v)] == pin_stamp_now_ || pins_ == pin_capacity_) continue;
      const Eigen::Vector3d target = reference_.col(v);
      const int c = m.pin_columns_precomputed() ? m.collision.vertex_index[std::size_t(v)] : -1;
      bool ok;
      if (c >= 0) {
        ok = update.add(v, m.poisson.pin_solution.column(c), m.poisson.pin_solution.scale[std::size_t(c)], kPinWeight * m.params.beta, target);
      } else {
        ok = update.add({v, v, v}, Eigen::Vector3d(1.0, 0.0, 0.0), pin_column(v), kPinWeight * m.params.beta, target);
      }
      if (!ok) return false;
      pin_stamp_[std::size_t(v)] = pin_stamp_now_;
      ++pins_;
      ++added;
    }
    return true;
  };
  for (const int t : detector_.folded_triangles()) {
    if (!pin_corners(t)) return added;
    if (with_neighbours)
      for (const int u : detector_.neighbours(t))
        if (!pin_corners(u)) return added;
  }
  return added;
}

}  // namespace facecap
