#include "pipeline/settings.hpp"

#include <fmt/format.h>

#include "config/schema.hpp"

namespace facecap::pipeline {

namespace {

// filter.mode decided for `context`: on or off.
config::FilterMode filter_mode_in(config::FilterMode mode, SolveContext context) {
  if (mode != config::FilterMode::kLive) return mode;
  return context == SolveContext::kLive ? config::FilterMode::kOn : config::FilterMode::kOff;
}

}  // namespace

SolveSettings solve_settings(const config::DaemonConfig& config, SolveContext context) {
  SolveSettings settings;
  settings.method = config.solver.method;
  settings.params = config.solver;  // the section is the solver's parameters
  settings.mapper.stabilise_head = config.calibration.stabilise_head;
  settings.label_markers = config.calibration.label_markers;
  settings.mapper.max_marker_speed_mm_s = config.calibration.max_marker_speed_mm_s;
  settings.marker_consistency_mm = config.calibration.marker_consistency_mm;
  const config::FilterSection& filter = config.filter;
  settings.filter.targets = filter_mode_in(filter.mode, context) == config::FilterMode::kOn;
  settings.filter.weights = settings.filter.targets && filter.weights;
  settings.filter.target_params = {.min_cutoff_hz = filter.min_cutoff_hz, .beta = filter.beta, .d_cutoff_hz = filter.d_cutoff_hz};
  settings.filter.weight_params = {.min_cutoff_hz = filter.min_cutoff_hz, .beta = filter.weights_beta,
                                   .d_cutoff_hz = filter.d_cutoff_hz};
  return settings;
}

CalibrationSpec calibration_spec(const config::DaemonConfig& config) {
  return {.file = config.calibration.file,
          .face_markers = int(config.calibration.face_markers),
          .head_markers = int(config.calibration.head_markers)};
}

bool is_solve_setting(std::string_view key_path) {
  return key_path.starts_with("solver.") || key_path.starts_with("filter.") || key_path == "calibration.stabilise_head" ||
         key_path == "calibration.label_markers" ||
         key_path == "calibration.max_marker_speed_mm_s" || key_path == "calibration.marker_consistency_mm";
}

std::string solve_settings_toml(const config::DaemonConfig& config_as_given, SolveContext context) {
  config::DaemonConfig config = config_as_given;
  config.filter.mode = filter_mode_in(config.filter.mode, context);
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
