#include "daemon/marker_telemetry.hpp"

#include <cmath>
#include <limits>
#include <numbers>

namespace facecap::daemon {
namespace {

// E|d| for d = p(t) - 2 p(t-1) + p(t-2) of independent Gaussian noise with standard
// deviation sigma per coordinate: d has sqrt(6) sigma per coordinate, and the mean length
// of a 3-D Gaussian vector is 2 sqrt(2 / pi) times its per-coordinate deviation.
const double kMeanSecondDifferencePerSigma = std::sqrt(6.0) * 2.0 * std::sqrt(2.0 / std::numbers::pi);

template <typename T>
void add(std::atomic<T>& counter, T value) noexcept {
  counter.store(counter.load(std::memory_order_relaxed) + value, std::memory_order_relaxed);  // one writer
}

}  // namespace

MarkerCounts MarkerCounts::since(const MarkerCounts& earlier) const {
  MarkerCounts out = *this;
  if (earlier.present.size() != present.size()) return out;  // a different source: all of this one
  out.frames -= earlier.frames;
  for (std::size_t k = 0; k < present.size(); ++k) {
    out.present[k] -= earlier.present[k];
    out.jitter_samples[k] -= earlier.jitter_samples[k];
    out.jitter_sum[k] -= earlier.jitter_sum[k];
    out.residual_samples[k] -= earlier.residual_samples[k];
    out.residual_sum_mm[k] -= earlier.residual_sum_mm[k];
  }
  return out;
}

std::vector<MarkerFigures> marker_figures(const MarkerCounts& w) {
  std::vector<MarkerFigures> out(w.present.size());
  for (std::size_t k = 0; k < out.size(); ++k) {
    if (w.frames > 0) out[k].present_fraction = double(w.present[k]) / double(w.frames);
    if (w.jitter_samples[k] > 0) out[k].noise = w.jitter_sum[k] / double(w.jitter_samples[k]) / kMeanSecondDifferencePerSigma;
    if (w.residual_samples[k] > 0) out[k].residual_mm = w.residual_sum_mm[k] / double(w.residual_samples[k]);
  }
  return out;
}

MarkerTelemetry::MarkerTelemetry(std::size_t slots)
    : slots_(slots),
      counts_(std::make_unique<Slot[]>(slots)),
      previous_(Eigen::Matrix3Xd::Constant(3, Eigen::Index(slots), std::numeric_limits<double>::quiet_NaN())),
      before_previous_(previous_) {}

void MarkerTelemetry::record(const MarkerFrame& markers, const SolvedFrame& solved) noexcept {
  add(frames_, uint64_t{1});
  // Second differences only over three consecutive source frames (none across a gap).
  const bool consecutive = markers.frame_no == previous_frame_no_ + 1 && previous_frame_no_ == before_previous_frame_no_ + 1;
  const std::size_t n = std::min(slots_, markers.markers.size());
  for (std::size_t k = 0; k < n; ++k) {
    Slot& slot = counts_[k];
    const Marker& m = markers.markers[k];
    const auto col = Eigen::Index(k);
    const bool present = m.present() && m.position.allFinite();
    if (present) {
      add(slot.present, uint64_t{1});
      if (consecutive && previous_.col(col).allFinite() && before_previous_.col(col).allFinite()) {
        add(slot.jitter_samples, uint64_t{1});
        add(slot.jitter_sum, (m.position - 2.0 * previous_.col(col) + before_previous_.col(col)).norm());
      }
    }
    before_previous_.col(col) = previous_.col(col);
    previous_.col(col) = present ? m.position : Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN());
    if (col < solved.marker_residual_mm.size() && !std::isnan(solved.marker_residual_mm[col])) {
      add(slot.residual_samples, uint64_t{1});
      add(slot.residual_sum_mm, double(solved.marker_residual_mm[col]));
    }
  }
  before_previous_frame_no_ = previous_frame_no_;
  previous_frame_no_ = markers.frame_no;
}

MarkerCounts MarkerTelemetry::snapshot() const {
  MarkerCounts out;
  out.frames = frames_.load(std::memory_order_relaxed);
  out.present.resize(slots_);
  out.jitter_samples.resize(slots_);
  out.jitter_sum.resize(slots_);
  out.residual_samples.resize(slots_);
  out.residual_sum_mm.resize(slots_);
  for (std::size_t k = 0; k < slots_; ++k) {
    const Slot& slot = counts_[k];
    out.present[k] = slot.present.load(std::memory_order_relaxed);
    out.jitter_samples[k] = slot.jitter_samples.load(std::memory_order_relaxed);
    out.jitter_sum[k] = slot.jitter_sum.load(std::memory_order_relaxed);
    out.residual_samples[k] = slot.residual_samples.load(std::memory_order_relaxed);
    out.residual_sum_mm[k] = slot.residual_sum_mm.load(std::memory_order_relaxed);
  }
  return out;
}

}  // namespace facecap::daemon
