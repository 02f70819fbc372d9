#pragma once
// The collision stage of the Poisson solvers (DESIGN.md step 4, docs/solver.md
// "Collisions"): after Eq. 5, the collider finds triangle pairs of the candidate region
// closer than epsilon, and the stage pins the vertices of those in a worse state than in
// the linear blend x0 + B w (the paper's collision-free reference) to that blend, as
// changes of a PinUpdate (solver/pin_update.hpp). It also supplies the linear blend at
// the held vertices (tangles, the outer boundary), which Eq. 5's right-hand side holds
// every frame.
// Lifecycle: construct (allocates) -> per frame begin_frame(), add_held_targets(),
// add_pins() (all real-time safe).
#include <cstdint>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "solver/blend_terms.hpp"
#include "solver/collide/collider.hpp"
#include "solver/pin_update.hpp"

namespace facecap {

class SolverModel;

class CollisionStage {
 public:
  // Configures the collider over CollisionData::triangles (nothing when the region is
  // none). Keeps a reference to model. Allocates; not real-time.
  explicit CollisionStage(const SolverModel& model);

  // Pins a frame may add at most: collision_max_pins, or fewer when the region has fewer
  // vertices. The PinUpdate passed to add_pins() needs room for them.
  Eigen::Index pin_capacity() const noexcept { return pin_capacity_; }

  // Starts a frame whose linear blend uses `weights` (per shape, from active_weights();
  // read until the frame ends): forgets the last frame's pins and blended references.
  // Real-time safe.
  void begin_frame(const float* weights) noexcept;

  // Adds the held vertices' share of the right-hand side, h_v beta (x0 + B w)_v, to
  // rhs (3 x N). Real-time safe.
  void add_held_targets(Eigen::Matrix3Xd& rhs) noexcept;

  struct Result {
    uint32_t pairs = 0;             // colliding triangle pairs found
    uint32_t pins = 0;              // vertices pinned to the linear blend
    bool beyond_capacity = false;   // a pair wanted pins after pin_capacity() was reached
  };
  // Finds the colliding pairs of `vertices` (3 x N, this frame's Eq. 5 solve) and adds
  // their pins to `update`. Real-time safe.
  Result add_pins(const Eigen::Matrix3Xd& vertices, PinUpdate& update) noexcept;

 private:
  // This frame's (x0 + B w)_v at a collision or held vertex.
  Eigen::Vector3d reference(int v) noexcept;
  // Pins vertex v to the linear blend, once per frame and while capacity lasts.
  void pin(int v, PinUpdate& update, Result& result) noexcept;

  const SolverModel& model_;
  TriangleCollider collider_;
  CollisionResult collisions_;
  std::vector<std::pair<int, int>> fold_edges_;  // candidate triangles sharing an edge (indices into the candidates)
  Eigen::Matrix3Xd fold_normals_;                // per candidate triangle: this frame's normal (not unit)
  Eigen::Index pin_capacity_ = 0;
  Eigen::MatrixXd pin_columns_;  // A0^-1 e_v solved per frame when not precomputed
  Eigen::VectorXd pin_work_;
  LinearBlend reference_blend_;     // x0 + B w at CollisionData::reference_vertices
  const float* weights_ = nullptr;  // this frame's active weights
  Eigen::Matrix3Xd reference_;      // the linear blend at CollisionData::reference_vertices (reference())
  uint32_t frame_stamp_ = 0;
  std::vector<uint32_t> pin_stamp_;        // per vertex: the frame it was last pinned
  std::vector<uint32_t> reference_stamp_;  // per block of reference_blocks: the frame it was last blended
};

}  // namespace facecap
