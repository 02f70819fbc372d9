#pragma once
// What an output learns when it is made: what is solved and how (the recording header the
// pipeline builds: rig, shapes, calibration, source markers and units, solver settings)
// and the loop's figures. Not real-time code.
#include <cstdint>

#include "formats/recording.hpp"

namespace facecap::outputs {

struct SinkContext {
  formats::RecordingHeader header;  // pipeline::make_recording_header
  uint32_t vertex_count = 0;        // the rig's vertices (SolvedFrame::vertices when solved)
  double loop_rate_hz = 0.0;        // the solve loop's tick rate
};

}  // namespace facecap::outputs
