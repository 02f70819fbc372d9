#pragma once
// One frame's work, the same in facecapd's solve loop and in every tool: marker frame ->
// (label check) -> rig-space targets with the head stabilised (MarkerMapper) -> (temporal
// filter) -> face solve -> (weight filter) -> SolvedFrame. Built whole off the real-time
// thread (facecapd builds a new one aside on reload and swaps it in); process() then runs
// once per frame without allocating, locking, throwing or logging.
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "config/daemon_config.hpp"
#include "core/frame.hpp"
#include "pipeline/marker_consistency.hpp"
#include "pipeline/marker_mapper.hpp"
#include "pipeline/temporal_filter.hpp"
#include "solver/align/label.hpp"
#include "solver/face_solver.hpp"
#include "solver/rig.hpp"

namespace facecap::pipeline {

// What the frames to be solved carry: their marker slots and units.
struct SourceDescription {
  std::vector<std::string> labels;  // MarkerFrame::markers order
  std::string units;                // "mm", "cm", "m"; empty when unknown (the calibration's are assumed)
};

// The temporal filter ([filter]): One Euro on the mapped targets, optionally on the weights.
struct FilterSettings {
  bool targets = false;
  bool weights = false;                // only with targets
  OneEuroParams target_params;         // beta in Hz per mm/s (the rig's mm)
  OneEuroParams weight_params;         // beta in Hz per weight/s
};

// The targets' filter for `markers` markers in rig space, beta converted from per mm/s to
// per rig unit/s. Not RT-safe.
OneEuroFilter make_target_filter(const FilterSettings& filter, Eigen::Index markers, double rig_mm_per_unit);
// The weights' filter for `shapes` shapes: one row of scalars, a channel per shape. Not
// RT-safe.
OneEuroFilter make_weight_filter(const FilterSettings& filter, Eigen::Index shapes);
// Filters `weights` (M, a make_weight_filter filter's channels) in place. RT-safe.
void filter_weights(OneEuroFilter& filter, Eigen::VectorXd& weights, int64_t time_ns) noexcept;

// How to solve: the [solver] section's method and parameters, and the mapping options.
struct SolveSettings {
  SolverMethod method = SolverMethod::kNonlinear;
  SolverParams params;
  MapperOptions mapper;
  // Check each frame's labels against the markers' predicted positions and correct
  // swaps before mapping (align::MarkerLabeller::check).
  bool check_labels = false;
  // Label every frame afresh (align::MarkerLabeller::label): its present points, whatever
  // labels they came with, are matched to the calibration's markers, so that a face is
  // solved from an unlabelled point cloud. Implies the check.
  bool label_markers = false;
  // Each face marker checked against its neighbours before it pins (MarkerConsistency):
  // one further than this (rig mm) from what they say is left out of the frame, a
  // swapped pair is swapped back. 0: off.
  double marker_consistency_mm = 0.0;  // off (config::kSuggestedMarkerConsistencyMm turns it on)
  FilterSettings filter;
};

class SolvePipeline {
 public:
  // Precomputes the solver for the calibration's markers (up to seconds for a large rig).
  // Throws Error (unknown method, a calibration that does not fit the rig or the source).
  // Not RT-safe.
  SolvePipeline(const Rig& rig, const align::Calibration& calibration, const SourceDescription& source,
                const SolveSettings& settings);

  // Solves one marker frame into `out`, which make_solved_frame() sized, with its
  // telemetry: markers used of expected, the status bits, and per marker slot the target
  // and the fit residual (solved surface point vs target, mm). RT-safe.
  void process(const MarkerFrame& markers, SolvedFrame& out) noexcept;

  // A frame sized for this rig and the source's marker slots (vertices only when
  // wanted). Not RT-safe.
  SolvedFrame make_solved_frame(bool with_vertices) const;

  // When the next process() should end (monotonic_now_ns; 0: none): FaceSolver::set_deadline.
  // RT-safe.
  void set_deadline(int64_t deadline_ns) noexcept { solver_->set_deadline(deadline_ns); }
  // The fold stage of the next process() calls stops after `rounds` rounds, as a deadline
  // stopped it in the solve being reproduced (FaceSolver::stop_folds_after; -1: no stop).
  // RT-safe.
  void stop_folds_after(int rounds) noexcept { solver_->stop_folds_after(rounds); }

