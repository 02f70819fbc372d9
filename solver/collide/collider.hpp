#pragma once
// Triangle-triangle proximity for the face solve (DESIGN.md "Collisions"): a bounding
// volume hierarchy of axis-aligned boxes over a candidate set of triangles (the lip
// region or the whole face, collide/lip_region.hpp), built once on the rest mesh and
// refitted every frame with each triangle's box grown by epsilon / 2, finds the triangle
// pairs closer than epsilon that share no vertex. The solver pins those pairs' vertices
// to the linear blend. Frame to frame the tree is traversed only when needed: its boxes
// are grown by a skin beyond epsilon / 2, and the pairs whose boxes overlapped are tested
// again as they are until some candidate vertex has moved farther than the skin (a
// Verlet list: no pair closer than epsilon can be missed).
//
// Lifecycle: TriangleCollider::configure() (allocates, not real-time) -> make_result()
// (allocates the output once) -> detect() per frame (real-time safe).
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "solver/collide/triangle_pair.hpp"
#include "solver/kernels/kernels.hpp"

namespace facecap {

struct ColliderConfig {
  double epsilon = 0.01;  // rig units: triangle pairs closer than this collide (>= 0)
  int max_pairs = 4096;   // pairs stored per frame; more are counted, not stored (>= 0)
  // Constrained vertices stored per frame; < 0 means every vertex of the candidate
  // triangles, which can never overflow.
  int max_vertices = -1;
  // Leave out pairs already closer than epsilon in the rest pose. Real rigs have such
  // contacts (the ICT neutral's lip corners interpenetrate), and pinning them every
  // frame constrains the mouth for nothing.
  bool ignore_rest_contacts = false;
  // Also leave out pairs where a vertex of one is within this many mesh edges of a
  // vertex of the other (0: only pairs sharing a vertex). Such triangles are neighbours
  // on one sheet of skin, near by construction rather than in contact, and their boxes
  // overlap: leaving them out spares most exact tests (>= 0).
  int neighbour_edges = 0;
  // The kernels of the batched closeness test; null: the widest this CPU runs.
  const kernels::KernelTable* kernels = nullptr;
  // Rig units the boxes are grown by beyond epsilon / 2, so that their overlapping pairs
  // serve the following frames while no candidate vertex moves farther (>= 0; 0 traverses
  // the tree every frame).
  double skin = 0.0;
  // Box-overlapping pairs kept for the following frames at most; a frame with more
  // traverses the tree again next frame.
  int max_kept_pairs = 1 << 15;
};

// One frame's collisions, sized once by TriangleCollider::make_result(); detect() only
// writes into it. The first pair_count pairs and vertex_count vertices are valid.
struct CollisionResult {
  std::vector<TrianglePair> pairs;  // capacity max_pairs; valid prefix sorted ascending
  std::vector<int32_t> vertices;    // capacity max_vertices; valid prefix ascending, unique
  int32_t pair_count = 0;
  int32_t vertex_count = 0;
  int32_t pairs_found = 0;     // colliding pairs this frame, including those not stored
  int32_t vertices_found = 0;  // distinct vertices of all pairs found, including unstored
  int32_t pairs_tested = 0;    // box-overlapping pairs given the closeness test
  bool traversed = false;      // the tree was traversed (else last traversal's pairs were reused)
  // True when pairs or vertices exceeded capacity. The vertices always come from every
  // pair found, stored or not, so pinning stays complete while vertex capacity lasts.
  bool overflowed() const noexcept { return pairs_found > pair_count || vertices_found > vertex_count; }
  std::span<const TrianglePair> valid_pairs() const noexcept { return {pairs.data(), std::size_t(pair_count)}; }
  std::span<const int32_t> valid_vertices() const noexcept { return {vertices.data(), std::size_t(vertex_count)}; }
};

class TriangleCollider {
 public:
  TriangleCollider();
  ~TriangleCollider();
  TriangleCollider(TriangleCollider&&) noexcept;
  TriangleCollider& operator=(TriangleCollider&&) noexcept;

  // Builds the tree over candidate_triangles on the rest mesh (deterministically: the
  // same input always gives the same tree) and sizes every per-frame buffer.
  // triangles: 3 x T vertex indices; rest_positions: 3 x N; candidate_triangles:
  // indices into triangles (duplicates ignored; all_triangles() for the whole face).
  // Not real-time: allocates; throws Error on out-of-range indices or bad limits.
  void configure(const Eigen::Matrix3Xi& triangles, const Eigen::Matrix3Xd& rest_positions,
                 std::span<const int> candidate_triangles, const ColliderConfig& config);

  // A result with capacity for this configuration. Not real-time: allocates.
  CollisionResult make_result() const;

  // Refits the tree to `positions` (3 x N, same vertex order as configure) and writes
  // every candidate pair closer than epsilon that shares no vertex into `out`.
  // Real-time safe: no allocation, locks, logging or exceptions. Pass a Matrix3Xd or a
  // Map of contiguous 3 x N doubles (another expression type would be copied).
  // Returns false, with `out` emptied, if not configured, if the sizes do not match or
  // if a candidate vertex is not finite. It updates the tree in place: one thread at a
  // time per collider.
  bool detect(const Eigen::Ref<const Eigen::Matrix3Xd>& positions, CollisionResult& out) noexcept;

  bool configured() const noexcept;
  double epsilon() const noexcept;
  Eigen::Index vertex_count() const noexcept;          // N the collider expects
  std::span<const int32_t> candidate_triangles() const noexcept;  // ascending, unique
  std::span<const int32_t> candidate_vertices() const noexcept;   // ascending, unique
  int tree_depth() const noexcept;                     // levels of four-wide nodes, root = 1
  // Pairs left out because they touch at rest (ignore_rest_contacts), sorted.
  std::span<const TrianglePair> rest_contacts() const noexcept;

 private:
  struct State;
  std::unique_ptr<State> state_;
};

}  // namespace facecap
