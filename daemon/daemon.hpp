#pragma once
// facecapd's supervisor, on the main thread: builds everything from a validated
// configuration (configure), starts the solve loop (activate), then handles signals,
// sd_notify (READY, WATCHDOG, STATUS, STOPPING), figures, SIGHUP reloads and a clean stop.
// Nothing here is real-time code; the solve thread is SolveLoop.
#include <array>
#include <atomic>
#include <cstdint>
#include <filesystem>
#include <future>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "config/config_file.hpp"
#include "control/commands.hpp"
#include "control/server.hpp"
#include "control/status.hpp"
#include "control/stream_sink.hpp"
#include "core/time.hpp"
#include "daemon/capture_quality.hpp"
#include "daemon/controller.hpp"
#include "daemon/io_thread.hpp"
#include "daemon/solve_loop.hpp"
#include "daemon/systemd_notify.hpp"
#include "drivers/api/marker_source.hpp"
#include "outputs/api/sink.hpp"
#include "outputs/recording/take_recorder.hpp"
#include "pipeline/calibration.hpp"
#include "pipeline/source_units.hpp"

namespace facecap::daemon {

// One latency histogram's figures over a window.
struct LatencyFigures {
  uint64_t frames = 0;
  int64_t p50_ns = 0, p99_ns = 0, max_ns = 0;
};

// Control commands waiting for the supervisor at most; more are refused (503).
inline constexpr std::size_t kCommandQueueCapacity = 32;
// Frames the WebSocket stream's queue holds between the solve thread and the I/O thread.
inline constexpr std::size_t kStreamSlots = 8;
// How often the supervisor publishes the control API's status (and after every command).
inline constexpr int64_t kPublishIntervalNs = 100 * kNsPerMs;

// A window's or a whole run's figures.
struct Figures {
  double seconds = 0.0;
  uint64_t ticks = 0;
  uint64_t frames_solved = 0;
  uint64_t idle_ticks = 0;
  uint64_t missed_deadlines = 0;
  uint64_t late_start_misses = 0;  // of the missed deadlines: work within a period, started late
  uint64_t skipped_ticks = 0;
  uint64_t fold_deadline_stops = 0;  // frames whose fold stage stopped at the deadline
  double solved_fps = 0.0;
  int64_t latency_p50_ns = 0;  // source frame received -> slot published
  int64_t latency_p99_ns = 0;
  int64_t latency_max_ns = 0;
  std::array<LatencyFigures, kLatencyStageCount> latency_chain{};  // by LatencyStage
  double cpu_percent = 0.0;    // whole process, of one CPU
  uint64_t source_overwritten = 0;
  uint64_t source_late = 0;
  uint64_t source_errors = 0;
  uint64_t source_foreign = 0;   // datagrams from senders other than the source's server
  uint64_t outputs_dropped = 0;  // over every output whose drops are losses (not drops_by_design)
  std::array<uint64_t, kSolvedFlagCount> flagged_frames{};  // solved frames with each SolvedFlags bit
  CaptureFigures capture;        // markers used, held frames, fit residuals
};

// What `facecapd --check-config` checks beyond the file itself: loads the configured rig
// and the calibration, checked against it (pipeline::load_calibration), as start() would.
// Returns a one-line summary; throws Error naming the file at fault. Not RT-safe.
std::string check_rig_and_calibration(const config::DaemonConfig& config);

struct DaemonOptions {
  std::string config_file;                // re-read on SIGHUP; empty: defaults
  std::vector<std::string> overrides;     // --set key=value, re-applied on reload
  bool handle_signals = true;             // SIGTERM/SIGINT/SIGHUP are blocked and awaited here
  std::string version;                    // "facecapd 0.1.0 (git ...)", for the control API
};

class Daemon {
 public:
  Daemon(DaemonOptions options, config::LoadedConfig config);
  ~Daemon();
  Daemon(const Daemon&) = delete;
  Daemon& operator=(const Daemon&) = delete;

  // Loads the rig and calibration, opens the source, builds the solve pipeline, makes the
  // outputs (shared memory, recording, ...) and starts the solve loop. Throws Error.
  void start();
  // Supervises until SIGTERM/SIGINT, request_stop(), control.run_seconds or the end of a
  // replay; then stops cleanly. Returns the process exit status.
  int run();
  // Any thread.
  void request_stop() noexcept { stop_requested_.store(true, std::memory_order_release); }
  // Asks the supervising thread to reload, as SIGHUP does. Any thread.
  void request_reload() noexcept { reload_requested_.store(true, std::memory_order_release); }
  uint64_t reloads_accepted() const noexcept { return reloads_accepted_.load(std::memory_order_acquire); }
  uint64_t reloads_rejected() const noexcept { return reloads_rejected_.load(std::memory_order_acquire); }

