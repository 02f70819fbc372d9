#pragma once
// The one interface every marker source implements (sim, replay, and the hardware
// drivers to come). Lifecycle: open() (allocate, load, check; may throw) -> start() ->
// take_frame() once per loop tick on the solve thread -> stop().
#include <atomic>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "core/frame.hpp"
#include "core/realtime.hpp"
#include "core/rt/latest_mailbox.hpp"
#include "drivers/api/state_line.hpp"

namespace facecap::drivers {

// What the source delivers, known after open().
struct SourceInfo {
  std::vector<std::string> labels;  // marker slots, in the order of MarkerFrame::markers
  std::string units;                // "mm", "cm", "m" or empty when unknown
  double nominal_rate_hz = 0.0;     // 0 when unknown
  bool own_clock = false;           // frames arrive on the source's schedule (devices, sim),
                                    // rather than when the loop asks (replay)
  bool unlabelled = false;          // the slots carry unnamed points (cameras, a NatNet cloud,
                                    // a replay of either): solved only through the labeller
};

// Counters an operator (and STATUS=) reads; all since start().
struct SourceHealth {
  uint64_t frames_delivered = 0;    // handed to the loop
  uint64_t frames_overwritten = 0;  // replaced by a newer frame before the loop took them
  uint64_t frames_late = 0;         // their time passed before they could be produced or taken
  uint64_t errors = 0;              // malformed input, device errors
  uint64_t foreign = 0;             // input from a sender other than the source's server, dropped unread
  uint64_t reconnects = 0;          // times a lost device or connection came back
  bool finished = false;            // no more frames will come (a replay that ended)
  // What the source is doing when an operator should know (waiting for a device, the last
  // gap in its frames); empty for sources that always just deliver.
  StateLine state;
};

struct SourceStart {
  int64_t epoch_ns = 0;   // CLOCK_MONOTONIC time of the loop's first tick: frame times count from here
  bool lockstep = false;  // hand every frame in order, as fast as the loop asks (replay)
  // > 0: SCHED_FIFO priority (tried) for the driver's thread: a receive thread takes each
  // frame off the network or device as it arrives, and a simulated device keeps its own
  // timing, however loaded the host. A failure leaves ordinary scheduling (the solve
  // thread reports the same failure).
  int thread_priority = 0;
};

// A driver's own thread, running `run` at start.thread_priority (SCHED_FIFO, tried) when
// that is above 0. Not RT-safe.
template <typename Run>
std::thread start_driver_thread(const SourceStart& start, Run run) {
  return std::thread([priority = start.thread_priority, run = std::move(run)]() mutable {
    if (priority > 0) apply_realtime({.fifo = true, .priority = priority});
    run();
  });
}

class MarkerSource {
 public:
  virtual ~MarkerSource() = default;

  // Loads files, checks devices, sizes every buffer. Not RT-safe; throws Error.
  virtual void open() = 0;
  // Valid after open().
  virtual const SourceInfo& info() const noexcept = 0;
  // Begins producing frames. Not RT-safe; throws Error.
  virtual void start(const SourceStart& start) = 0;
  // Stops producing and joins any thread. Not RT-safe; idempotent.
  virtual void stop() noexcept = 0;

  // Copies the newest frame due by now_ns that the loop has not had yet into `out`
  // (whose markers were reserved for info().labels.size()); false when there is none.
  // Never blocks. RT-safe.
  virtual bool take_frame(int64_t now_ns, MarkerFrame& out) noexcept = 0;

  // For logs and STATUS ("sim builtin 48+4 markers at 120 Hz"). Not RT-safe.
  virtual std::string description() const = 0;
  // Safe from any thread. RT-safe.
  virtual SourceHealth health() const noexcept = 0;
  // No frame will come any more (a replay that ended). RT-safe.
  bool finished() const noexcept { return health().finished; }
  // Every frame the source will deliver, when it holds them all from open() (a replay's
  // take, in its window): what facecapd checks before it starts (the units); empty for
  // live sources. Valid after open(). RT-safe.
  virtual std::span<const MarkerFrame> recorded_frames() const noexcept { return {}; }
};

// Base for sources whose own thread produces frames (simulated or network devices):
// the thread fills mailbox_.write_buffer() and publishes; the loop takes the newest.
class MailboxSource : public MarkerSource {
 public:
  bool take_frame(int64_t now_ns, MarkerFrame& out) noexcept override;
  SourceHealth health() const noexcept override;

 protected:
  // Sizes the mailbox for frames with these labels. Not RT-safe.
  void configure_mailbox(const std::vector<std::string>& labels);

  std::unique_ptr<rt::LatestMailbox<MarkerFrame>> mailbox_;
  std::atomic<uint64_t> delivered_{0};
  std::atomic<uint64_t> late_{0};
  std::atomic<uint64_t> errors_{0};
  std::atomic<uint64_t> foreign_{0};
  std::atomic<uint64_t> reconnects_{0};
  std::atomic<bool> finished_{false};
  SharedStateLine state_;  // written by the source's own thread
};

}  // namespace facecap::drivers
