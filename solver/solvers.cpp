// The per-frame solvers: nonlinear (the paper), linear and dt, each a composition of the
// stages (weights_stage, triangle_blend, pin_update, collision_stage), and make_solver.
// Everything here after construction is real-time safe unless said otherwise.
#include <algorithm>
#include <memory>

#include "core/error.hpp"
#include "core/time.hpp"
#include "solver/blend_terms.hpp"
#include "solver/collision_stage.hpp"
#include "solver/face_solver.hpp"
#include "solver/fold_stage.hpp"
#include "solver/meshik.hpp"
#include "solver/pin_update.hpp"
#include "solver/solver_model.hpp"
#include "solver/triangle_blend.hpp"
#include "solver/weights_stage.hpp"

namespace facecap {
namespace {

class StageClock {
 public:
  explicit StageClock(SolveResult& out) : out_(out), start_(monotonic_now_ns()), last_(start_) { out.stage_ns.fill(0); }
  void lap(SolveStage stage) noexcept {
    const int64_t now = monotonic_now_ns();
    out_.stage_ns[std::size_t(stage)] += now - last_;
    last_ = now;
  }
  void finish() noexcept { out_.total_ns = monotonic_now_ns() - start_; }

 private:
  SolveResult& out_;
  int64_t start_, last_;
};

// Starts a frame's result: no flags, no collisions. Too few usable markers hold the
// previous result and flag it; returns whether the frame is to be solved.
bool begin_solve(const WeightsStage& weights, const Eigen::Matrix3Xd& targets, std::span<const uint8_t> present,
                 SolveResult& out) noexcept {
  out.collision_pairs = out.collision_constraints = out.fold_pins = out.markers_released = 0;
  out.fold_stopped_at_deadline = false;
  out.fold_rounds = 0;
  out.folds = {};
  out.status = weights.usable(present, targets) ? 0u : uint32_t(kSolvedTooFewMarkers);
  return out.status == 0;
}

// Eq. 2 into out: weights, markers used, the QP's flag.
void solve_weights(WeightsStage& weights, const Eigen::Matrix3Xd& targets, std::span<const uint8_t> present,
                   SolveResult& out) noexcept {
  const WeightsStage::Result result = weights.solve(targets, present, out.weights);
  out.markers_used = result.markers_used;
  if (result.iteration_cap) out.status |= kSolvedQpIterationCap;
}

// Direct manipulation: x0 + B w with the weights of Eq. 2.
class LinearSolver final : public FaceSolver {
 public:
  explicit LinearSolver(std::shared_ptr<const SolverModel> model)
      : FaceSolver(std::move(model)),
        weights_(*model_, false),
        blend_(*model_->kernels, model_->blend.vertex_blocks, model_->blend.vertex_deltas, model_->rig.neutral),
        active_(std::size_t(model_->shape_count())) {}
  std::string_view name() const noexcept override { return kSolverMethods.name(SolverMethod::kLinear); }
  void reset() noexcept override { weights_.reset(); }
  State make_state() const override { return weights_.make_state(); }
  bool save_state(State& state) const noexcept override { return weights_.save(state); }
  bool restore_state(const State& state) noexcept override { return weights_.restore(state); }
  void solve(const Eigen::Matrix3Xd& targets, std::span<const uint8_t> present, SolveResult& out) noexcept override {
    StageClock clock(out);
    if (!begin_solve(weights_, targets, present, out)) { clock.finish(); return; }
    solve_weights(weights_, targets, present, out);
    clock.lap(SolveStage::kWeights);
    blend(out);
    clock.lap(SolveStage::kBlend);
    clock.finish();
  }
  void solve_with_weights(const Eigen::VectorXd& weights, const Eigen::Matrix3Xd&, std::span<const uint8_t>,
                          SolveResult& out) noexcept override {
    StageClock clock(out);
    out.status = 0;
    out.weights = weights;
    blend(out);
    clock.lap(SolveStage::kBlend);
    clock.finish();
  }

 private:
  void blend(SolveResult& out) noexcept {
    active_weights(out.weights, model_->params.active_weight, model_->blend.shape_reach, model_->blend.negligible_reach, active_);
    blend_.all(active_.data(), out.vertices);
  }

  WeightsStage weights_;
  LinearBlend blend_;
  std::vector<float> active_;  // per shape: its weight, 0 if inactive
};

// Eq. 4-5 with the matrix factored once: the right-hand side G^T W T(w) + beta C^T b is
// built over the triangles the active shapes touch (TriangleBlend), back-substituted,
// then corrected for missing markers and collision pins (CollisionStage) by a low-rank
// update (PinUpdate). This class only puts the stages in order.
class PoissonSolver final : public FaceSolver {
 public:
  PoissonSolver(std::shared_ptr<const SolverModel> model, TriangleBlend::Kind kind)
      : FaceSolver(std::move(model)),
        weights_(*model_, kind == TriangleBlend::Kind::kNonlinear),
        blend_(*model_, kind),
        collisions_(*model_),
        folds_(*model_),
        pins_(model_->vertex_count(), model_->marker_count() + collisions_.pin_capacity() + folds_.pin_capacity()),
        active_(std::size_t(model_->shape_count())),
        rhs_(3, model_->vertex_count()),
        work_(4, model_->vertex_count()) {}

