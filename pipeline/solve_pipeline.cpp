#include "pipeline/solve_pipeline.hpp"

#include "core/time.hpp"
#include "solver/marker_layout.hpp"

namespace facecap::pipeline {
namespace {

// The label check's gates, in mm of the actor's face.
constexpr double kLabelGateMm = 6.0;
constexpr double kLabelGateGrowthMm = 1.0;  // per frame a marker stays lost
constexpr double kLabelMaxGateMm = 20.0;
constexpr double kLabelMarginMm = 1.0;      // in favour of the label a point came with

}  // namespace

SolvePipeline::SolvePipeline(const Rig& rig, const align::Calibration& calibration, const SourceDescription& source,
                             const SolveSettings& settings)
    : mapper_(calibration, source.labels, source.units, settings.mapper),
      solver_(make_solver(settings.method,
                          build_solver_model(rig, calibration.bindings(), settings.params,
                                             calibration.unfitted_shapes()))),
      mapped_(mapper_.make_output()),
      result_(solver_->make_result()),
      shape_count_(rig.shape_count()),
      vertex_count_(rig.vertex_count()) {
  if (settings.check_labels) {
    // Predictions start from the calibration frame, in the source's units.
    const double mm = calibration.take_mm_per_unit * mapper_.source_to_take();  // per source unit
    Eigen::Matrix3Xd reference = Eigen::Matrix3Xd::Zero(3, Eigen::Index(source.labels.size()));
    for (std::size_t s = 0; s < source.labels.size(); ++s)
      if (const Eigen::Vector3d* neutral = calibration.neutral_of(source.labels[s]))
        reference.col(Eigen::Index(s)) = *neutral / mapper_.source_to_take();
    align::LabellerParams params;
    params.gate = kLabelGateMm / mm;
    params.gate_growth = kLabelGateGrowthMm / mm;
    params.max_gate = kLabelMaxGateMm / mm;
    params.label_margin = kLabelMarginMm / mm;
    labeller_.emplace(source.labels, std::move(reference), params);
    checked_.markers.resize(source.labels.size());
  }
}

SolvedFrame SolvePipeline::make_solved_frame(bool with_vertices) const {
  SolvedFrame frame;
  frame.resize(shape_count_, with_vertices ? vertex_count_ : 0);
  return frame;
}

void SolvePipeline::process(const MarkerFrame& markers, SolvedFrame& out) noexcept {
  out.frame_no = markers.frame_no;
  out.source_time_ns = markers.source_time_ns;
  out.receive_time_ns = markers.receive_time_ns;
  out.timecode = markers.timecode;
  out.solve_start_ns = monotonic_now_ns();

  const MarkerFrame* frame = &markers;
  if (labeller_ && markers.markers.size() == checked_.markers.size()) {
    checked_ = markers;  // same marker count: the copy reuses checked_'s storage
    label_stats_ = labeller_->check(checked_);
    frame = &checked_;
  }
  const int64_t checked_ns = monotonic_now_ns();
  mapper_.process(*frame, mapped_);
  const int64_t mapped_ns = monotonic_now_ns();
  solver_->solve(mapped_.targets, mapped_.present, result_);

  out.weights = result_.weights.cast<float>();  // same size: no allocation
  if (out.vertices.cols() == result_.vertices.cols()) out.vertices = result_.vertices.cast<float>();
  out.head_rotation = mapped_.head_rotation;
  out.head_translation = mapped_.head_translation;
  out.stage_ns = result_.stage_ns;
  out.stage_ns[std::size_t(SolveStage::kCorrespond)] = checked_ns - out.solve_start_ns;
  out.stage_ns[std::size_t(SolveStage::kStabilise)] = mapped_ns - checked_ns;
  out.markers_used = result_.markers_used;
  out.collision_constraints = result_.collision_constraints;
  out.flags = (mapped_.head_held ? kSolvedHeadPoseHeld : 0u) | result_.status;
  out.solve_end_ns = monotonic_now_ns();
}

}  // namespace facecap::pipeline
