#include "daemon/solve_pipeline.hpp"

#include <fmt/format.h>

#include "core/error.hpp"
#include "core/time.hpp"
#include "solver/marker_layout.hpp"

namespace facecap::daemon {
namespace {

// A head marker this far off the rigid fit (and 4x the others' median) is left out of
// the head pose, as `facecap solve` does.
constexpr double kHeadOutlierFloorMm = 1.0;

}  // namespace

SolverParams solver_params(const config::SolverSection& section) {
  SolverParams p;
  p.alpha = section.alpha;
  p.mu = section.mu;
  p.beta = section.beta;
  p.weight_refinements = int(section.weight_refinements);
  p.collision_region = section.collisions == "none"   ? CollisionRegion::kNone
                       : section.collisions == "face" ? CollisionRegion::kFace
                                                      : CollisionRegion::kLips;
  p.collision_epsilon = section.collision_epsilon;
  p.collision_max_pins = int(section.collision_max_pins);
  p.active_weight = section.active_weight;
  return p;
}

SolvePipeline::SolvePipeline(const Rig& rig, const MarkerCalibration& calibration, const drivers::SourceInfo& source,
                             const config::SolverSection& solver, bool stabilise_head)
    : scale_(marker_to_rig_scale(calibration, source.units, rig)),
      mapper_(calibration, source.labels, scale_, stabilise_head, kHeadOutlierFloorMm * rig_units_per_mm(rig)),
      solver_(make_solver(solver.method, build_solver_model(rig, calibration.markers.face, solver_params(solver)))),
      result_(solver_->make_result()),
      targets_(Eigen::Matrix3Xd::Zero(3, Eigen::Index(calibration.markers.face.size()))),
      present_(calibration.markers.face.size(), 0),
      shape_count_(rig.shape_count()),
      vertex_count_(rig.vertex_count()) {}

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

  const MappedFrame mapped = mapper_.map(markers, targets_, present_);
  const int64_t mapped_ns = monotonic_now_ns();
  solver_->solve(targets_, present_, result_);

  out.weights = result_.weights.cast<float>();  // same size: no allocation
  if (out.vertices.cols() == result_.vertices.cols()) out.vertices = result_.vertices.cast<float>();
  out.head_rotation = Eigen::Quaterniond(mapped.T_world_head.rotation());
  out.head_translation = mapped.T_world_head.translation();
  out.stage_ns = result_.stage_ns;
  out.stage_ns[std::size_t(SolveStage::kStabilise)] = mapped_ns - out.solve_start_ns;
  out.markers_used = result_.markers_used;
  out.collision_constraints = result_.collision_constraints;
  out.flags = (mapped.head_pose_held ? kSolvedHeadPoseHeld : 0u) | (result_.held ? kSolvedTooFewMarkers : 0u);
  out.solve_end_ns = monotonic_now_ns();
}

}  // namespace facecap::daemon