  const config::DaemonConfig& config() const noexcept { return config_.values; }
  const SolveLoop* loop() const noexcept { return loop_.get(); }
  drivers::MarkerSource* source() noexcept { return source_.get(); }
  const Rig& rig() const noexcept { return *rig_; }
  // The run's last take (empty when none was recorded); still known after the run.
  const std::filesystem::path& recording_file() const noexcept { return recording_file_; }
  // The control API's port (0 when it is off): the one picked when control.http.port is 0.
  uint16_t control_port() const noexcept;
  Figures figures_since_start() const;
  // The capture quality of a window's figures against the [quality] thresholds.
  QualityAssessment quality(const Figures& window) const;
  // Per face marker of the current calibration, its slot's window figures (in mm), named
  // and given its region.
  std::vector<MarkerQuality> marker_quality(const std::vector<MarkerFigures>& slots) const;
  std::string status_line(const Figures& window) const;

 private:
  struct Sample;
  // Re-reads the configuration: an invalid one is rejected and the running one kept.
  bool reload();
  Sample take_sample() const;
  Figures figures_between(const Sample& from, const Sample& to) const;
  void supervise_once(int64_t now_ns);
  void start_control();
  void serve_commands();
  void publish_status(int64_t now_ns);
  void apply_live_settings();
  void shutdown(const std::string& reason);
  void write_stats_file(const Figures& run) const;
  void start_io_thread(const config::DaemonConfig& c);
  void log_pipeline(const pipeline::SolvePipeline& solve, const pipeline::Calibration& calibration,
                    double build_seconds) const;
  // The source's units against the calibration's face (docs/daemon.md "Units"): a replay's
  // take is checked whole before the loop starts and refused (throws Error) when its values
  // look like other units than it is read in; any source is judged from its first seconds of frames, sampled off the
  // solve thread (SolveLoop::sampled_markers), and judged afresh after each pipeline swap.
  void require_plausible_recorded_units(const pipeline::Calibration& calibration) const;
  void watch_source_units();
  static std::string flagged_text(const Figures& window);
  static std::string latency_chain_text(const Figures& window);

  DaemonOptions options_;
  config::LoadedConfig config_;
  SystemdNotifier notifier_;
  std::shared_ptr<const Rig> rig_;
  uint64_t rig_hash_ = 0;  // rig_->content_hash()
  std::unique_ptr<drivers::MarkerSource> source_;
  std::unique_ptr<IoThread> io_;  // before the sinks and the server: they schedule work on it
  std::vector<std::unique_ptr<outputs::OutputSink>> sinks_;
  outputs::TakeRecorder* takes_ = nullptr;  // among sinks_, when recording is possible
  std::filesystem::path recording_file_;
  std::unique_ptr<SolveLoop> loop_;  // borrows the members above
  std::unique_ptr<Controller> controller_;  // borrows the loop
  // The control API (control.http.enabled): what it reports, what it asks, its sockets.
  control::StatusBoard board_;
  control::CommandQueue commands_{kCommandQueueCapacity};
  control::StreamSink* stream_ = nullptr;  // among sinks_
  std::unique_ptr<control::ControlServer> server_;
  int64_t next_publish_ns_ = 0;
  Figures status_window_;  // the last STATUS window's figures
  QualityHold quality_hold_;  // the state shown, from the status windows' assessments
  std::array<uint64_t, 3> quality_windows_{};  // status windows in each quality state
  std::optional<pipeline::LiveUnitsCheck> units_check_;
  uint64_t units_check_swaps_ = 0;  // the loop's pipeline swaps when units_check_ began
  std::string units_problem_;       // the verdict when implausible: what is wrong, for STATUS, /status and the log

  std::atomic<bool> stop_requested_{false};
  std::atomic<bool> reload_requested_{false};
  std::atomic<uint64_t> reloads_accepted_{0}, reloads_rejected_{0};
  bool ready_sent_ = false;
  bool realtime_logged_ = false;
  std::unique_ptr<Sample> start_sample_, status_sample_, stats_sample_;
  int64_t start_ns_ = 0;
  int64_t next_status_ns_ = 0, next_stats_ns_ = 0, next_watchdog_ns_ = 0;
  uint64_t ticks_at_last_watchdog_ = 0;
  std::string last_status_;
};

}  // namespace facecap::daemon
