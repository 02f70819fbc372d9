#pragma once
// The solve thread: a fixed-rate loop on absolute CLOCK_MONOTONIC deadlines (or
// lockstep: every frame of a replay, as fast as possible). Each tick takes the newest
// frame from the source, solves it (pipeline::SolvePipeline) and offers it to every
// output, timing each. The loop reports through counters and histograms only; the main
// thread turns them into logs and STATUS= lines.
#include <array>
#include <atomic>
#include <cstdint>
#include <memory>
#include <span>
#include <thread>
#include <vector>

#include "core/frame.hpp"
#include "core/realtime.hpp"
#include "core/rt/handoff.hpp"
#include "core/rt/phase_follower.hpp"
#include "core/rt/spsc_slots.hpp"
#include "core/latency_histogram.hpp"
#include "daemon/marker_telemetry.hpp"
#include "drivers/api/marker_source.hpp"
#include "outputs/api/sink.hpp"
#include "pipeline/solve_pipeline.hpp"

namespace facecap::daemon {

struct LoopOptions {
  double rate_hz = 120.0;
  bool lockstep = false;
  // > 0: shift ticks to fall this long after frames of a source on its own clock arrive.
  int64_t phase_margin_ns = 0;
  // > 0: wake this long before each deadline to prefetch the solver's streamed memory
  // (fixed rate only), so that a solve after a sleep does not start from main memory.
  int64_t prefetch_lead_ns = 0;
  RealtimeRequest realtime;
};

// Loop stages timed besides the solver's own (SolvedFrame::stage_ns); each output's offer
// is timed on its own as well (SinkTiming).
enum class LoopStage : uint8_t { kTake, kSolve, kOutputs, kCount };
inline constexpr std::size_t kLoopStageCount = std::size_t(LoopStage::kCount);
std::string_view loop_stage_name(LoopStage stage) noexcept;

// The latency chain of a solved frame, stage by stage: the cameras' mid-exposure (when the
// source says, as NatNet does) -> received by facecapd -> solved -> offered to every output.
enum class LatencyStage : uint8_t { kExposureToReceive, kReceiveToSolved, kSolvedToSent, kCount };
inline constexpr std::size_t kLatencyStageCount = std::size_t(LatencyStage::kCount);
// "exposure_to_receive", "receive_to_solved", "solved_to_sent".
std::string_view latency_stage_name(LatencyStage stage) noexcept;

// Written by the solve thread only; read by anyone.
struct LoopCounters {
  std::atomic<uint64_t> ticks{0};
  std::atomic<uint64_t> frames_solved{0};
  std::atomic<uint64_t> idle_ticks{0};          // no new frame at the tick
  std::atomic<uint64_t> missed_deadlines{0};    // ticks whose work ran past the next deadline
  // Of those, the ticks whose work took no longer than a period: they missed because
  // they started late, the thread not running when due (another task or the hypervisor
  // held its CPU). The others ran longer than a period.
  std::atomic<uint64_t> late_start_misses{0};
  // Frames whose fold stage stopped before a round that would have run past the
  // solve's share of the tick (FaceSolver::set_deadline).
  std::atomic<uint64_t> fold_deadline_stops{0};
  std::atomic<uint64_t> skipped_ticks{0};       // ticks given up to get back on the grid
  std::atomic<int64_t> max_wake_late_ns{0};     // worst wake-up after a deadline
  std::atomic<int64_t> max_tick_ns{0};          // longest tick, wake-up to the end of its work
  // Phase lock: the most the ticks waited beyond phase_margin for frames arriving late.
  std::atomic<int64_t> max_jitter_margin_ns{0};
  std::atomic<uint64_t> pipeline_swaps{0};
  // Missed deadlines of the ticks that adopted a new pipeline and of the tick after each
  // (its caches cold): what a swap (reload, actor, calibration) cost the loop.
  std::atomic<uint64_t> swap_misses{0};
  std::array<std::atomic<int64_t>, kLoopStageCount> stage_total_ns{};
  std::array<std::atomic<int64_t>, kLoopStageCount> stage_max_ns{};
  std::array<std::atomic<int64_t>, kSolveStageCount> solver_stage_total_ns{};
  // Solved frames with each SolvedFlags bit set (bit i: solved_flag_name(i)).
  std::array<std::atomic<uint64_t>, kSolvedFlagCount> flagged_frames{};
  std::atomic<uint64_t> solved_sequence{0};     // bumps per solved frame; the watchdog checks it moves
  // Operator telemetry: face markers used and expected, summed over the solved frames.
  std::atomic<uint64_t> markers_used{0};
  std::atomic<uint64_t> markers_expected{0};
};

// What one output's offer() costs the solve thread. Written by the solve thread only.
struct SinkTiming {
  LatencyHistogram offer_ns;
  std::atomic<int64_t> max_ns{0};
};

class SolveLoop {
 public:
  // The loop borrows the source and the outputs, which must outlive it; it solves
  // vertices only when some output wants them. Not RT-safe.
  SolveLoop(LoopOptions options, drivers::MarkerSource& source, std::unique_ptr<pipeline::SolvePipeline> pipeline,
            std::vector<outputs::OutputSink*> sinks);
  ~SolveLoop();  // request_stop() and join()
  SolveLoop(const SolveLoop&) = delete;
  SolveLoop& operator=(const SolveLoop&) = delete;

