#pragma once
// What an output learns when it is made: what is solved and how (the recording header the
// pipeline builds: rig, shapes, calibration, source markers and units, solver settings)
// and the loop's figures. Not real-time code.
#include <cstddef>
#include <cstdint>

#include "formats/recording.hpp"

namespace boost::asio {
class io_context;
}

namespace facecap::outputs {

struct SinkContext {
  formats::RecordingHeader header;  // pipeline::make_recording_header
  uint32_t vertex_count = 0;        // the rig's vertices (SolvedFrame::vertices when solved)
  double loop_rate_hz = 0.0;        // the solve loop's tick rate
  // The solve's encoded state (pipeline::SolvePipeline::encoded_state_size): the room a
  // recording keeps to store it before its first frame.
  std::size_t pipeline_state_bytes = 0;
  // facecapd's one I/O thread (daemon/io_thread.hpp), where network outputs do their
  // sending; it runs from before the loop's first frame until after every sink stopped.
  boost::asio::io_context* io = nullptr;
};

}  // namespace facecap::outputs
