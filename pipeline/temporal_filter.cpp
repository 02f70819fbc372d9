#include "pipeline/temporal_filter.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

#include "core/time.hpp"

namespace facecap::pipeline {
namespace {

// The smoothing factor of a first-order low-pass at `cutoff_hz` over `dt_s`.
double smoothing(double cutoff_hz, double dt_s) noexcept {
  return 1.0 / (1.0 + 1.0 / (2.0 * std::numbers::pi * cutoff_hz * dt_s));
}

}  // namespace

OneEuroFilter::OneEuroFilter(Eigen::Index rows, Eigen::Index channels, OneEuroParams params)
    : params_(params),
      state_{.raw = Eigen::MatrixXd::Zero(rows, channels),
             .filtered = Eigen::MatrixXd::Zero(rows, channels),
             .speed = Eigen::MatrixXd::Zero(rows, channels),
             .live = std::vector<uint8_t>(std::size_t(channels), 0)} {}

void OneEuroFilter::reset() noexcept {
  std::fill(state_.live.begin(), state_.live.end(), uint8_t{0});
  state_.started = false;
}

OneEuroFilter::State OneEuroFilter::make_state() const { return state_; }

bool OneEuroFilter::save(State& state) const noexcept {
  if (!same_shape(state)) return false;
  state = state_;  // same sizes: no allocation
  return true;
}

bool OneEuroFilter::restore(const State& state) noexcept {
  if (!same_shape(state)) return false;
  state_ = state;
  return true;
}

bool OneEuroFilter::same_shape(const State& state) const noexcept {
  const auto fits = [&](const Eigen::MatrixXd& m) { return m.rows() == rows() && m.cols() == channels(); };
  return fits(state.raw) && fits(state.filtered) && fits(state.speed) && state.live.size() == state_.live.size();
}

void OneEuroFilter::filter(Eigen::Ref<Eigen::MatrixXd> values, std::span<const uint8_t> present, int64_t time_ns) noexcept {
  if (values.rows() != rows() || values.cols() != channels()) return;
  if (state_.started && time_ns <= state_.last_ns) reset();
  const double dt_s = state_.started ? double(time_ns - state_.last_ns) / double(kNsPerSecond) : 0.0;
  state_.started = true;
  state_.last_ns = time_ns;
  const double speed_a = dt_s > 0.0 ? smoothing(params_.d_cutoff_hz, dt_s) : 1.0;
  for (Eigen::Index n = 0; n < channels(); ++n) {
    const auto k = std::size_t(n);
    auto x = values.col(n);
    if ((!present.empty() && !present[k]) || !x.allFinite()) {
      state_.live[k] = 0;
      continue;
    }
    if (!state_.live[k]) {  // first frame of the channel: nothing to filter against
      state_.raw.col(n) = x;
      state_.filtered.col(n) = x;
      state_.speed.col(n).setZero();
      state_.live[k] = 1;
      continue;
    }
    state_.speed.col(n) += speed_a * ((x - state_.raw.col(n)) / dt_s - state_.speed.col(n));
    const double cutoff_hz = params_.min_cutoff_hz + params_.beta * state_.speed.col(n).norm();
    state_.raw.col(n) = x;
    state_.filtered.col(n) += smoothing(cutoff_hz, dt_s) * (x - state_.filtered.col(n));
    x = state_.filtered.col(n);
  }
}

}  // namespace facecap::pipeline