  // Starts the source and the solve thread; the first tick is a few ms from now. Not RT-safe.
  void start();
  // Any thread. RT-safe.
  void request_stop() noexcept { stop_requested_.store(true, std::memory_order_release); }
  // Waits for the solve thread. Not RT-safe.
  void join();

  // Hands a newly built pipeline to the loop, which adopts it between two frames.
  // A pipeline offered before the loop took the previous offer replaces it. Not RT-safe.
  void offer_pipeline(std::unique_ptr<pipeline::SolvePipeline> pipeline);
  // Deletes pipelines the loop has let go of (off the solve thread). Not RT-safe.
  void collect_retired();

  const LoopCounters& counters() const noexcept { return counters_; }
  LatencyHistogram::Snapshot latency() const noexcept { return latency_.snapshot(); }
  LatencyHistogram::Snapshot latency(LatencyStage stage) const noexcept {
    return latency_chain_[std::size_t(stage)].snapshot();
  }
  // Every fit residual of every solved frame, in nanometres: the histogram's buckets,
  // 1 us wide below 1 ms, ..., are 1 um wide below 1 mm, 10 um below 10 mm, ...
  LatencyHistogram::Snapshot residuals_nm() const noexcept { return residual_nm_.snapshot(); }
  // Per source marker slot: presence, jitter and fit residual so far. Any thread.
  MarkerCounts marker_counts() const { return marker_telemetry_.snapshot(); }
  // The outputs in offer order, and what each costs the solve thread.
  std::span<outputs::OutputSink* const> sinks() const noexcept { return sinks_; }
  const SinkTiming& sink_timing(std::size_t i) const noexcept { return sink_timing_[i]; }
  bool first_frame_solved() const noexcept { return counters_.frames_solved.load(std::memory_order_acquire) > 0; }
  bool source_finished() const noexcept { return source_finished_.load(std::memory_order_acquire); }
  bool running() const noexcept { return thread_.joinable() && !exited_.load(std::memory_order_acquire); }
  // Valid once realtime_ready() (the solve thread applied its request).
  bool realtime_ready() const noexcept { return realtime_ready_.load(std::memory_order_acquire); }
  const RealtimeReport& realtime_report() const noexcept { return realtime_report_; }
  const LoopOptions& options() const noexcept { return options_; }
  int64_t period_ns() const noexcept { return period_ns_; }

  // Marker frames copied for the supervisor's checks (the source's units), while asked:
  // the solve thread copies each frame it takes into a free slot, or skips it when none is
  // free. sample_markers(): any thread, RT-safe; sampled_markers(): the supervisor only,
  // front() and pop() as rt::SpscSlots has them.
  void sample_markers(bool on) noexcept { sampling_markers_.store(on, std::memory_order_relaxed); }
  rt::SpscSlots<MarkerFrame>& sampled_markers() noexcept { return sampled_markers_; }

  // One tick's work at time now_ns; public so tests can drive the loop by hand. RT-safe.
  // Returns true when a frame was solved.
  bool tick(int64_t now_ns) noexcept;

  // Sleeps until deadline_ns, prefetching the solver's streamed memory in the last
  // prefetch_lead_ns before it. RT-safe.
  void wait_for_tick(int64_t deadline_ns) noexcept;

 private:
  void run() noexcept;
  void run_fixed_rate(int64_t epoch_ns) noexcept;
  void run_lockstep() noexcept;
  void adopt_offered_pipeline() noexcept;
  // The pipeline's state before this tick's frame, to the sinks that want it (a take's
  // first frame). RT-safe.
  void offer_start_state() noexcept;
  void record_stage(LoopStage stage, int64_t ns) noexcept;
  // Markers used and expected, and each fit residual, of the frame just solved. RT-safe.
  void record_telemetry() noexcept;

  LoopOptions options_;
  drivers::MarkerSource& source_;
  std::unique_ptr<pipeline::SolvePipeline> pipeline_;
  std::vector<outputs::OutputSink*> sinks_;
  std::vector<SinkTiming> sink_timing_;
  int64_t period_ns_;
  bool phase_lock_ = false;
  rt::PhaseFollower phase_follower_;
  int64_t phase_correction_ns_ = 0;  // applied to the next deadline
  int swap_ticks_watched_ = 0;       // ticks left whose misses count as swap_misses

  MarkerFrame marker_frame_;
  SolvedFrame solved_frame_;
  std::atomic<bool> sampling_markers_{false};
  rt::SpscSlots<MarkerFrame> sampled_markers_;

  rt::Handoff<pipeline::SolvePipeline> pipeline_handoff_;

  LoopCounters counters_;
  LatencyHistogram latency_;  // received -> offered to every output
  std::array<LatencyHistogram, kLatencyStageCount> latency_chain_;
  LatencyHistogram residual_nm_;
  MarkerTelemetry marker_telemetry_;
  RealtimeReport realtime_report_;
  std::atomic<bool> realtime_ready_{false};
  std::atomic<bool> stop_requested_{false};
  std::atomic<bool> source_finished_{false};
  std::atomic<bool> exited_{false};
  int64_t epoch_ns_ = 0;
  std::thread thread_;
};

}  // namespace facecap::daemon
