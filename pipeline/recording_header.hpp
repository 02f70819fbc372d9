#pragma once
// The one recording header (.fcrec HEAD) for a solve: facecapd's recorder and
// `facecap solve` write the same fields, so a recording says how to reproduce its solved
// frames: the rig, the calibration (as a profile), the source's markers and units, and
// the [solver] settings. Not real-time code.
#include <string>

#include "formats/recording.hpp"
#include "pipeline/solve_pipeline.hpp"
#include "solver/align/calibration.hpp"
#include "solver/rig.hpp"

namespace facecap::pipeline {

// source_description: "sim builtin ...", "facecap solve of take.trc", ...; rate_hz: the
// frames' nominal rate (0 when unknown); solver_settings: the [solver] section as TOML
// (pipeline::solve_settings_toml).
formats::RecordingHeader make_recording_header(const Rig& rig, const align::Calibration& calibration,
                                               const SourceDescription& source, std::string source_description,
                                               double rate_hz, std::string solver_settings);

}  // namespace facecap::pipeline