  // What the pipeline carries from one frame to the next, each stateful stage's own: a
  // recording started mid-run stores it as it was before its first frame and a re-solve
  // restores it, so that the re-solve matches from that frame (docs/recording-format.md,
  // STAT). The marker consistency check keeps nothing of its own (it predicts from the
  // last weights, held here).
  struct State {
    std::optional<align::MarkerLabeller::State> labeller;  // with the label check or labelling
    MarkerMapper::State mapper;
    std::optional<OneEuroFilter::State> target_filter, weight_filter;  // with the filters
    FaceSolver::State solver;
    // The last solve's result: a frame with too few markers holds it, the consistency
    // check predicts from its weights.
    Eigen::VectorXd weights;    // M
    Eigen::Matrix3Xd vertices;  // 3 x N, rig units
  };
  // The state as it is now, encoded (pipeline/pipeline_state.hpp) into storage sized at
  // construction; valid until the next call. RT-safe.
  std::span<const char> encoded_state() noexcept;
  // Its size, constant for this pipeline. RT-safe.
  std::size_t encoded_state_size() const noexcept { return encoded_state_.size(); }
  // Continues from `state` at the next process(). Throws Error naming the stage whose
  // state does not fit this pipeline (another rig, marker set or [solver] section);
  // nothing is changed then. Not RT-safe.
  void restore_state(const State& state);
  // What a loop prefetches ahead of a frame (FaceSolver::streamed_memory). RT-safe.
  std::span<const std::span<const std::byte>> streamed_memory() const noexcept { return solver_->streamed_memory(); }
  const MarkerMapper& mapper() const noexcept { return mapper_; }
  // The last frame's mapping (its targets filtered when the filter is on) and solve, for
  // tools that report more than a SolvedFrame.
  const MappedFrame& mapped() const noexcept { return mapped_; }
  const SolveResult& result() const noexcept { return result_; }
  // The last frame's label check or labelling (zeros without either).
  const align::LabelStats& label_stats() const noexcept { return label_stats_; }
  // The last frame as the mapper took it after the label check (the source's slots) or the
  // labelling (the calibration's markers, bound ones first); empty without either.
  const MarkerFrame& labelled_frame() const noexcept { return checked_; }
  std::string_view method() const noexcept { return solver_->name(); }
  // The solver's settings as decided for the rig (kByRig ones resolved).
  const SolverParams& solver_params() const noexcept;
  // The kernels the solver runs (SolverParams::kernels decided for this CPU).
  KernelPath kernel_path() const noexcept;

 private:
  void record_fit_residuals(SolvedFrame& out) const noexcept;
  // A state sized for this pipeline. Not RT-safe.
  State make_state() const;
  // Copies the pipeline's state into `state`; false (and `state` not to be used) when it
  // was not sized for this pipeline. RT-safe.
  bool save_state(State& state) const noexcept;

  MarkerMapper mapper_;
  std::unique_ptr<FaceSolver> solver_;
  std::optional<align::MarkerLabeller> labeller_;
  bool label_markers_ = false;
  MarkerFrame checked_;  // the frame after the label check or labelling, sized at construction
  std::vector<Eigen::Vector3d> points_;  // label_markers: a frame's present points, sized to its slots
  MappedFrame mapped_;
  std::optional<MarkerConsistency> consistency_;
  std::optional<OneEuroFilter> target_filter_, weight_filter_;
  Eigen::VectorXd filtered_weights_;  // M, with the weight filter
  SolveResult result_;
  align::LabelStats label_stats_;
  std::vector<MarkerBinding> bindings_;  // per calibration marker, for the fit residuals
  State saved_state_;                // encoded_state()'s, sized at construction
  std::vector<char> encoded_state_;  // its bytes, the capacity they need reserved
  double rig_mm_per_unit_ = 1.0;
  Eigen::Index shape_count_ = 0;
  Eigen::Index vertex_count_ = 0;
  Eigen::Index source_slots_ = 0;
};

}  // namespace facecap::pipeline