  std::string_view name() const noexcept override {
    return kSolverMethods.name(blend_.kind() == TriangleBlend::Kind::kNonlinear ? SolverMethod::kNonlinear : SolverMethod::kDt);
  }
  void reset() noexcept override { weights_.reset(); }
  State make_state() const override { return weights_.make_state(); }
  bool save_state(State& state) const noexcept override { return weights_.save(state); }
  bool restore_state(const State& state) noexcept override { return weights_.restore(state); }
  std::span<const std::span<const std::byte>> streamed_memory() const noexcept override { return blend_.streamed_memory(); }

  void solve(const Eigen::Matrix3Xd& targets, std::span<const uint8_t> present, SolveResult& out) noexcept override {
    StageClock clock(out);
    if (!begin_solve(weights_, targets, present, out)) { clock.finish(); return; }
    solve_weights(weights_, targets, present, out);
    clock.lap(SolveStage::kWeights);
    solve_mesh(targets, present, out, clock);
  }

  void solve_with_weights(const Eigen::VectorXd& weights, const Eigen::Matrix3Xd& targets,
                          std::span<const uint8_t> present, SolveResult& out) noexcept override {
    StageClock clock(out);
    out.status = 0;
    out.collision_pairs = out.collision_constraints = out.fold_pins = out.markers_released = 0;
    out.fold_stopped_at_deadline = false;
    out.fold_rounds = 0;
    out.weights = weights;
    solve_mesh(targets, present, out, clock);
  }

 private:
  // Eq. 4, Eq. 5, collisions and folds for out.weights.
  void solve_mesh(const Eigen::Matrix3Xd& targets, std::span<const uint8_t> present, SolveResult& out,
                  StageClock& clock) noexcept {
    const SolverModel& m = *model_;
    active_weights(out.weights, m.params.active_weight, m.blend.shape_reach, m.blend.negligible_reach, active_);
    blend_.right_hand_side(active_.data(), rhs_);  // the triangles' share of the right-hand side
    clock.lap(SolveStage::kBlend);

    pins_.clear();
    const double beta = m.params.beta;
    for (Eigen::Index k = 0; k < m.marker_count(); ++k) {
      const auto& b = m.markers[std::size_t(k)];
      if (present[std::size_t(k)] && targets.col(k).allFinite()) {
        for (int a = 0; a < 3; ++a) rhs_.col(b.vertices[a]) += beta * b.barycentric[a] * targets.col(k);
      } else {
        pins_.add(b.vertices, b.barycentric, m.poisson.marker_solution.col(k).data(), -beta);  // the marker drops out
      }
    }
    collisions_.begin_frame(active_.data());
    collisions_.add_held_targets(rhs_);
    clock.lap(SolveStage::kRhs);

    m.poisson.factor->solve_in_place(rhs_, work_);  // rhs_ now holds y = A0^-1 r
    if (!pins_.apply(rhs_, out.vertices)) out.status |= kSolvedSingularCorrection;
    clock.lap(SolveStage::kBacksolve);

    const CollisionStage::Result collided = collisions_.add_pins(out.vertices, pins_);
    out.collision_pairs = collided.pairs;
    out.collision_constraints = collided.pins;
    if (collided.beyond_capacity) out.status |= kSolvedPinsBeyondCapacity;
    if (collided.pins > 0 && !pins_.apply(rhs_, out.vertices)) out.status |= kSolvedSingularCorrection;

    // Folds (timed with the collisions: both are pins to the linear blend): the folded
    // triangles' corners pinned to the linear blend's shape where the skin around them is
    // (FoldStage::add_pins), then measured again, round by round
    // (a corner still on a fold is pinned again). From round kReleaseRound, or when
    // capacity is spent, a marker pinning a corner of a fold that remains pulls the skin
    // through itself (a far pin, a swapped label): it is released for this frame.
    out.folds = folds_.measure(active_.data(), out.vertices);
    folds_.begin_frame();
    bool released = false;
    // A frame folded widely needs its pins for the folds themselves: the blend itself
    // from the first round.
    const int blend_round = int64_t(out.folds.folded) * kMovedShapeShare <= int64_t(folds_.pin_capacity()) ? kBlendRound : 0;
    for (int round = 0; round < kFoldRounds && out.folds.folded > 0 && folds_.pin_capacity() > 0; ++round) {
      const int64_t round_start_ns = monotonic_now_ns();
      if ((deadline_ns_ != 0 && round_start_ns + longest_fold_round_ns_ > deadline_ns_) || round == fold_round_stop_) {
        out.fold_stopped_at_deadline = true;
        break;
      }
      out.fold_rounds = uint32_t(round + 1);
      // At blend_round a round of its own, when there are any: the pins so far put back
      // onto the blend itself, and measured as they are.
      if (round != blend_round || folds_.pins_to_blend(pins_) == 0) {
        const uint32_t added = folds_.add_pins(pins_, round >= kNeighbourRound, round >= blend_round, out.vertices);
        out.fold_pins += added;
        if (!released && (added == 0 || round == kReleaseRound)) {
          released = true;
          if (release_folding_markers(targets, present, out) == 0 && added == 0) break;
        } else if (added == 0) {
          break;
        }
      }
      if (!pins_.apply(rhs_, out.vertices)) out.status |= kSolvedSingularCorrection;
      out.folds = folds_.measure_again(out.vertices);
      longest_fold_round_ns_ = std::max(longest_fold_round_ns_, monotonic_now_ns() - round_start_ns);
    }
    longest_fold_round_ns_ -= longest_fold_round_ns_ / kFoldRoundDecay;
    if (out.folds.folded > 0) out.status |= kSolvedFolded;
    clock.lap(SolveStage::kCollide);
    clock.finish();
  }

