#include "pipeline/solve_pipeline.hpp"

#include <limits>

#include <fmt/format.h>

#include "core/error.hpp"
#include "core/time.hpp"
#include "pipeline/pipeline_state.hpp"
#include "solver/marker_layout.hpp"
#include "solver/solver_model.hpp"

namespace facecap::pipeline {
namespace {

// The label check's gates, in mm of the actor's face.
constexpr double kLabelGateMm = 6.0;
constexpr double kLabelGateGrowthMm = 1.0;  // per frame a marker stays lost
constexpr double kLabelMaxGateMm = 20.0;
constexpr double kLabelMarginMm = 1.0;      // in favour of the label a point came with

// The markers the labeller gives frames to the mapper in: every marker of the calibration
// with a neutral position, bound ones first.
std::vector<std::string> calibration_labels(const align::Calibration& calibration) {
  std::vector<std::string> labels;
  for (const auto& m : calibration.markers) labels.push_back(m.label);
  for (const auto& h : calibration.head_markers) labels.push_back(h.label);
  return labels;
}

}  // namespace

OneEuroFilter make_target_filter(const FilterSettings& filter, Eigen::Index markers, double rig_mm_per_unit) {
  OneEuroParams params = filter.target_params;
  params.beta *= rig_mm_per_unit;
  return OneEuroFilter(3, markers, params);
}

OneEuroFilter make_weight_filter(const FilterSettings& filter, Eigen::Index shapes) {
  return OneEuroFilter(1, shapes, filter.weight_params);
}

void filter_weights(OneEuroFilter& filter, Eigen::VectorXd& weights, int64_t time_ns) noexcept {
  filter.filter(Eigen::Map<Eigen::MatrixXd>(weights.data(), 1, weights.size()), {}, time_ns);
}

SolvePipeline::SolvePipeline(const Rig& rig, const align::Calibration& calibration, const SourceDescription& source,
                             const SolveSettings& settings)
    : mapper_(calibration, settings.label_markers ? calibration_labels(calibration) : source.labels, source.units,
              settings.mapper),
      solver_(make_solver(settings.method,
                          build_solver_model(rig, calibration.bindings(), settings.params,
                                             calibration.unfitted_shapes()))),
      mapped_(mapper_.make_output()),
      result_(solver_->make_result()),
      bindings_(calibration.bindings()),
      rig_mm_per_unit_(calibration.rig_mm_per_unit),
      shape_count_(rig.shape_count()),
      vertex_count_(rig.vertex_count()),
      source_slots_(Eigen::Index(source.labels.size())) {
  label_markers_ = settings.label_markers;
  if (settings.marker_consistency_mm > 0.0)
    consistency_.emplace(solver_->model(), settings.marker_consistency_mm / rig_mm_per_unit_);
  if (settings.filter.targets) {
    target_filter_.emplace(make_target_filter(settings.filter, mapper_.marker_count(), rig_mm_per_unit_));
    if (settings.filter.weights) {
      weight_filter_.emplace(make_weight_filter(settings.filter, shape_count_));
      filtered_weights_.resize(shape_count_);
    }
  }
  if (settings.check_labels || label_markers_) {
    // The labeller's markers: the source's slots for the check, the calibration's when
    // labelling. Predictions start from the calibration frame, in the source's units.
    const std::vector<std::string> labels = label_markers_ ? calibration_labels(calibration) : source.labels;
    const double mm = calibration.take_mm_per_unit * mapper_.source_to_take();  // per source unit
    Eigen::Matrix3Xd reference = Eigen::Matrix3Xd::Zero(3, Eigen::Index(labels.size()));
    for (std::size_t s = 0; s < labels.size(); ++s)
      if (const Eigen::Vector3d* neutral = calibration.neutral_of(labels[s]))
        reference.col(Eigen::Index(s)) = *neutral / mapper_.source_to_take();
    align::LabellerParams params;
    params.gate = kLabelGateMm / mm;
    params.gate_growth = kLabelGateGrowthMm / mm;
    params.max_gate = kLabelMaxGateMm / mm;
    params.label_margin = kLabelMarginMm / mm;
    params.max_points = std::max<int>(1, int(source.labels.size()));
    labeller_.emplace(labels, std::move(reference), params);
    checked_ = make_marker_frame(labels);
    points_.resize(source.labels.size());
  }
  saved_state_ = make_state();
  encode_pipeline_state(saved_state_, encoded_state_);
}

SolvePipeline::State SolvePipeline::make_state() const {
  State state{.mapper = mapper_.make_state(), .solver = solver_->make_state(), .weights = result_.weights,
              .vertices = result_.vertices};
  if (labeller_) state.labeller = labeller_->make_state();
  if (target_filter_) state.target_filter = target_filter_->make_state();
  if (weight_filter_) state.weight_filter = weight_filter_->make_state();
  return state;
}

bool SolvePipeline::save_state(State& state) const noexcept {
  if (state.labeller.has_value() != labeller_.has_value() || state.target_filter.has_value() != target_filter_.has_value() ||
      state.weight_filter.has_value() != weight_filter_.has_value())
    return false;
  if (state.weights.size() != result_.weights.size() || state.vertices.cols() != result_.vertices.cols()) return false;
  if (labeller_ && !labeller_->save(*state.labeller)) return false;
  if (target_filter_ && !target_filter_->save(*state.target_filter)) return false;
  if (weight_filter_ && !weight_filter_->save(*state.weight_filter)) return false;
  if (!mapper_.save(state.mapper) || !solver_->save_state(state.solver)) return false;
  state.weights = result_.weights;  // same sizes: no allocation
  state.vertices = result_.vertices;
  return true;
}

std::span<const char> SolvePipeline::encoded_state() noexcept {
  save_state(saved_state_);  // made by make_state(): it fits
  encode_pipeline_state(saved_state_, encoded_state_);
  return encoded_state_;
}

void SolvePipeline::restore_state(const State& state) {
  const auto refuse = [](std::string_view stage, std::string_view why) {
    throw Error(fmt::format("the pipeline state's {} does not fit this solve: {}", stage, why));
  };
  const auto presence = [&](std::string_view stage, bool stored, bool here) {
    if (stored != here) refuse(stage, stored ? "this solve has none" : "none is stored");
  };
  presence("label check", state.labeller.has_value(), labeller_.has_value());
  presence("target filter", state.target_filter.has_value(), target_filter_.has_value());
  presence("weight filter", state.weight_filter.has_value(), weight_filter_.has_value());
  if (state.weights.size() != shape_count_ || state.vertices.cols() != result_.vertices.cols())
    refuse("last result", fmt::format("{} shapes and {} vertices stored, the rig has {} and {}", state.weights.size(),
                                      state.vertices.cols(), shape_count_, result_.vertices.cols()));
  // Each stage checks its own sizes: try on copies, so that a refusal changes nothing.
  std::optional<align::MarkerLabeller> labeller = labeller_;
  std::optional<OneEuroFilter> target_filter = target_filter_, weight_filter = weight_filter_;
  MarkerMapper mapper = mapper_;
  if (labeller && !labeller->restore(*state.labeller)) refuse("label check", "another marker count");
  if (target_filter && !target_filter->restore(*state.target_filter)) refuse("target filter", "another marker count");
  if (weight_filter && !weight_filter->restore(*state.weight_filter)) refuse("weight filter", "another shape count");
  if (!mapper.restore(state.mapper)) refuse("marker mapper", "another marker count");
  if (!solver_->restore_state(state.solver)) refuse("solver warm start", "another shape count");
  labeller_ = std::move(labeller);
  target_filter_ = std::move(target_filter);
  weight_filter_ = std::move(weight_filter);
  mapper_ = std::move(mapper);
  result_.weights = state.weights;
  result_.vertices = state.vertices;
}

const SolverParams& SolvePipeline::solver_params() const noexcept { return solver_->model().params; }
KernelPath SolvePipeline::kernel_path() const noexcept { return solver_->model().kernels->path; }

SolvedFrame SolvePipeline::make_solved_frame(bool with_vertices) const {
  SolvedFrame frame;
  frame.resize(shape_count_, with_vertices ? vertex_count_ : 0, source_slots_);
  return frame;
}

void SolvePipeline::process(const MarkerFrame& markers, SolvedFrame& out) noexcept {
  out.frame_no = markers.frame_no;
  out.source_time_ns = markers.source_time_ns;
  out.receive_time_ns = markers.receive_time_ns;
  out.timecode = markers.timecode;
  out.solve_start_ns = monotonic_now_ns();

  const MarkerFrame* frame = &markers;
  if (labeller_ && label_markers_) {
    std::size_t n = 0;
    for (const Marker& m : markers.markers)
      if (m.present() && n < points_.size()) points_[n++] = m.position;
    label_stats_ = labeller_->label(std::span<const Eigen::Vector3d>(points_.data(), n), checked_);
    frame = &checked_;
  } else if (labeller_ && markers.markers.size() == checked_.markers.size()) {
    checked_ = markers;  // same marker count: the copy reuses checked_'s storage
    label_stats_ = labeller_->check(checked_);
    frame = &checked_;
  }
  const int64_t checked_ns = monotonic_now_ns();
  mapper_.process(*frame, mapped_);
  bool inconsistent = false;
  if (consistency_) {  // against the previous frame's weights (the solver's warm start, still in result_)
    const MarkerConsistency::Result checked = consistency_->check(mapped_.targets, mapped_.present, result_.weights);
    inconsistent = checked.dropped + checked.unswapped > 0;
  }
  if (target_filter_) target_filter_->filter(mapped_.targets, mapped_.present, markers.source_time_ns);
  const int64_t mapped_ns = monotonic_now_ns();
  solver_->solve(mapped_.targets, mapped_.present, result_);

  if (weight_filter_) {  // the weights sent out; the solver's result (its warm start) stays as solved
    filtered_weights_ = result_.weights;  // same size: no allocation
    filter_weights(*weight_filter_, filtered_weights_, markers.source_time_ns);
    out.weights = filtered_weights_.cast<float>();
  } else {
    out.weights = result_.weights.cast<float>();  // same size: no allocation
  }
  if (out.vertices.cols() == result_.vertices.cols()) out.vertices = result_.vertices.cast<float>();
  out.head_rotation = mapped_.head_rotation;
  out.head_translation = mapped_.head_translation;
  out.stage_ns = result_.stage_ns;
  out.stage_ns[std::size_t(SolveStage::kCorrespond)] = checked_ns - out.solve_start_ns;
  out.stage_ns[std::size_t(SolveStage::kStabilise)] = mapped_ns - checked_ns;
  out.markers_used = result_.markers_used;
  out.markers_expected = uint32_t(bindings_.size());
  out.collision_constraints = result_.collision_constraints;
  out.folded_triangles = result_.folds.folded;
  out.max_edge_stretch_mm = float(result_.folds.max_edge_stretch * rig_mm_per_unit_);
  out.fold_deadline_rounds = result_.fold_stopped_at_deadline ? int32_t(result_.fold_rounds) : -1;
  out.flags = (mapped_.head_held ? kSolvedHeadPoseHeld : 0u) | (mapped_.markers_implausible > 0 ? kSolvedImplausibleMarker : 0u) |
              (inconsistent ? kSolvedInconsistentMarker : 0u) | result_.status;
  record_fit_residuals(out);
  out.solve_end_ns = monotonic_now_ns();
}

// Each bound marker present this frame: its target and its distance from the solved
// surface point it is bound to (a held face keeps the previous mesh, so its residuals
// show how far the face is from the markers now). RT-safe.
void SolvePipeline::record_fit_residuals(SolvedFrame& out) const noexcept {
  if (out.marker_residual_mm.size() != source_slots_ || out.marker_targets.cols() != source_slots_) return;
  out.marker_targets.setConstant(std::numeric_limits<float>::quiet_NaN());
  out.marker_residual_mm.setConstant(std::numeric_limits<float>::quiet_NaN());
  const std::span<const int> slots = mapper_.slots();
  for (std::size_t k = 0; k < bindings_.size(); ++k) {
    const auto slot = Eigen::Index(slots[k]);
    if (slot < 0 || !mapped_.present[k]) continue;
    const Eigen::Vector3d target = mapped_.targets.col(Eigen::Index(k));
    out.marker_targets.col(slot) = target.cast<float>();
    out.marker_residual_mm[slot] = float((binding_point(bindings_[k], result_.vertices) - target).norm() * rig_mm_per_unit_);
  }
}

}  // namespace facecap::pipeline
