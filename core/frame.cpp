#include "core/frame.hpp"

namespace facecap {

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
      "head_pose_held", "too_few_markers", "qp_iteration_cap", "pins_beyond_capacity", "singular_correction"};
  return bit < kSolvedFlagCount ? kNames[bit] : "?";
}

}  // namespace facecap
