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
      raw_(Eigen::MatrixXd::Zero(rows, channels)),
      filtered_(Eigen::MatrixXd::Zero(rows, channels)),
      speed_(Eigen::MatrixXd::Zero(rows, channels)),
      live_(std::size_t(channels), 0) {}

void OneEuroFilter::reset() noexcept {
  std::fill(live_.begin(), live_.end(), uint8_t{0});
  started_ = false;
}

OneEuroFilter::State OneEuroFilter::make_state() const { return {raw_, filtered_, speed_, live_, last_ns_, started_}; }

bool OneEuroFilter::save(State& state) const noexcept {
  if (!same_shape(state)) return false;
  state.raw = raw_;  // same sizes: no allocation
  state.filtered = filtered_;
  state.speed = speed_;
  state.live = live_;
  state.last_ns = last_ns_;
  state.started = started_;
  return true;
}

bool OneEuroFilter::restore(const State& state) noexcept {
  if (!same_shape(state)) return false;
  raw_ = state.raw;
  filtered_ = state.filtered;
  speed_ = state.speed;
  live_ = state.live;
  last_ns_ = state.last_ns;
  started_ = state.started;
  return true;
}

bool OneEuroFilter::same_shape(const State& state) const noexcept {
  const auto fits = [&](const Eigen::MatrixXd& m) { return m.rows() == rows() && m.cols() == channels(); };
  return fits(state.raw) && fits(state.filtered) && fits(state.speed) && state.live.size() == live_.size();
}

void OneEuroFilter::filter(Eigen::Ref<Eigen::MatrixXd> values, std::span<const uint8_t> present, int64_t time_ns) noexcept {
  if (values.rows() != rows() || values.cols() != channels()) return;
  if (started_ && time_ns <= last_ns_) reset();
  const double dt_s = started_ ? double(time_ns - last_ns_) / double(kNsPerSecond) : 0.0;
  started_ = true;
  last_ns_ = time_ns;
  const double speed_a = dt_s > 0.0 ? smoothing(params_.d_cutoff_hz, dt_s) : 1.0;
  for (Eigen::Index n = 0; n < channels(); ++n) {
    const auto k = std::size_t(n);
    auto x = values.col(n);
    if ((!present.empty() && !present[k]) || !x.allFinite()) {
      live_[k] = 0;
      continue;
    }
    if (!live_[k]) {  // first frame of the channel: nothing to filter against
      raw_.col(n) = x;
      filtered_.col(n) = x;
      speed_.col(n).setZero();
      live_[k] = 1;
      continue;
    }
    speed_.col(n) += speed_a * ((x - raw_.col(n)) / dt_s - speed_.col(n));
    const double cutoff_hz = params_.min_cutoff_hz + params_.beta * speed_.col(n).norm();
    raw_.col(n) = x;
    filtered_.col(n) += smoothing(cutoff_hz, dt_s) * (x - filtered_.col(n));
    x = filtered_.col(n);
  }
}

}  // namespace facecap::pipeline
