#pragma once
// The grid of absolute CLOCK_MONOTONIC deadlines a fixed-rate loop sleeps to, and the
// one way a tick that runs past its period is counted: the loop skips the slots already
// gone and stays on the grid rather than running late ticks back to back. Shared by the
// solve loop and `facecap loopcheck`, so that both count missed deadlines alike.
#include <cstdint>

namespace facecap::rt {

struct TickOutcome {
  bool missed = false;        // the work ended past the next deadline
  bool started_late = false;  // missed, though the work took no longer than a period
  uint64_t skipped = 0;       // slots given up to get back on the grid
};

class DeadlineGrid {
 public:
  DeadlineGrid(int64_t first_deadline_ns, int64_t period_ns) noexcept
      : deadline_ns_(first_deadline_ns), period_ns_(period_ns) {}

  int64_t deadline_ns() const noexcept { return deadline_ns_; }
  int64_t period_ns() const noexcept { return period_ns_; }

  // After a tick that woke at wake_ns and ended at end_ns: moves to the next deadline
  // (shifted by correction_ns, for phase lock) past end_ns. RT-safe.
  TickOutcome advance(int64_t wake_ns, int64_t end_ns, int64_t correction_ns = 0) noexcept {
    deadline_ns_ += period_ns_ + correction_ns;
    TickOutcome outcome;
    if (end_ns > deadline_ns_) {
      outcome.missed = true;
      outcome.started_late = end_ns - wake_ns <= period_ns_;
      outcome.skipped = uint64_t((end_ns - deadline_ns_) / period_ns_ + 1);
      deadline_ns_ += int64_t(outcome.skipped) * period_ns_;
    }
    return outcome;
  }

 private:
  int64_t deadline_ns_;
  int64_t period_ns_;
};

}  // namespace facecap::rt
