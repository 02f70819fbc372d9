#include "daemon/solve_loop.hpp"

#include <algorithm>
#include <cmath>

#include "core/time.hpp"
#include "core/rt/deadline_grid.hpp"

namespace facecap::daemon {
namespace {

// The first tick comes this long after start(): time for the source to get going.
constexpr int64_t kStartDelayNs = 20 * kNsPerMs;
// A source whose rate differs from the loop's by more than this is not phase-locked to.
constexpr double kPhaseLockRateTolerance = 0.01;
// Lockstep with nothing to do (replay ended, recorder queue full): re-check this often.
constexpr int64_t kLockstepIdleNs = 200 * kNsPerUs;
// Marker frames the supervisor's checks may have waiting: it drains them every 20 ms
// (kSuperviseSliceNs), 5 frames of a 240 Hz source; a frame with no free slot is skipped.
constexpr std::size_t kSampledMarkerSlots = 16;
// Pre-faulted so that the solve thread's stack never page-faults in the loop.
constexpr std::size_t kStackPrefaultBytes = 256 * 1024;

void sleep_for(int64_t ns) noexcept { sleep_until(monotonic_now_ns() + ns); }

[[gnu::noinline]] void prefault_stack() noexcept {
  [[maybe_unused]] volatile unsigned char stack[kStackPrefaultBytes];
  for (std::size_t i = 0; i < kStackPrefaultBytes; i += 4096) stack[i] = 0;
}

void store_max(std::atomic<int64_t>& slot, int64_t value) noexcept {
  if (value > slot.load(std::memory_order_relaxed)) slot.store(value, std::memory_order_relaxed);
}

void add(std::atomic<uint64_t>& counter, uint64_t n = 1) noexcept {
  counter.store(counter.load(std::memory_order_relaxed) + n, std::memory_order_relaxed);
}

}  // namespace

std::string_view loop_stage_name(LoopStage stage) noexcept {
  switch (stage) {
    case LoopStage::kTake: return "take";
    case LoopStage::kSolve: return "solve";
    case LoopStage::kOutputs: return "outputs";
    case LoopStage::kCount: break;
  }
  return "?";
}

std::string_view latency_stage_name(LatencyStage stage) noexcept {
  switch (stage) {
    case LatencyStage::kExposureToReceive: return "exposure_to_receive";
    case LatencyStage::kReceiveToSolved: return "receive_to_solved";
    case LatencyStage::kSolvedToSent: return "solved_to_sent";
    case LatencyStage::kCount: break;
  }
  return "?";
}

namespace {
bool any_wants_vertices(const std::vector<outputs::OutputSink*>& sinks) {
  return std::any_of(sinks.begin(), sinks.end(), [](const outputs::OutputSink* s) { return s->wants_vertices(); });
}
}  // namespace

SolveLoop::SolveLoop(LoopOptions options, drivers::MarkerSource& source, std::unique_ptr<pipeline::SolvePipeline> pipeline,
                     std::vector<outputs::OutputSink*> sinks)
    : options_(std::move(options)),
      source_(source),
      pipeline_(std::move(pipeline)),
      sinks_(std::move(sinks)),
      sink_timing_(sinks_.size()),
      period_ns_(int64_t(std::llround(double(kNsPerSecond) / options_.rate_hz))),
      phase_follower_(period_ns_, options_.phase_margin_ns),
      marker_frame_(make_marker_frame(source.info().labels)),
      solved_frame_(pipeline_->make_solved_frame(any_wants_vertices(sinks_))),
      sampled_markers_(kSampledMarkerSlots, marker_frame_),
      marker_telemetry_(source.info().labels.size()) {
  const double source_rate = source.info().nominal_rate_hz;
  phase_lock_ = !options_.lockstep && options_.phase_margin_ns > 0 && source.info().own_clock && source_rate > 0.0 &&
                std::abs(source_rate - options_.rate_hz) <= kPhaseLockRateTolerance * options_.rate_hz;
}

SolveLoop::~SolveLoop() {
  request_stop();
  join();
}

void SolveLoop::start() {
  epoch_ns_ = monotonic_now_ns() + kStartDelayNs;
  // Simulated devices run just below the solve thread, as real ones are outside the host.
  const int loop_priority = realtime_priority(options_.realtime.priority);
  source_.start({.epoch_ns = epoch_ns_, .lockstep = options_.lockstep,
                 .thread_priority = options_.realtime.fifo ? std::max(1, loop_priority - 1) : 0});
  thread_ = std::thread([this] { run(); });
}

void SolveLoop::join() {
  if (thread_.joinable()) thread_.join();
}

void SolveLoop::offer_pipeline(std::unique_ptr<pipeline::SolvePipeline> pipeline) { pipeline_handoff_.offer(std::move(pipeline)); }

void SolveLoop::collect_retired() { pipeline_handoff_.collect(); }

void SolveLoop::adopt_offered_pipeline() noexcept {
  if (pipeline_handoff_.adopt(pipeline_)) {
    add(counters_.pipeline_swaps);
    swap_ticks_watched_ = 2;
  }
}

void SolveLoop::offer_start_state() noexcept {
  std::span<const char> state;  // encoded once, for every sink that wants it
  for (outputs::OutputSink* sink : sinks_) {
    if (!sink->wants_start_state()) continue;
    if (state.empty()) state = pipeline_->encoded_state();
    sink->offer_start_state(state);
  }
}

void SolveLoop::record_stage(LoopStage stage, int64_t ns) noexcept {
  auto& total = counters_.stage_total_ns[std::size_t(stage)];
  total.store(total.load(std::memory_order_relaxed) + ns, std::memory_order_relaxed);
  store_max(counters_.stage_max_ns[std::size_t(stage)], ns);
}

void SolveLoop::record_telemetry() noexcept {
  add(counters_.markers_used, solved_frame_.markers_used);
  add(counters_.markers_expected, solved_frame_.markers_expected);
  for (const float residual_mm : solved_frame_.marker_residual_mm)
    if (!std::isnan(residual_mm)) residual_nm_.record(int64_t(std::llround(double(residual_mm) * 1e6)));
  marker_telemetry_.record(marker_frame_, solved_frame_);
}

bool SolveLoop::tick(int64_t now_ns) noexcept {
  add(counters_.ticks);
  for (outputs::OutputSink* sink : sinks_) sink->tick(now_ns);
  adopt_offered_pipeline();

  const bool got = source_.take_frame(now_ns, marker_frame_);
  const int64_t taken_ns = monotonic_now_ns();
  record_stage(LoopStage::kTake, taken_ns - now_ns);
  if (!got) {
    add(counters_.idle_ticks);
    if (source_.finished()) source_finished_.store(true, std::memory_order_release);
    return false;
  }

  if (sampling_markers_.load(std::memory_order_relaxed))
    if (MarkerFrame* slot = sampled_markers_.begin_push(); slot && slot->markers.capacity() >= marker_frame_.markers.size()) {
      *slot = marker_frame_;  // fits its storage: no allocation
      sampled_markers_.commit_push();
    }
  offer_start_state();
  // At a fixed rate the solve should leave the tick's last quarter for the outputs.
  pipeline_->set_deadline(options_.lockstep ? 0 : now_ns + period_ns_ - period_ns_ / 4);
  pipeline_->process(marker_frame_, solved_frame_);
  const int64_t solved_ns = monotonic_now_ns();
  if (pipeline_->result().fold_stopped_at_deadline) add(counters_.fold_deadline_stops);
  record_stage(LoopStage::kSolve, solved_ns - taken_ns);
  for (std::size_t s = 0; s < kSolveStageCount; ++s) {
    auto& total = counters_.solver_stage_total_ns[s];
    total.store(total.load(std::memory_order_relaxed) + solved_frame_.stage_ns[s], std::memory_order_relaxed);
  }
  for (std::size_t bit = 0; bit < kSolvedFlagCount; ++bit)
    if (solved_frame_.flags & (1u << bit)) add(counters_.flagged_frames[bit]);
  record_telemetry();

  int64_t offered_ns = solved_ns;
  for (std::size_t i = 0; i < sinks_.size(); ++i) {
    outputs::OutputSink& sink = *sinks_[i];
    // Lockstep is not real time: there a queued output may hold the loop back instead of
    // dropping frames.
    while (options_.lockstep && !sink.ready() && !stop_requested_.load(std::memory_order_relaxed))
      sleep_for(kLockstepIdleNs);
    const int64_t begin_ns = monotonic_now_ns();
    sink.offer(marker_frame_, solved_frame_);
    offered_ns = monotonic_now_ns();
    sink_timing_[i].offer_ns.record(offered_ns - begin_ns);
    store_max(sink_timing_[i].max_ns, offered_ns - begin_ns);
  }
  record_stage(LoopStage::kOutputs, offered_ns - solved_ns);
  latency_.record(offered_ns - marker_frame_.receive_time_ns);
  if (marker_frame_.exposure_time_ns != 0)
    latency_chain_[std::size_t(LatencyStage::kExposureToReceive)].record(marker_frame_.receive_time_ns -
                                                                          marker_frame_.exposure_time_ns);
  latency_chain_[std::size_t(LatencyStage::kReceiveToSolved)].record(solved_ns - marker_frame_.receive_time_ns);
  latency_chain_[std::size_t(LatencyStage::kSolvedToSent)].record(offered_ns - solved_ns);

  if (phase_lock_) {
    phase_correction_ns_ = phase_follower_.correction(now_ns - marker_frame_.receive_time_ns,
                                                      source_.health().frames_overwritten);
    counters_.max_jitter_margin_ns.store(phase_follower_.max_jitter_margin_ns(), std::memory_order_relaxed);
  }
  counters_.frames_solved.store(counters_.frames_solved.load(std::memory_order_relaxed) + 1, std::memory_order_release);
  add(counters_.solved_sequence);
  return true;
}

void SolveLoop::wait_for_tick(int64_t deadline_ns) noexcept {
  if (options_.prefetch_lead_ns > 0) {
    sleep_until(deadline_ns - options_.prefetch_lead_ns);
    prefetch_until(pipeline_->streamed_memory(), deadline_ns);
  }
  sleep_until(deadline_ns);
}

void SolveLoop::run_fixed_rate(int64_t epoch_ns) noexcept {
  rt::DeadlineGrid grid(epoch_ns, period_ns_);
  while (!stop_requested_.load(std::memory_order_acquire)) {
    wait_for_tick(grid.deadline_ns());
    const int64_t wake_ns = monotonic_now_ns();
    store_max(counters_.max_wake_late_ns, wake_ns - grid.deadline_ns());
    tick(wake_ns);
    if (source_finished_.load(std::memory_order_relaxed)) break;

    const int64_t end_ns = monotonic_now_ns();
    store_max(counters_.max_tick_ns, end_ns - wake_ns);
    const rt::TickOutcome outcome = grid.advance(wake_ns, end_ns, phase_correction_ns_);
    phase_correction_ns_ = 0;
    if (swap_ticks_watched_ > 0) {
      --swap_ticks_watched_;
      if (outcome.missed) add(counters_.swap_misses);
    }
    if (outcome.missed) {
      add(counters_.missed_deadlines);
      if (outcome.started_late) add(counters_.late_start_misses);
      add(counters_.skipped_ticks, outcome.skipped);
    }
  }
}

void SolveLoop::run_lockstep() noexcept {
  while (!stop_requested_.load(std::memory_order_acquire)) {
    if (tick(monotonic_now_ns())) continue;
    if (source_finished_.load(std::memory_order_relaxed)) break;
    sleep_for(kLockstepIdleNs);
  }
}

void SolveLoop::run() noexcept {
  realtime_report_ = apply_realtime(options_.realtime);
  realtime_ready_.store(true, std::memory_order_release);
  prefault_stack();
  if (options_.lockstep) run_lockstep();
  // The source's frames are due from the epoch on: a phase-locked loop starts its ticks
  // the margin after them rather than racing them.
  else run_fixed_rate(epoch_ns_ + (phase_lock_ ? options_.phase_margin_ns : 0));
  exited_.store(true, std::memory_order_release);
}

}  // namespace facecap::daemon
