#include "core/frame.hpp"

namespace facecap {

MarkerFrame make_marker_frame(const std::vector<std::string>& labels) {
  MarkerFrame frame;
  frame.markers.resize(labels.size());
  for (std::size_t i = 0; i < labels.size(); ++i) {
    frame.markers[i].id = int32_t(i);
    frame.markers[i].label.assign(labels[i]);
    frame.markers[i].flags = kMarkerMissing;
  }
  return frame;
}

void copy_solved_frame(const SolvedFrame& from, SolvedFrame& to) noexcept {
  to.frame_no = from.frame_no;
  to.source_time_ns = from.source_time_ns;
  to.receive_time_ns = from.receive_time_ns;
  to.solve_start_ns = from.solve_start_ns;
  to.solve_end_ns = from.solve_end_ns;
  to.timecode = from.timecode;
  to.head_rotation = from.head_rotation;
  to.head_translation = from.head_translation;
  if (to.weights.size() == from.weights.size()) to.weights = from.weights;
  if (to.vertices.cols() > 0 && to.vertices.cols() == from.vertices.cols()) to.vertices = from.vertices;
  to.stage_ns = from.stage_ns;
  to.collision_constraints = from.collision_constraints;
  to.markers_used = from.markers_used;
  to.flags = from.flags;
  to.folded_triangles = from.folded_triangles;
  to.max_edge_stretch_mm = from.max_edge_stretch_mm;
  to.fold_deadline_rounds = from.fold_deadline_rounds;
}

std::string_view solve_stage_name(SolveStage stage) noexcept {
  switch (stage) {
    case SolveStage::kStabilise: return "stabilise";
    case SolveStage::kCorrespond: return "correspond";
    case SolveStage::kWeights: return "weights";
    case SolveStage::kBlend: return "blend";
    case SolveStage::kRhs: return "rhs";
    case SolveStage::kBacksolve: return "backsolve";
    case SolveStage::kCollide: return "collide";
    case SolveStage::kFilter: return "filter";
    case SolveStage::kCount: break;
  }
  return "?";
}

std::string_view solved_flag_name(std::size_t bit) noexcept {
  static constexpr std::string_view kNames[kSolvedFlagCount] = {
      "head_pose_held", "too_few_markers", "qp_iteration_cap", "pins_beyond_capacity", "singular_correction",
      "implausible_marker", "folded", "inconsistent_marker"};
  return bit < kSolvedFlagCount ? kNames[bit] : "?";
}

}  // namespace facecap
