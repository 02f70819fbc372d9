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
// frames' nominal rate (0 when unknown; a loop's: recorded_rate_hz); solver_settings: the
// [solver] section as TOML (pipeline::solve_settings_toml).
formats::RecordingHeader make_recording_header(const Rig& rig, const align::Calibration& calibration,
                                               const SourceDescription& source, std::string source_description,
                                               double rate_hz, std::string solver_settings);

// The nominal rate of the frames a solve loop records. Each recorded frame is a source
// frame with its own source_time_ns (the source's clock: what gives the frames their
// times), so the rate is the source's: in lockstep every frame is solved; at a fixed rate
// each source frame is solved at most once and at most one per tick, so a 60 Hz source
// under a 120 Hz loop records 60 Hz and a 240 Hz source under a 120 Hz loop every other
// frame, 120 Hz. 0 (unknown: readers take the rate from the frames' times) when the
// source does not state its rate.
double recorded_rate_hz(double source_rate_hz, double loop_rate_hz, bool lockstep);

}  // namespace facecap::pipeline
