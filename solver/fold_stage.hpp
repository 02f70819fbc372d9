#pragma once
// The fold stage of the Poisson solvers (docs/solver.md "Folds"): after Eq. 5 and the
// collision pins, it measures the solve against the rig's linear blend x0 + B w of the
// same weights (FoldDetector: triangles flipped or creased against it, the largest edge
// stretch), and where the non-linear blend folded a triangle it pins that triangle's
// vertices to the linear blend's shape (moved to where the solve put the skin around it)
// through the same low-rank update as the collision pins, then measures again. A frame
// still folded after that is flagged kSolvedFolded.
// Lifecycle: construct (allocates) -> per frame measure(), add_pins() (real-time safe).
#include <cstdint>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "solver/blend_terms.hpp"
#include "solver/collide/folds.hpp"
#include "solver/pin_update.hpp"

namespace facecap {

class SolverModel;

class FoldStage {
 public:
  // Keeps a reference to model. Allocates; not real-time.
  explicit FoldStage(const SolverModel& model);

  // Pins a frame may add at most (SolverParams::fold_max_pins); the PinUpdate passed to
  // add_pins() needs room for them.
  Eigen::Index pin_capacity() const noexcept { return pin_capacity_; }

  // Blends x0 + B w with `weights` (per shape, from active_weights()) and measures
  // `vertices` (3 x N) against it. Real-time safe.
  const FoldReport& measure(const float* weights, const Eigen::Matrix3Xd& vertices) noexcept;
  // measure() again on new vertices, against the same blend. Real-time safe.
  const FoldReport& measure_again(const Eigen::Matrix3Xd& vertices) noexcept;

  // Pins the vertices of the triangles the last measure() found folded to the linear
  // blend's shape: each edge-connected patch of them to the blend moved by the mean offset
  // (vertices - blend) of the unfolded corners around the patch, so the patch takes the
  // blend's unfolded shape where the solve put the skin around it. Each vertex once per
  // call (a corner pinned in an earlier round and still on a fold is pinned again: its
  // hold adds up), while capacity lasts; with_neighbours: the corners of the triangles
  // beside them too, with their patch's offset. to_blend: to the linear blend itself (the
  // last rounds, for a fold the moved shape does not undo: far pins pull the skin around
  // it apart). vertices: 3 x N, the solve being measured. Returns the pins added.
  // Real-time safe.
  uint32_t add_pins(PinUpdate& update, bool with_neighbours, bool to_blend, const Eigen::Matrix3Xd& vertices) noexcept;
  // This frame's pins to a moved blend put back onto the blend itself (their PinUpdate
  // changes retargeted: no capacity spent). Returns how many. Real-time safe.
  uint32_t pins_to_blend(PinUpdate& update) noexcept;
  // Forgets this frame's pins (call once per frame before add_pins). Real-time safe.
  void begin_frame() noexcept;

  // After a measure: whether vertex v is a corner of a folded triangle. Real-time safe.
  bool on_fold(int v) const noexcept { return fold_vertex_stamp_[std::size_t(v)] == measure_stamp_; }

 private:
  // Times beta: a fold pin holds its vertex to the linear blend firmly, as the tangle
  // hold does (at beta alone the pulled neighbours fold in turn).
  static constexpr double kPinWeight = 10.0;

  const SolverModel& model_;
  FoldDetector detector_;
  LinearBlend blend_;
  Eigen::Matrix3Xd reference_;  // 3 x N: this frame's x0 + B w
  Eigen::Index pin_capacity_ = 0;
  Eigen::Index pins_ = 0;  // this frame's
  // A0^-1 e_v of pinned vertices outside the precomputed collision columns, kept across
  // frames (folds recur at the same eyelids and mouth corners, and each new column is a
  // whole back-substitution): slot -> vertex, vertex -> slot, and the frame that last used
  // each slot (the least recently used one not in this frame's pins is replaced).
  Eigen::MatrixXd pin_columns_;
  std::vector<int> column_vertex_;
  std::vector<int> vertex_column_;
  std::vector<uint64_t> column_used_frame_;
  uint64_t frame_ = 0;
  Eigen::VectorXd pin_work_;
  uint32_t pin_stamp_now_ = 0;        // this round's
  std::vector<uint32_t> pin_stamp_;  // per vertex: the round it was last pinned
  std::vector<std::pair<Eigen::Index, int>> moved_pins_;  // this frame's pins to a moved blend: PinUpdate change, vertex
  std::vector<int> cluster_;              // a patch of folded triangles (capacity T)
  uint32_t cluster_stamp_now_ = 0;
  std::vector<uint32_t> cluster_stamp_;  // per triangle: the add_pins call that put it in a patch
  uint32_t measure_stamp_ = 0;
  std::vector<uint32_t> fold_vertex_stamp_;  // per vertex: the measure that found it on a fold

  const FoldReport& mark_fold_vertices() noexcept;
  // A0^-1 e_v, from the cache or back-substituted into a free or stale slot. Real-time safe.
  const double* pin_column(int v) noexcept;
};

}  // namespace facecap
