#pragma once
// What facecapd reports about itself (GET /status, GET /metrics): the supervisor fills a
// StatusReport from its counters a few times a second and publishes its renderings on a
// StatusBoard; the I/O thread serves the latest text, so a request never reaches the solve
// thread or waits for the supervisor. Field meanings: docs/control-api.md. Not real-time code.
#include <array>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

namespace facecap::control {

struct OutputReport {
  std::string name, description;
  uint64_t offered = 0, delivered = 0, dropped = 0, errors = 0;
  bool failed = false;
  double offer_p50_us = 0, offer_p99_us = 0, offer_max_us = 0;  // what its offer() costs the solve thread
};

// One face marker the calibration binds, over the last status window.
struct MarkerReport {
  std::string label, region;
  double present_fraction = 0, noise_mm = 0, residual_mm = 0;  // NaN: not measured
  bool missing = false;
  std::array<double, 3> rest{};  // its bound point on the neutral mesh, rig space: where to draw it when missing
};

struct TakeReport {
  bool active = false;
  std::string file, take, actor, scene, shot, notes;
  bool markers_only = false;
  double seconds = 0;
  uint64_t frames_written = 0, frames_dropped = 0;
  bool failed = false;  // a write failed (disk full, file-size limit, file deleted): the take stopped there
};

struct StatusReport {
  std::string version;
  int64_t pid = 0;
  double uptime_s = 0;
  // The source.
  std::string source_driver, source_description;
  double source_rate_hz = 0;
  uint64_t source_delivered = 0, source_overwritten = 0, source_late = 0, source_errors = 0;
  uint64_t source_foreign = 0;  // datagrams from senders other than the source's server (NatNet), dropped
  bool source_finished = false;
  // Its units against the calibration's face (docs/daemon.md "Units"): "checking" (its
  // first seconds), "plausible" or "implausible"; the face's size over the calibrated one's;
  // the unit its values look like and what is wrong, when implausible.
  std::string source_units, source_units_check = "checking";
  double source_size_ratio = 0;
  std::string source_units_look_like, source_units_problem;
  // The rig, the solver, the actor and the calibration.
  std::string rig_name, solver;
  std::string kernels, cpu_features;  // the solver's kernel path and what the CPU offers
  uint64_t rig_hash = 0;
  int64_t rig_vertices = 0, rig_shapes = 0;
  std::string actor, calibration;  // the actor's name ("" when none); what the calibration came from
  uint64_t calibration_markers = 0, calibration_markers_found = 0;
  bool head_stabilised = false;
  std::vector<std::string> unobserved_shapes;  // shapes the calibration's markers cannot observe (left at 0)
  // The loop.
  std::string mode;
  double rate_hz = 0;
  // The last status window.
  double window_s = 0, solved_fps = 0, cpu_percent = 0;
  double latency_p50_ms = 0, latency_p99_ms = 0, latency_max_ms = 0;
  uint64_t window_missed_deadlines = 0;
  double markers_used = 0, markers_expected = 0, head_held_fraction = 0, face_held_fraction = 0;
  double residual_p50_mm = 0, residual_p95_mm = 0, residual_max_mm = 0;
  std::string quality;               // good, degraded, bad
  std::vector<std::string> quality_reasons;
  std::vector<MarkerReport> markers;  // the calibration's face markers
  // Since the start.
  uint64_t ticks = 0, frames_solved = 0, idle_ticks = 0, missed_deadlines = 0, late_start_misses = 0,
           skipped_ticks = 0, fold_deadline_stops = 0, pipeline_swaps = 0, swap_misses = 0, reloads_accepted = 0, reloads_rejected = 0,
           quality_changes = 0;
  std::vector<std::pair<std::string, uint64_t>> flagged_frames;  // per status bit
  std::vector<OutputReport> outputs;
  TakeReport recording;
  std::string busy;  // long work in flight ("calibrating", "loading actor"), "" when idle
};

nlohmann::json status_json(const StatusReport& report);
// Prometheus text exposition format 0.0.4 (`promtool check metrics` accepts it).
std::string metrics_text(const StatusReport& report);

// The renderings the I/O thread serves.
struct Published {
  std::string status_json;
  std::string metrics_text;
  std::string config_json;
};

// The latest Published, swapped whole. Any thread; never held while rendering.
class StatusBoard {
 public:
  void publish(std::shared_ptr<const Published> next) {
    const std::lock_guard lock(mutex_);
    latest_ = std::move(next);
  }
  std::shared_ptr<const Published> latest() const {
    const std::lock_guard lock(mutex_);
    return latest_;
  }

 private:
  mutable std::mutex mutex_;
  std::shared_ptr<const Published> latest_ = std::make_shared<Published>();
};

}  // namespace facecap::control
