#include "pipeline/settings.hpp"

#include <fmt/format.h>

#include "config/schema.hpp"

namespace facecap::pipeline {

SolveSettings solve_settings(const config::DaemonConfig& config) {
  const config::SolverSection& s = config.solver;
  SolveSettings settings;
  settings.method = s.method;
  settings.params.alpha = s.alpha;
  settings.params.mu = s.mu;
  settings.params.beta = s.beta;
  settings.params.weight_refinements = int(s.weight_refinements);
  settings.params.collision_region = s.collisions == "none"   ? CollisionRegion::kNone
                                     : s.collisions == "face" ? CollisionRegion::kFace
                                                              : CollisionRegion::kLips;
  settings.params.collision_epsilon = s.collision_epsilon;
  settings.params.collision_max_pins = int(s.collision_max_pins);
  settings.params.active_weight = s.active_weight;
  settings.mapper.stabilise_head = config.calibration.stabilise_head;
  settings.label_markers = config.calibration.label_markers;
  return settings;
}

CalibrationSpec calibration_spec(const config::DaemonConfig& config) {
  return {.file = config.calibration.file,
          .face_markers = int(config.calibration.face_markers),
          .head_markers = int(config.calibration.head_markers)};
}

bool is_solve_setting(std::string_view key_path) {
  return key_path.starts_with("solver.") || key_path == "calibration.stabilise_head" ||
         key_path == "calibration.label_markers";
}

std::string solve_settings_toml(const config::DaemonConfig& config) {
  std::string out;
  std::string_view section = "\x01";
  for (const config::KeySpec& key : config::config_schema()) {
    if (!is_solve_setting(key.path)) continue;
    if (key.section() != section) {
      section = key.section();
      out += fmt::format("{}[{}]\n", out.empty() ? "" : "\n", section);
    }
    out += fmt::format("{} = {}\n", key.name(), config::format_value(config::get_value(key, config)));
  }
  return out;
}

}  // namespace facecap::pipeline
