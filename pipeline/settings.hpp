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

// Where a solve runs: facecapd solving a source as it comes, or a tool solving a take.
// filter.mode = "live" filters the first and not the second.
enum class SolveContext : uint8_t { kLive, kOffline };

SolveSettings solve_settings(const config::DaemonConfig& config, SolveContext context);
CalibrationSpec calibration_spec(const config::DaemonConfig& config);

// Whether a configuration key is one a solve depends on: the [solver] and [filter] sections
// and calibration.stabilise_head, label_markers and max_marker_speed_mm_s. Only these matter
// to `facecap solve` and `eval`.
bool is_solve_setting(std::string_view key_path);

// The solve settings' keys at their values in `config`, as TOML: what a recording stores
// (RecordingHeader::solver_settings) so that its solve can be reproduced. filter.mode is
// written as what it was in `context` ("on" or "off"), so that solving the recording again
// offline filters as the recording's solve did.
std::string solve_settings_toml(const config::DaemonConfig& config, SolveContext context);

}  // namespace facecap::pipeline
