#pragma once
// The configuration's [calibration] and [solver] sections as the pipeline takes them: the
// one translation facecapd and the tools share, so that a live solve and an offline one
// with the same configuration are the same solve.
#include <string>
#include <string_view>

#include "config/daemon_config.hpp"
#include "pipeline/calibration.hpp"
#include "pipeline/solve_pipeline.hpp"

namespace facecap::pipeline {

SolveSettings solve_settings(const config::DaemonConfig& config);
CalibrationSpec calibration_spec(const config::DaemonConfig& config);

// Whether a configuration key is one a solve depends on: the [solver] section and
// calibration.stabilise_head, label_markers and max_marker_speed_mm_s. Only these matter to
// `facecap solve` and `eval`.
bool is_solve_setting(std::string_view key_path);

// The solve settings' keys at their values in `config`, as TOML: what a recording stores
// (RecordingHeader::solver_settings) so that its solve can be reproduced.
std::string solve_settings_toml(const config::DaemonConfig& config);

}  // namespace facecap::pipeline
