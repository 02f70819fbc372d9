#pragma once
// The per-frame face solve, libigl style: build_solver_model() precomputes everything
// from a rig and a marker layout (off the real-time thread, may take a second);
// make_solver() gives a solver whose solve() runs once per frame into pre-sized
// outputs and never allocates, locks, throws or logs.
#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include "core/frame.hpp"
#include "solver/collide/folds.hpp"
#include "solver/params.hpp"
#include "solver/rig.hpp"
#include "solver/weights_stage.hpp"

namespace facecap {

// Where a marker sits on the rig: a surface point as barycentric coordinates over a
// triangle's vertices. A marker on a vertex is {v, v, v} with weights {1, 0, 0}.
struct MarkerBinding {
  std::string label;
  std::array<int, 3> vertices{};
  Eigen::Vector3d barycentric{1.0, 0.0, 0.0};
  static MarkerBinding at_vertex(std::string label, int vertex) {
    return {std::move(label), {vertex, vertex, vertex}, {1.0, 0.0, 0.0}};
  }
};

// One frame's result. Sized by FaceSolver::make_result(); solve() only writes into it.
struct SolveResult {
  Eigen::VectorXd weights;    // M
  Eigen::Matrix3Xd vertices;  // 3 x N, rig units
  std::array<int64_t, kSolveStageCount> stage_ns{};
  int64_t total_ns = 0;
  uint32_t markers_used = 0;
  uint32_t collision_pairs = 0;        // colliding triangle pairs found
  uint32_t collision_constraints = 0;  // vertices pinned to the linear blend
  uint32_t fold_pins = 0;              // vertices of folded triangles pinned to the linear blend
  uint32_t markers_released = 0;       // present markers whose pins a fold released this frame
  // The fold stage stopped before the next round for the deadline set_deadline() gave
  // (what it had not undone stays folded and flagged), after fold_rounds rounds.
  bool fold_stopped_at_deadline = false;
  uint32_t fold_rounds = 0;
  // The fold metric against the linear blend of the same weights after the fold stage
  // (nonlinear, dt; zero for linear and meshik).
  FoldReport folds;
  // SolvedFlags (core/frame.hpp) this solve raised: kSolvedTooFewMarkers (the previous
  // result kept), kSolvedQpIterationCap, kSolvedPinsBeyondCapacity,
  // kSolvedSingularCorrection, kSolvedFolded. 0 for a normal frame.
  uint32_t status = 0;
};

class SolverModel;

class FaceSolver {
 public:
  virtual ~FaceSolver() = default;
  virtual std::string_view name() const noexcept = 0;

  // targets: 3 x K marker positions in rig space; present: K flags (0 = missing).
  // Real-time safe for nonlinear, linear and dt; meshik is an offline baseline.
  virtual void solve(const Eigen::Matrix3Xd& targets, std::span<const uint8_t> present, SolveResult& out) noexcept = 0;

  // The mesh for given weights (M) and pins, skipping Eq. 2: for editing, for solving
  // from captured weight curves, and for tests. Real-time safe like solve().
  virtual void solve_with_weights(const Eigen::VectorXd& weights, const Eigen::Matrix3Xd& targets,
                                  std::span<const uint8_t> present, SolveResult& out) noexcept = 0;

  // Forgets the warm start (previous weights). Real-time safe.
  virtual void reset() noexcept = 0;
  // The time (monotonic_now_ns) the next solves should end by, 0 for none (offline:
  // every stage runs to the end). Only the fold stage's rounds, which a badly folded
  // frame can repeat for milliseconds, heed it: a round is not started when the longest
  // recent round would end past it. Real-time safe.
  void set_deadline(int64_t deadline_ns) noexcept { deadline_ns_ = deadline_ns; }
  // Replays a deadline stop: from the next solve on (until told otherwise) the fold stage
  // stops after `rounds` rounds, as a deadline stopped it in the solve being reproduced
  // (its SolveResult::fold_rounds); -1: no such stop. A re-solve without the live deadline
  // thus stops where the live solve stopped. Real-time safe.
  void stop_folds_after(int rounds) noexcept { fold_round_stop_ = rounds; }

  // What the solver carries from one frame to the next: Eq. 2's warm start.
  using State = WeightsStage::State;
  // A state sized for this solver. Not real-time.
  virtual State make_state() const = 0;
  // Copies the warm start into `state`; false (nothing copied) when it was not sized for
  // this solver. Real-time safe.
  virtual bool save_state(State& state) const noexcept = 0;
  // Continues from `state`; false (nothing changed) when its shape count is not this
  // solver's. Real-time safe.
  virtual bool restore_state(const State& state) noexcept = 0;

  // The model memory each solve streams through that is too large to stay cached
  // between paced frames (the blend's terms), in the order it is read: a loop that
  // sleeps between frames prefetches it before the next one (prefetch_until). Empty
  // when nothing is worth it. Valid while the solver lives.
  virtual std::span<const std::span<const std::byte>> streamed_memory() const noexcept { return {}; }

  SolveResult make_result() const;
  const SolverModel& model() const { return *model_; }

 protected:
  explicit FaceSolver(std::shared_ptr<const SolverModel> model) : model_(std::move(model)) {}
  std::shared_ptr<const SolverModel> model_;
  int64_t deadline_ns_ = 0;
  int fold_round_stop_ = -1;
};

// Precomputes deformation gradients, the factorisation and the collision structure.
// unfitted_shapes (names) are left out of Eq. 2: their weights stay 0 (the shapes the
// calibration's markers cannot observe, align::Calibration::unfitted_shapes). Settings
// left at kByRig are decided for the rig (SolverParams); SolverModel::params holds them
// decided. Throws Error on an unusable rig or binding, or an unfitted name the rig lacks.
std::shared_ptr<const SolverModel> build_solver_model(const Rig& rig, std::vector<MarkerBinding> markers,
                                                      const SolverParams& params = {},
                                                      const std::vector<std::string>& unfitted_shapes = {});

// The solver of `method` (kSolverMethods) over a built model. Not real-time; throws Error
// without a model.
std::unique_ptr<FaceSolver> make_solver(SolverMethod method, std::shared_ptr<const SolverModel> model);

}  // namespace facecap
