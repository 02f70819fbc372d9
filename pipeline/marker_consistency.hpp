#pragma once
// Label swaps caught before they pin (docs/alignment.md "Label swaps"). A swapped label
// puts a marker's target where a neighbour is; when it glides there over a few frames it
// passes the speed gate, and the Poisson solvers, which pin vertices to the targets, tear
// the face towards it. Each frame, every face marker's target is compared with where the
// rig puts its bound point under the previous frame's weights (x0~ + B~ w_prev); the
// difference (its residual) is compared with its neighbours' (the markers nearest to it
// on the rest face): motion since the last frame and the actor-rig mismatch move
// neighbours alike, a swap does not. A marker whose residual is further than the gate
// from the median of its neighbours' is inconsistent: a pair of inconsistent markers that
// are consistent with each other's targets is swapped back, any other inconsistent marker
// is left out of the frame (weights and pins). Lifecycle: construct (allocates) ->
// check() per frame (real-time safe).
#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include <Eigen/Core>

namespace facecap {
class SolverModel;
}

namespace facecap::pipeline {

class MarkerConsistency {
 public:
  static constexpr int kNeighbours = 6;

  // gate_rig: the gate in rig units (> 0). Keeps a reference to model. Allocates.
  MarkerConsistency(const SolverModel& model, double gate_rig);

  struct Result {
    uint32_t dropped = 0;    // markers left out
    uint32_t unswapped = 0;  // pairs swapped back
  };
  // targets: 3 x K rig space (the model's marker order), present: K (dropped markers set
  // to 0, a swapped pair's targets exchanged); previous_weights: M, the last frame's
  // solved weights. Real-time safe.
  Result check(Eigen::Matrix3Xd& targets, std::span<uint8_t> present, const Eigen::VectorXd& previous_weights) noexcept;

  // After check(): per marker, 1 if left out, 2 if swapped back this frame.
  std::span<const uint8_t> verdicts() const noexcept { return verdict_; }

 private:
  // Whether residual r of marker k sits within the gate of its present neighbours'
  // median residual (true when fewer than 3 neighbours are present).
  bool consistent(int k, const Eigen::Vector3d& r, std::span<const uint8_t> present) const noexcept;

  const SolverModel& model_;
  double gate_rig_;
  std::vector<std::array<int, kNeighbours>> neighbours_;  // K: nearest markers at rest
  Eigen::Matrix3Xd predicted_, residual_;                 // 3 x K
  std::vector<uint8_t> verdict_;                          // K
  std::vector<int> inconsistent_;                         // capacity K
};

}  // namespace facecap::pipeline
