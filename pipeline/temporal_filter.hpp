#pragma once
// The One Euro filter (Casiez, Roussel and Vogel, "1 Euro Filter: A Simple Speed-based
// Low-pass Filter for Noisy Input in Interactive Systems", CHI 2012): a first-order
// low-pass whose cutoff rises with the signal's speed, so that a still face loses its
// noise and a moving one keeps up. Causal: a frame's output depends on it and earlier
// frames only. Per channel (a marker's 3 coordinates, or one weight):
//   dt      = time since the previous frame
//   v       = (x - x_prev_raw) / dt, low-passed at d_cutoff_hz            (its speed)
//   cutoff  = min_cutoff_hz + beta |v|                                     (|v|: norm over the channel's rows)
//   x_hat   = x_hat_prev + a (x - x_hat_prev),  a = 1 / (1 + 1 / (2 pi cutoff dt))
// What the parameters trade: min_cutoff_hz is the cutoff at rest (lower: less jitter on a
// still face, more lag on slow motion, about 1 / (2 pi min_cutoff_hz) seconds); beta is
// how fast the cutoff rises with speed (higher: less lag in fast motion, more of the noise
// through while moving); d_cutoff_hz smooths the speed estimate itself (rarely changed).
#include <cstdint>
#include <span>
#include <vector>

#include <Eigen/Core>

namespace facecap::pipeline {

struct OneEuroParams {
  double min_cutoff_hz = 1.0;
  double beta = 0.0;  // Hz per unit of speed (per value unit per second)
  double d_cutoff_hz = 1.0;
};

// Filters a D x N matrix of N channels (columns) frame by frame, in place. Sized at
// construction; filter() neither allocates nor throws.
class OneEuroFilter {
 public:
  // rows: D (3 for points, 1 for scalars); channels: N. Not RT-safe.
  OneEuroFilter(Eigen::Index rows, Eigen::Index channels, OneEuroParams params);

  // values: D x N, this frame's; present: N (empty: all present). A channel that is
  // absent, or not finite, is left as it is and starts afresh (unfiltered) when it comes
  // back, so that nothing glides from where a marker was before an occlusion. A frame
  // whose time does not advance past the previous one (a replay looping back, sources
  // without timestamps) passes unfiltered and restarts every channel. RT-safe.
  void filter(Eigen::Ref<Eigen::MatrixXd> values, std::span<const uint8_t> present, int64_t time_ns) noexcept;
  // Every channel starts afresh at the next frame. RT-safe.
  void reset() noexcept;

  // What the filter carries from one frame to the next.
  struct State {
    Eigen::MatrixXd raw, filtered, speed;  // D x N
    std::vector<uint8_t> live;             // N: the channel was filtered last frame
    int64_t last_ns = 0;
    bool started = false;
  };
  // A state sized for this filter. Not RT-safe.
  State make_state() const;
  // Copies the filter's state into `state`; false (and nothing copied) when it was not
  // sized for this filter. RT-safe.
  bool save(State& state) const noexcept;
  // Continues from `state`; false (and nothing changed) when its sizes are not this
  // filter's. RT-safe.
  bool restore(const State& state) noexcept;

  Eigen::Index rows() const noexcept { return state_.filtered.rows(); }
  Eigen::Index channels() const noexcept { return state_.filtered.cols(); }

 private:
  bool same_shape(const State& state) const noexcept;

  OneEuroParams params_;
  State state_;  // raw, filtered, speed: the previous frame's input, output and filtered speed
};

}  // namespace facecap::pipeline
