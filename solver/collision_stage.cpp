#include "solver/collision_stage.hpp"

#include <algorithm>
#include <span>

#include <Eigen/Geometry>

#include "solver/blend_terms.hpp"
#include "solver/collide/geometry.hpp"
#include "solver/collide/pair_batch.hpp"
#include "solver/mesh_topology.hpp"
#include "solver/solver_model.hpp"

namespace facecap {
namespace {

Eigen::Vector3d triangle_normal(const Eigen::Matrix3Xd& x, const Eigen::Ref<const Eigen::Vector3i>& t) noexcept {
  return (x.col(t[1]) - x.col(t[0])).cross(x.col(t[2]) - x.col(t[0]));
}

}  // namespace

CollisionStage::CollisionStage(const SolverModel& model)
    : model_(model),
      reference_blend_(*model.kernels, model.collision.reference_blocks, model.collision.reference_deltas, model.rig.neutral,
                       model.collision.reference_vertices) {
  const SolverModel& m = model_;
  const Eigen::Index T = m.rig.triangle_count(), N = m.vertex_count();
  reference_.resize(3, Eigen::Index(m.collision.reference_vertices.size()));
  reference_stamp_.assign(std::size_t(m.collision.reference_blocks.block_count()), 0);
  if (!m.collision.triangles.empty()) {
    ColliderConfig config;
    config.epsilon = m.params.collision_epsilon;
    config.ignore_rest_contacts = true;  // a neutral that already touches is the artist's intent
    config.neighbour_edges = 2;
    config.kernels = m.kernels;
    config.skin = m.params.collision_skin_mm * rig_units_per_mm(m.rig);
    collider_.configure(m.rig.triangles, m.rig.neutral, m.collision.triangles, config);
    pin_stamp_.assign(std::size_t(N), 0);
    collisions_ = collider_.make_result();
    const TriangleAdjacency adjacency(m.rig.triangles);
    const auto candidates = collider_.candidate_triangles();
    std::vector<int> candidate_index(std::size_t(T), -1);
    for (std::size_t i = 0; i < candidates.size(); ++i) candidate_index[std::size_t(candidates[i])] = int(i);
    for (std::size_t i = 0; i < candidates.size(); ++i)
      for (const int u : adjacency.neighbours(candidates[i]))
        if (candidate_index[std::size_t(u)] > int(i)) fold_edges_.push_back({int(i), candidate_index[std::size_t(u)]});
    fold_normals_.resize(3, Eigen::Index(candidates.size()));
  }
  pin_capacity_ = std::min<Eigen::Index>(Eigen::Index(m.collision.vertices.size()), m.params.collision_max_pins);
  if (!m.pin_columns_precomputed()) pin_columns_.resize(N, pin_capacity_);
  pin_work_.resize(N);
}

void CollisionStage::begin_frame(const float* weights) noexcept {
  weights_ = weights;
  if (++frame_stamp_ == 0) {  // wrapped: forget every old stamp
    std::fill(pin_stamp_.begin(), pin_stamp_.end(), 0u);
    std::fill(reference_stamp_.begin(), reference_stamp_.end(), 0u);
    frame_stamp_ = 1;
  }
}

// Its block of reference_blocks is blended on first use in a frame.
inline Eigen::Vector3d CollisionStage::reference(int v) noexcept {
  const CollisionData& c = model_.collision;
  const int i = c.reference_index[std::size_t(v)];
  const int block = c.reference_blocks.slot_of_element[std::size_t(i)] / ShapeBlocks::kBlock;
  if (reference_stamp_[std::size_t(block)] != frame_stamp_) {
    reference_stamp_[std::size_t(block)] = frame_stamp_;
    reference_blend_.block(weights_, block, reference_);
  }
  return reference_.col(i);
}

// Inline, as reference(): they run for every vertex of every pair considered.
inline void CollisionStage::pin(int v, PinUpdate& update, Result& result) noexcept {
  const SolverModel& m = model_;
  if (pin_stamp_[std::size_t(v)] == frame_stamp_) return;
  if (Eigen::Index(result.pins) == pin_capacity_) {
    result.beyond_capacity = true;
    return;
  }
  pin_stamp_[std::size_t(v)] = frame_stamp_;
  if (m.pin_columns_precomputed()) {
    const auto c = Eigen::Index(m.collision.vertex_index[std::size_t(v)]);
    update.add(v, m.poisson.pin_solution.column(c), m.poisson.pin_solution.scale[std::size_t(c)], m.params.beta, reference(v));
  } else {
    auto z = pin_columns_.col(Eigen::Index(result.pins));
    m.poisson.factor->solve_unit(v, z, pin_work_);
    update.add({v, v, v}, Eigen::Vector3d(1.0, 0.0, 0.0), z.data(), m.params.beta, reference(v));
  }
  ++result.pins;
}

void CollisionStage::add_held_targets(Eigen::Matrix3Xd& rhs) noexcept {
  const CollisionData& c = model_.collision;
  const double beta = model_.params.beta;
  for (std::size_t j = 0; j < c.held_vertices.size(); ++j)
    rhs.col(c.held_vertices[j]) += c.held_weights[j] * beta * reference(c.held_vertices[j]);
}

// Triangle pairs closer than epsilon pin their vertices to the linear blend
// (x0 + B w)_v, the paper's collision-free reference: A0 gains beta e_v e_v^T, the
// right-hand side beta e_v p_v^T. Only pairs in a worse state than in the reference are
// pinned: closer than epsilon where the linear blend keeps them apart, or crossing where
// it only touches. Lips that rest in contact (ICT) touch in both, and where the linear
// blend itself crosses (ICT's own shapes do) it is no reference.
CollisionStage::Result CollisionStage::add_pins(const Eigen::Matrix3Xd& vertices, PinUpdate& update) noexcept {
  const SolverModel& m = model_;
  Result result;
  if (!collider_.configured() || !collider_.detect(vertices, collisions_)) return result;
  result.pairs = uint32_t(collisions_.pairs_found);
  const double epsilon = m.params.collision_epsilon;
  // A pair whose six vertices are pinned already cannot add a pin: its reference is not
  // worth testing. Once capacity is reached, pairs are tested only until one wants a pin
  // (the frame is then flagged).
  auto wants_pins = [&](const auto& ta, const auto& tb) {
    if (result.beyond_capacity) return false;
    for (const int v : {ta[0], ta[1], ta[2], tb[0], tb[1], tb[2]})
      if (pin_stamp_[std::size_t(v)] != frame_stamp_) return true;
    return false;
  };
  auto pin_pair = [&](const auto& ta, const auto& tb) {
    for (const int v : {ta[0], ta[1], ta[2], tb[0], tb[1], tb[2]}) pin(v, update, result);
  };
  // The pairs' references are tested kCloserBatch at a time, the pins then made in order.
  TrianglePairCorners batch[kCloserBatch];
  const TrianglePair* batch_pairs[kCloserBatch];
  int batched = 0;
  auto pin_batch = [&] {
    const uint32_t close = triangles_closer_than(*m.kernels, std::span(batch, std::size_t(batched)), epsilon);
    for (int k = 0; k < batched; ++k) {
      const auto ta = m.rig.triangles.col(batch_pairs[k]->first), tb = m.rig.triangles.col(batch_pairs[k]->second);
      if (!wants_pins(ta, tb)) continue;
      if ((close >> k) & 1u) {
        // The reference is in contact too: pin only if the solve crosses where it does not.
        const auto& [a, b] = batch[k];
        if (triangles_intersect(a[0], a[1], a[2], b[0], b[1], b[2]) ||
            !triangles_intersect(vertices.col(ta[0]), vertices.col(ta[1]), vertices.col(ta[2]), vertices.col(tb[0]),
                                 vertices.col(tb[1]), vertices.col(tb[2])))
          continue;
      }
      pin_pair(ta, tb);
    }
    batched = 0;
  };
  for (const TrianglePair& pair : collisions_.valid_pairs()) {
    const auto ta = m.rig.triangles.col(pair.first), tb = m.rig.triangles.col(pair.second);
    if (!wants_pins(ta, tb)) continue;
    batch[batched] = {{reference(ta[0]), reference(ta[1]), reference(ta[2])}, {reference(tb[0]), reference(tb[1]), reference(tb[2])}};
    batch_pairs[batched] = &pair;
    if (++batched == kCloserBatch) pin_batch();
  }
  pin_batch();
  // Folds: neighbours across an edge turned more than 90 degrees against each other
  // where the linear blend keeps them less than 90 degrees apart. Such a crease folds
  // the skin through itself within a few triangles, where pairs are too near to test.
  const auto candidates = collider_.candidate_triangles();
  for (std::size_t i = 0; i < candidates.size(); ++i)
    fold_normals_.col(Eigen::Index(i)) = triangle_normal(vertices, m.rig.triangles.col(candidates[i]));
  for (const auto& [first, second] : fold_edges_) {
    if (fold_normals_.col(first).dot(fold_normals_.col(second)) >= 0.0) continue;
    const auto ta = m.rig.triangles.col(candidates[std::size_t(first)]), tb = m.rig.triangles.col(candidates[std::size_t(second)]);
    if (!wants_pins(ta, tb)) continue;
    const Eigen::Vector3d la = (reference(ta[1]) - reference(ta[0])).cross(reference(ta[2]) - reference(ta[0]));
    const Eigen::Vector3d lb = (reference(tb[1]) - reference(tb[0])).cross(reference(tb[2]) - reference(tb[0]));
    if (la.dot(lb) < 0.0) continue;
    pin_pair(ta, tb);
  }
  return result;
}

}  // namespace facecap
