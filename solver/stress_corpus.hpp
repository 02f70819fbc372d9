#pragma once
// The stress corpus of the non-linear blend (docs/solver.md "Folds"): poses where the
// blend of rotations and stretches is most likely to fold the skin. Built for a rig from
// its own shape names and regions, deterministic (fixed seeds), so that a fold count on
// it is comparable run to run. `facecap bench --stress` and the tests solve it.
// Building allocates; not real-time.
#include <string>
#include <vector>

#include <Eigen/Core>

#include "solver/face_solver.hpp"

namespace facecap {

struct StressPose {
  std::string name;         // "eyeBlink_L+browDown_L", "pair lips 3", "random eyelids 7", "far pins 2"
  std::string kind;         // combination | pair | random | far_pins
  Eigen::VectorXd weights;  // M
  Eigen::Matrix3Xd targets; // 3 x K: the markers of the linear blend of `weights`, far pins moved
};

struct StressCorpusOptions {
  int random_per_region = 40;  // random draws of 2 to 4 shapes of one region
  int far_pin_poses = 40;      // random draws with 1 to 3 markers dragged far
  double far_pin_mm = 25.0;    // how far (rig mm): a drag in the editor
  unsigned seed = 29;
};

// The corpus over `markers` (the layout its targets are for):
// - combinations: eyeBlink with browDown, eyeBlink with eyeWide, eyeSquint with
//   mouthSmile (each side, when the rig has them: _L/_R or without suffix), jawOpen with
//   mouthPucker and mouthFunnel; each at full weight;
// - every pair of shapes at 1 whose largest motion is in the same region (lips,
//   eyelids, elsewhere: triangle_regions);
// - random draws per region, and random draws with markers dragged far.
std::vector<StressPose> stress_corpus(const Rig& rig, const std::vector<MarkerBinding>& markers,
                                      const StressCorpusOptions& options = {});

}  // namespace facecap
