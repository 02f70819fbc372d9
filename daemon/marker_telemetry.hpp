#pragma once
// What the solve thread saw of each source marker slot, for the capture quality: how often
// the marker was present, how much it jitters and how far it sits from the solved surface.
// The jitter comes from the data: the second difference of the marker's raw position over
// three consecutive frames, p(t) - 2 p(t-1) + p(t-2), is the capture noise (times sqrt 6
// per coordinate) plus the face's acceleration times dt^2, which at capture rates is a few
// hundredths of a millimetre. The solve thread records each frame (record(): RT-safe, no
// allocation, no lock); the supervisor reads snapshots at any time and compares two.
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <memory>
#include <vector>

#include <Eigen/Core>

#include "core/frame.hpp"

namespace facecap::daemon {

// Per slot, summed since the telemetry was made.
struct MarkerCounts {
  uint64_t frames = 0;                    // solved frames recorded
  std::vector<uint64_t> present;          // frames the slot was present (and finite)
  std::vector<uint64_t> jitter_samples;   // second differences taken
  std::vector<double> jitter_sum;         // of |second difference|, source units
  std::vector<uint64_t> residual_samples; // fit residuals measured (bound and present)
  std::vector<double> residual_sum_mm;

  // The counts of the window from `earlier` to this one.
  MarkerCounts since(const MarkerCounts& earlier) const;
};

// A window's figures for one slot.
struct MarkerFigures {
  double present_fraction = 0.0;  // of the window's solved frames
  double noise = std::numeric_limits<double>::quiet_NaN();        // per coordinate, source units; NaN without samples
  double residual_mm = std::numeric_limits<double>::quiet_NaN();  // mean fit residual; NaN without samples
};

// The figures per slot over a window (from MarkerCounts::since).
std::vector<MarkerFigures> marker_figures(const MarkerCounts& window);

class MarkerTelemetry {
 public:
  explicit MarkerTelemetry(std::size_t slots);  // Not RT-safe.

  // One solved frame and the marker frame it was solved from. Solve thread; RT-safe.
  void record(const MarkerFrame& markers, const SolvedFrame& solved) noexcept;
  // The counts so far. Any thread (values written by the solve thread may be a frame apart).
  MarkerCounts snapshot() const;

 private:
  struct Slot {
    std::atomic<uint64_t> present{0}, jitter_samples{0}, residual_samples{0};
    std::atomic<double> jitter_sum{0.0}, residual_sum_mm{0.0};
  };
  std::size_t slots_;
  std::unique_ptr<Slot[]> counts_;
  std::atomic<uint64_t> frames_{0};
  // Solve thread only: the last two frames' positions (NaN when missing) and frame numbers.
  Eigen::Matrix3Xd previous_, before_previous_;
  int64_t previous_frame_no_ = -2, before_previous_frame_no_ = -2;
};

}  // namespace facecap::daemon
