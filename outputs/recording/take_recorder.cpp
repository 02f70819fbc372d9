#include "outputs/recording/take_recorder.hpp"

#include <fmt/format.h>

#include "core/error.hpp"
#include "core/log.hpp"

namespace facecap::outputs {
namespace {

void add(SinkHealth& total, const SinkHealth& h) {
  total.offered += h.offered;
  total.delivered += h.delivered;
  total.dropped += h.dropped;
  total.errors += h.errors;
  total.failed = total.failed || h.failed;
}

}  // namespace

TakeRecorder::TakeRecorder(Eigen::Index vertex_count, bool record_vertices, std::size_t start_state_bytes)
    : vertex_count_(vertex_count), record_vertices_(record_vertices), start_state_bytes_(start_state_bytes) {}

TakeRecorder::~TakeRecorder() {
  try {
    stop();
  } catch (const std::exception& e) {
    spdlog::error("recording: {}", e.what());
  }
}

std::string TakeRecorder::description() const {
  const std::lock_guard lock(mutex_);
  if (live_ && !stopping_) return live_->description();
  return last_file_.empty() ? std::string("recording: takes started on request")
                            : fmt::format("recording: between takes (last {})", last_file_.string());
}

void TakeRecorder::tick(int64_t /*now_ns*/) noexcept { handoff_.adopt(current_); }

bool TakeRecorder::wants_start_state() const noexcept {
  return current_ && current_->recorder && current_->recorder->wants_start_state();
}

void TakeRecorder::offer_start_state(std::span<const char> state) noexcept {
  if (current_ && current_->recorder) current_->recorder->offer_start_state(state);
}

void TakeRecorder::offer(const MarkerFrame& markers, const SolvedFrame& solved) noexcept {
  if (current_ && current_->recorder) current_->recorder->offer(markers, solved);
}

bool TakeRecorder::ready() noexcept { return !current_ || !current_->recorder || current_->recorder->ready(); }

SinkHealth TakeRecorder::health() const noexcept {
  const std::lock_guard lock(mutex_);
  SinkHealth h = finished_;
  if (live_) add(h, live_->health());
  return h;
}

void TakeRecorder::start_take(RecorderOptions options) {
  const std::lock_guard lock(mutex_);
  if (live_) throw Error(stopping_ ? "the last take is still closing" : "a take is being recorded: stop it first");
  auto take = std::make_unique<Take>();
  options.vertices = options.vertices && record_vertices_;
  if (options.solved) options.start_state_bytes = start_state_bytes_;  // a markers-only take is not re-solved to itself
  take->recorder = std::make_unique<Recorder>(std::move(options), vertex_count_);
  live_ = take->recorder.get();
  last_file_ = live_->file();
  handoff_.offer(std::move(take));
}

void TakeRecorder::set_start_state_bytes(std::size_t bytes) {
  const std::lock_guard lock(mutex_);
  start_state_bytes_ = bytes;
}

bool TakeRecorder::stop_take() {
  const std::lock_guard lock(mutex_);
  // Not while the start is still on offer: a new offer would destroy it unadopted.
  if (!live_ || stopping_ || handoff_.pending()) return false;
  stopping_ = true;
  handoff_.offer(std::make_unique<Take>());
  return true;
}

std::optional<TakeSummary> TakeRecorder::finish_stopped() {
  std::unique_lock lock(mutex_);
  if (!stopping_) return std::nullopt;
  std::unique_ptr<Take> retired = handoff_.take_retired();
  if (!retired || !retired->recorder) return std::nullopt;  // the loop still holds it (or retired an idle one)
  lock.unlock();
  // Not under the lock: the writer thread writes what is queued, then the index, and syncs.
  std::optional<Error> failure;
  try {
    retired->recorder->stop();
  } catch (const Error& e) {
    failure = e;
  }
  TakeSummary summary{retired->recorder->file(), retired->recorder->counters(), retired->recorder->health(),
                      retired->recorder->failure()};
  lock.lock();
  add(finished_, summary.health);
  live_ = nullptr;
  stopping_ = false;
  lock.unlock();
  retired.reset();
  if (failure) throw *failure;
  return summary;
}

bool TakeRecorder::recording() const {
  const std::lock_guard lock(mutex_);
  return live_ && !stopping_;
}

std::filesystem::path TakeRecorder::file() const {
  const std::lock_guard lock(mutex_);
  return last_file_;
}

RecorderCounters TakeRecorder::take_counters() const {
  const std::lock_guard lock(mutex_);
  return live_ ? live_->counters() : RecorderCounters{};
}

void TakeRecorder::stop() {
  // The loop has stopped: what it held, retired or was offered is ours now.
  std::unique_ptr<Take> takes[3];
  takes[0] = handoff_.take_retired();
  handoff_.adopt(current_);
  takes[1] = handoff_.take_retired();
  takes[2] = std::move(current_);
  std::optional<Error> failure;
  for (const auto& take : takes) {
    if (!take || !take->recorder) continue;
    try {
      take->recorder->stop();
    } catch (const Error& e) {
      failure = e;
    }
    const std::lock_guard lock(mutex_);
    add(finished_, take->recorder->health());
    if (live_ == take->recorder.get()) live_ = nullptr, stopping_ = false;
  }
  if (failure) throw *failure;
}

}  // namespace facecap::outputs
