#pragma once
// facecap bench --stress: the stress corpus (solver/stress_corpus.hpp) through each
// selected solver, folds measured against the linear blend of the same weights.
#include <string>

#include <nlohmann/json.hpp>

#include "solver/params.hpp"

namespace facecap::tools {

struct StressOptions {
  std::string rig, solvers = "nonlinear,dt,linear";
  int markers = 60;
  SolverParams params;
  std::string worst_dir;  // when set: the worst pose per solver written there as OBJ (solve and linear blend)
  std::string pose;       // with worst_dir: this pose (by name) instead of the worst
};

// Per solver: poses, folded poses (in all and per kind), folded triangles, the largest edge
// stretch (rig mm), fold pins, the worst pose, solve time. Throws Error.
nlohmann::json run_stress(const StressOptions& options);
void print_stress(const nlohmann::json& report);

}  // namespace facecap::tools
