#pragma once
// One frame's work on the solve thread: markers -> rig space (head stabilised) -> face
// solve -> SolvedFrame. Built whole off the real-time thread (a rebuild builds a new one
// aside); process() then runs once per frame without allocating, locking or logging.
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "config/daemon_config.hpp"
#include "core/frame.hpp"
#include "daemon/calibration.hpp"
#include "daemon/marker_mapper.hpp"
#include "drivers/api/marker_source.hpp"
#include "solver/face_solver.hpp"

namespace facecap::daemon {

SolverParams solver_params(const config::SolverSection& section);

class SolvePipeline {
 public:
  // Precomputes the solver for the calibration's face markers (up to seconds for a large
  // rig). Not RT-safe; throws Error.
  SolvePipeline(const Rig& rig, const MarkerCalibration& calibration, const drivers::SourceInfo& source,
                const config::SolverSection& solver, bool stabilise_head);

  // Solves one marker frame into `out`, which make_solved_frame() sized. RT-safe.
  void process(const MarkerFrame& markers, SolvedFrame& out) noexcept;

  // A frame sized for this rig (vertices only when wanted). Not RT-safe.
  SolvedFrame make_solved_frame(bool with_vertices) const;

  // What the loop prefetches ahead of a frame (FaceSolver::streamed_memory). RT-safe.
  std::span<const std::span<const std::byte>> streamed_memory() const noexcept { return solver_->streamed_memory(); }
  const MarkerMapper& mapper() const noexcept { return mapper_; }
  std::string_view method() const noexcept { return solver_->name(); }
  double marker_scale() const noexcept { return scale_; }

 private:
  double scale_ = 1.0;
  MarkerMapper mapper_;
  std::unique_ptr<FaceSolver> solver_;
  SolveResult result_;
  Eigen::Matrix3Xd targets_;
  std::vector<uint8_t> present_;
  Eigen::Index shape_count_ = 0;
  Eigen::Index vertex_count_ = 0;
};

}  // namespace facecap::daemon
