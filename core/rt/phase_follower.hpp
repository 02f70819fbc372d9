#pragma once
// Phase lock of a fixed-rate loop to a source on its own clock at the same rate: moves the
// loop's deadlines so that ticks fall a margin after frames arrive, so a frame waits as
// little as possible for its solve. The margin is the configured one plus a jitter margin
// that grows while frames arrive too late for their tick (one replaced by the next before
// a tick took it) and shrinks slowly otherwise, so a jittery source loses no frames to the
// beat between two clocks, and a steady one keeps the smallest wait.
#include <algorithm>
#include <cstdint>

namespace facecap::rt {

class PhaseFollower {
 public:
  PhaseFollower(int64_t period_ns, int64_t margin_ns) noexcept : period_ns_(period_ns), margin_ns_(margin_ns) {}

  // After a tick took a frame that waited waited_ns since it arrived; frames_replaced: the
  // source's running count of frames replaced before the loop took them. Returns the
  // correction for the next deadline: the wait beyond the margin, wrapped into
  // (-period/2, period/2], a fraction corrected per tick and at most period/16 (the rate
  // stays steady). RT-safe.
  int64_t correction(int64_t waited_ns, uint64_t frames_replaced) noexcept {
    // Replacements before the first frame taken are the source starting ahead of the loop.
    if (seen_replaced_ != kNone && frames_replaced != seen_replaced_)
      jitter_margin_ns_ = std::min(jitter_margin_ns_ + period_ns_ / kJitterStepDivisor, period_ns_ / kJitterCapDivisor);
    else
      jitter_margin_ns_ = std::max<int64_t>(jitter_margin_ns_ - period_ns_ / kJitterDecayDivisor, 0);
    seen_replaced_ = frames_replaced;
    max_jitter_margin_ns_ = std::max(max_jitter_margin_ns_, jitter_margin_ns_);

    int64_t error = (waited_ns - margin_ns_ - jitter_margin_ns_) % period_ns_;
    if (error < 0) error += period_ns_;
    if (error > period_ns_ / 2) error -= period_ns_;
    const int64_t limit = period_ns_ / kMaxStepDivisor;
    return std::clamp(int64_t(-kGain * double(error)), -limit, limit);
  }

  int64_t jitter_margin_ns() const noexcept { return jitter_margin_ns_; }
  int64_t max_jitter_margin_ns() const noexcept { return max_jitter_margin_ns_; }

 private:
  static constexpr double kGain = 0.1;
  static constexpr int64_t kMaxStepDivisor = 16;
  // A late frame raises the jitter margin by period/32; every other frame taken lowers it
  // by 1/128 of that, so it settles where about one frame in 128 still comes late, and is
  // gone within seconds once the jitter is.
  static constexpr int64_t kJitterStepDivisor = 32;
  static constexpr int64_t kJitterDecayDivisor = 32 * 128;
  // At most a quarter period: past that, waiting costs more latency than the rare frame
  // it saves (scheduling hiccups of a busy host) is worth.
  static constexpr int64_t kJitterCapDivisor = 4;
  static constexpr uint64_t kNone = ~uint64_t{0};

  int64_t period_ns_;
  int64_t margin_ns_;
  int64_t jitter_margin_ns_ = 0;
  int64_t max_jitter_margin_ns_ = 0;
  uint64_t seen_replaced_ = kNone;
};

}  // namespace facecap::rt
