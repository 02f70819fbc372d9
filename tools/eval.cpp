// facecap eval: solver evaluation. On a real take with a calibration profile (--calib):
// leave-one-out held-out marker error, fit, jitter, intersections and flips per solver.
#include <cstdio>

#include "tools/commands.hpp"
#include "tools/eval_take.hpp"

namespace facecap::tools {

void add_eval_command(CLI::App& app, int& exit_code) {
  auto opts = std::make_shared<TakeEvalOptions>();
  auto json = std::make_shared<bool>(false);
  auto* cmd = app.add_subcommand("eval", "Evaluate solvers on a calibrated real take (held-out marker error, jitter, intersections, flips)");
  cmd->add_option("--rig", opts->rig, "builtin, an OBJ directory, a rig.toml manifest, or a .gltf/.glb file")->required();
  cmd->add_option("--take", opts->take, "Marker take (.trc, .c3d, .fcrec)")->required()->check(CLI::ExistingFile);
  cmd->add_option("--calib", opts->calib, "Calibration profile from facecap calibrate")->required()->check(CLI::ExistingFile);
  cmd->add_option("--solver", opts->solvers, "all, or a comma list of nonlinear, linear, dt, meshik")->capture_default_str();
  cmd->add_option("--every", opts->every, "Held-out error and mesh checks on every Nth frame")->capture_default_str()->check(CLI::PositiveNumber);
  cmd->add_option("--max-frames", opts->max_frames, "Evaluate only the first N frames (0: all)")->capture_default_str();
  cmd->add_option("--rig-units", opts->rig_units, "Rig units mm|cm|m (default: guessed from the face's size)");
  cmd->add_flag("--progress", opts->progress, "Show progress on stderr (default: on a terminal)");
  cmd->add_flag("--json", *json, "Print JSON instead of a table");
  cmd->callback([opts, json, &exit_code] {
    const auto report = evaluate_take(*opts);
    if (*json) std::puts(report.dump(2).c_str());
    else print_take_evaluation(report);
    exit_code = 0;
  });
}

}  // namespace facecap::tools