  // Removes the pin of each present marker bound to a corner of a folded triangle (the
  // low-rank change of a dropout, its target taken back out of the right-hand side).
  // Returns the markers released. Real-time safe.
  uint32_t release_folding_markers(const Eigen::Matrix3Xd& targets, std::span<const uint8_t> present, SolveResult& out) noexcept {
    const SolverModel& m = *model_;
    uint32_t released = 0;
    for (Eigen::Index k = 0; k < m.marker_count(); ++k) {
      const auto& b = m.markers[std::size_t(k)];
      if (!present[std::size_t(k)] || !targets.col(k).allFinite()) continue;
      if (!folds_.on_fold(b.vertices[0]) && !folds_.on_fold(b.vertices[1]) && !folds_.on_fold(b.vertices[2])) continue;
      if (!pins_.add(b.vertices, b.barycentric, m.poisson.marker_solution.col(k).data(), -m.params.beta, targets.col(k))) break;
      ++released;
    }
    out.markers_released += released;
    return released;
  }

  // Pinning a folded triangle can fold a neighbour it pulls: up to this many rounds of
  // pins and measures, markers released from the kReleaseRound'th on.
  static constexpr int kFoldRounds = 8, kReleaseRound = 4;
  // From this round on the triangles beside a fold are pinned with it: pinning only its
  // corners can push the fold onto a neighbour, round after round. Not earlier: a widely
  // folded frame needs its pins for the folds themselves.
  static constexpr int kNeighbourRound = 2;
  // From this round on a fold still there is pinned to the linear blend itself, not to its
  // shape moved to the skin around it (far pins pull that skin apart).
  static constexpr int kBlendRound = 2;
  // The moved shape only while the folded triangles' corners (3 each) fit 4 times into
  // the pin capacity: its rounds cost pins a widely folded frame (CheeksMoCap's 160s:
  // 61 frames left folded) needs for the blend itself.
  static constexpr int64_t kMovedShapeShare = 12;
  // What a fold round is expected to take, for the deadline: the longest recent one,
  // forgotten by 1/kFoldRoundDecay a frame (a heavy fold once does not stop rounds for
  // good).
  static constexpr int64_t kFoldRoundDecay = 64;
  int64_t longest_fold_round_ns_ = 0;

  WeightsStage weights_;
  TriangleBlend blend_;
  CollisionStage collisions_;
  FoldStage folds_;
  PinUpdate pins_;             // this frame's missing markers, then its collision and fold pins
  std::vector<float> active_;  // per shape: its weight, 0 if inactive
  Eigen::Matrix3Xd rhs_;       // 3 x N: the right-hand side, then y = A0^-1 r
  Eigen::Matrix4Xd work_;      // back-substitution scratch
};

}  // namespace

SolveResult FaceSolver::make_result() const {
  SolveResult r;
  r.weights.setZero(model_->shape_count());
  r.vertices = model_->rig.neutral;
  return r;
}

std::unique_ptr<FaceSolver> make_solver(SolverMethod method, std::shared_ptr<const SolverModel> model) {
  if (!model) throw Error("make_solver: no solver model");
  switch (method) {
    case SolverMethod::kNonlinear: return std::make_unique<PoissonSolver>(std::move(model), TriangleBlend::Kind::kNonlinear);
    case SolverMethod::kDt:
      return std::make_unique<PoissonSolver>(std::move(model), TriangleBlend::Kind::kDeformationTransfer);
    case SolverMethod::kLinear: return std::make_unique<LinearSolver>(std::move(model));
    case SolverMethod::kMeshik: return make_meshik_solver(std::move(model));
  }
  throw Error("make_solver: not a solver method");
}

}  // namespace facecap
