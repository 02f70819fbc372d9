#pragma once
// The one interface every output implements (shared memory, the recorder, and the network
// outputs), as every marker source implements drivers/api/marker_source.hpp. Lifecycle:
// construction (allocates every buffer, creates files and segments, starts its thread;
// may throw) -> offer() once per solved frame on the solve thread -> stop().
//
// A sink is either inline (offer() does the work at once and is wait-free: shared memory)
// or queued (offer() copies the frame into a pre-sized slot of a bounded SPSC queue that
// its own thread drains: the recorder; network outputs share one I/O thread). Either way
// offer() never waits: when a sink cannot take a frame it drops it and counts the drop.
#include <cstdint>
#include <span>
#include <string>
#include <string_view>

#include "core/frame.hpp"
#include "core/latency_histogram.hpp"

namespace facecap::outputs {

// Counters an operator (STATUS, the stats file) reads; all since the sink was made.
struct SinkHealth {
  uint64_t offered = 0;    // frames offered by the loop
  uint64_t delivered = 0;  // frames that reached the destination (published, written, sent)
  uint64_t dropped = 0;    // frames offered but not delivered (queue full, write failed after queuing)
  uint64_t errors = 0;     // failures of the destination (disk full, socket errors)
  uint64_t bytes = 0;      // bytes sent (network outputs; 0 where not counted)
  bool failed = false;     // the sink gave up after an error (a stopped recording); the loop goes on
};

class OutputSink {
 public:
  virtual ~OutputSink() = default;

  // The output table's name of this sink ("shm", "recording"). RT-safe.
  virtual std::string_view name() const noexcept = 0;
  // For logs and STATUS ("shared memory /facecap, 8 slots, with vertices"). Not RT-safe.
  virtual std::string description() const = 0;
  // Whether the sink reads SolvedFrame::vertices: the loop solves vertices into its frame
  // only when some sink does. RT-safe.
  virtual bool wants_vertices() const noexcept = 0;

  // Hands one solved frame, and the marker frame it was solved from, to the sink. Never
  // waits, allocates, locks, throws or logs. RT-safe.
  virtual void offer(const MarkerFrame& markers, const SolvedFrame& solved) noexcept = 0;
  // Whether the sink wants the solve's state as it is before the next frame it is offered
  // (a recording's first frame, so that a re-solve can start where the live solve was).
  // RT-safe.
  virtual bool wants_start_state() const noexcept { return false; }
  // That state (encoded: pipeline/pipeline_state.hpp), just before the next frame is
  // solved, when wants_start_state(). Copied into storage sized beforehand; dropped when it
  // does not fit. RT-safe.
  virtual void offer_start_state(std::span<const char> /*state*/) noexcept {}
  // Once per loop tick, with or without a frame (heartbeats). RT-safe.
  virtual void tick(int64_t /*now_ns*/) noexcept {}
  // Whether offer() would take a frame now rather than drop it. A lockstep loop (not real
  // time) waits for it instead of dropping. RT-safe.
  virtual bool ready() noexcept { return true; }
  // Whether dropping is how this sink works (a live preview that keeps the newest frame
  // for a slow viewer), not a loss: its drops are shown but not warned about. RT-safe.
  virtual bool drops_by_design() const noexcept { return false; }

  // Safe from any thread. RT-safe.
  virtual SinkHealth health() const noexcept = 0;
  // For a sink that delivers on its own thread: from a frame's arrival at facecapd
  // (MarkerFrame::receive_time_ns) to its delivery (the last datagram sent), per frame
  // delivered; nullptr for a sink whose delivery the loop's own latency covers. Any thread.
  virtual const LatencyHistogram* delivery_latency() const noexcept { return nullptr; }
  // Delivers what is queued, closes, joins its thread. Idempotent. Not RT-safe; throws
  // Error when what was queued could not be delivered (the recording's last write).
  virtual void stop() = 0;
};

}  // namespace facecap::outputs
