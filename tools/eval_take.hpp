#pragma once
// Evaluation of solvers on a real, calibrated take (no ground truth): leave-one-out
// held-out marker error, fit residual, jitter, intersecting and flipped triangles, head
// stabilisation figures. Definitions: docs/alignment.md.
#include <string>

#include <nlohmann/json.hpp>

#include "pipeline/solve_pipeline.hpp"
#include "tools/label_swap.hpp"

namespace facecap::tools {

struct TakeEvalOptions {
  std::string rig, take, calib, solvers = "all", rig_units;
  std::string units;       // the take's, when it states them wrongly (empty: as stated)
  int every = 10;          // held-out and mesh checks on every Nth frame (all frames solved)
  int offline_every = 200; // offline solvers (meshik, ~0.6 s a solve): only every Nth frame, no jitter
  int max_frames = 0;      // 0: the whole take
  bool progress = false;
  pipeline::SolveSettings settings;  // the solver parameters and mapping (the method comes from `solvers`)
  std::vector<LabelSwap> swaps;      // injected into the take before it is solved
};

// Throws Error on unusable input. Returns the JSON report.
nlohmann::json evaluate_take(const TakeEvalOptions& options);

// Prints the report as a table.
void print_take_evaluation(const nlohmann::json& report);

}  // namespace facecap::tools
