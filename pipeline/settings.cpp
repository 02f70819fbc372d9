#include "pipeline/settings.hpp"

#include <fmt/format.h>

#include "config/schema.hpp"

namespace facecap::pipeline {

SolveSettings solve_settings(const config::DaemonConfig& config) {
  SolveSettings settings;
  settings.method = config.solver.method;
  settings.params = config.solver;  // the section is the solver's parameters
  settings.mapper.stabilise_head = config.calibration.stabilise_head;
  return settings;
}

CalibrationSpec calibration_spec(const config::DaemonConfig& config) {
  return {.file = config.calibration.file,
          .face_markers = int(config.calibration.face_markers),
          .head_markers = int(config.calibration.head_markers)};
}

bool is_solve_setting(std::string_view key_path) {
  return key_path.starts_with("solver.") || key_path == "calibration.stabilise_head";
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
