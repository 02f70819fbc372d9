#include "solver/fold_stage.hpp"

#include <algorithm>
#include <span>

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
  moved_pins_.reserve(std::size_t(pin_capacity_));
  cluster_.resize(std::size_t(m.rig.triangles.cols()));
  cluster_stamp_.assign(std::size_t(m.rig.triangles.cols()), 0);
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
  moved_pins_.clear();
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
// per round. Its target is the linear blend moved by its patch's offset (below): the
// blend's own shape, which is unfolded, where the solve put the skin around it; the blend
// where it is (an earlier version) pulled a brow whose neighbour marker was held out 4-5 mm
// off the markers (EyebrowsMoCap's held-out p95 +3.1%; with the offset -0.1%). A pinned
// vertex gains beta e_v e_v^T in A0 and beta e_v (target)^T in the right-hand side, as a
// collision pin: A0^-1 e_v from the collision stage's precomputed
// columns where the vertex has one, else from pin_column(): back-substituted once and
// kept while it is used (a frame's cost is bounded by fold_max_pins).
uint32_t FoldStage::pins_to_blend(PinUpdate& update) noexcept {
  const auto moved = uint32_t(moved_pins_.size());
  for (const auto& [change, v] : moved_pins_) update.retarget(change, reference_.col(v));
  moved_pins_.clear();
  return moved;
}

uint32_t FoldStage::add_pins(PinUpdate& update, bool with_neighbours, bool to_blend, const Eigen::Matrix3Xd& vertices) noexcept {
  const SolverModel& m = model_;
  uint32_t added = 0;
  if (++pin_stamp_now_ == 0) {  // wrapped: forget every old stamp
    std::fill(pin_stamp_.begin(), pin_stamp_.end(), 0u);
    pin_stamp_now_ = 1;
  }
  auto pin_corners = [&](int t, const Eigen::Vector3d& patch_offset) {
    for (int j = 0; j < 3; ++j) {
      const int v = m.rig.triangles(j, t);
      if (pin_stamp_[std::size_t(v)] == pin_stamp_now_ || pins_ == pin_capacity_) continue;
      const Eigen::Vector3d target = reference_.col(v) + patch_offset;
      const int c = m.pin_columns_precomputed() ? m.collision.vertex_index[std::size_t(v)] : -1;
      bool ok;
      if (c >= 0) {
        ok = update.add(v, m.poisson.pin_solution.column(c), m.poisson.pin_solution.scale[std::size_t(c)], kPinWeight * m.params.beta, target);
      } else {
        ok = update.add({v, v, v}, Eigen::Vector3d(1.0, 0.0, 0.0), pin_column(v), kPinWeight * m.params.beta, target);
      }
      if (!ok) return false;
      if (!to_blend) moved_pins_.push_back({update.size() - 1, v});
      pin_stamp_[std::size_t(v)] = pin_stamp_now_;
      ++pins_;
      ++added;
    }
    return true;
  };
  // Each connected patch of folded triangles is held to the linear blend's shape, moved
  // by where the solve put the skin around it: the mean of (solved - blend) over the
  // corners of the patch's neighbours that are on no fold.
  const std::span<const uint8_t> folded = detector_.folded_flags();
  if (++cluster_stamp_now_ == 0) {
    std::fill(cluster_stamp_.begin(), cluster_stamp_.end(), 0u);
    cluster_stamp_now_ = 1;
  }
  for (const int seed : detector_.folded_triangles()) {
    if (cluster_stamp_[std::size_t(seed)] == cluster_stamp_now_) continue;
    std::size_t size = 0;
    cluster_[size++] = seed;
    cluster_stamp_[std::size_t(seed)] = cluster_stamp_now_;
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    int n = 0;
    for (std::size_t i = 0; i < size; ++i)
      for (const int u : detector_.neighbours(cluster_[i])) {
        if (folded[std::size_t(u)]) {
          if (cluster_stamp_[std::size_t(u)] != cluster_stamp_now_) {
            cluster_stamp_[std::size_t(u)] = cluster_stamp_now_;
            cluster_[size++] = u;
          }
          continue;
        }
        if (to_blend) continue;  // no offset to take
        for (int j = 0; j < 3; ++j) {
          const int w = m.rig.triangles(j, u);
          if (on_fold(w)) continue;
          sum += vertices.col(w) - reference_.col(w);
          ++n;
        }
      }
    const Eigen::Vector3d offset = n > 0 ? Eigen::Vector3d(sum / n) : Eigen::Vector3d::Zero();
    bool room = true;
    for (std::size_t i = 0; i < size && room; ++i) {
      room = pin_corners(cluster_[i], offset);
      if (with_neighbours)
        for (const int u : detector_.neighbours(cluster_[i])) room = room && pin_corners(u, offset);
    }
    if (!room) break;
  }
  return added;
}

}  // namespace facecap
