#include "daemon/daemon.hpp"

#include <algorithm>
#include <bit>
#include <cerrno>
#include <cstring>
#include <csignal>
#include <fstream>
#include <optional>
#include <utility>

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <nlohmann/json.hpp>
#include <sys/resource.h>
#include <unistd.h>

#include "core/error.hpp"
#include "core/io.hpp"
#include "core/log.hpp"
#include "core/text_list.hpp"
#include "core/time.hpp"
#include "core/units.hpp"
#include "daemon/process_signals.hpp"
#include "drivers/table.hpp"
#include "outputs/recording/recorder.hpp"
#include "outputs/table.hpp"
#include "pipeline/recording_header.hpp"
#include "config/config_file.hpp"
#include "control/status.hpp"
#include "pipeline/settings.hpp"
#include "solver/builtin_face.hpp"
#include "solver/kernels/kernels.hpp"

namespace facecap::daemon {
namespace {

// The supervisor wakes at least this often (stop requests, READY, deadlines).
constexpr int64_t kSuperviseSliceNs = 20 * kNsPerMs;

int64_t process_cpu_ns() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return (int64_t(usage.ru_utime.tv_sec) + usage.ru_stime.tv_sec) * kNsPerSecond +
         (int64_t(usage.ru_utime.tv_usec) + usage.ru_stime.tv_usec) * kNsPerUs;
}

double ms(int64_t ns) { return double(ns) / kNsPerMs; }

std::shared_ptr<const Rig> load_configured_rig(const config::RigSection& section) {
  if (section.path == "builtin") {
    // The process-wide instance: no copy of its 6,000 vertices and 45 shapes.
    return std::shared_ptr<const Rig>(std::shared_ptr<const Rig>(), &BuiltinFace::instance().rig());
  }
  RigLoadOptions options;
  options.use_cache = section.cache;
  RigLoadReport report;
  auto rig = std::make_shared<const Rig>(load_rig(section.path, options, &report));
  spdlog::info("rig {} loaded in {:.2f} s{}", section.path, report.seconds, report.from_cache ? " (from cache)" : "");
  return rig;
}

// The dashboard built with this facecapd when it runs from its build tree (the tests, a
// developer), else the one installed with it (relative to facecapd's directory unless the
// install directories were configured absolute).
std::string default_dashboard_dir() {
  std::error_code ec;
  const std::filesystem::path exe = std::filesystem::read_symlink("/proc/self/exe", ec);
  const std::string exe_path = ec ? std::string() : exe.string();
  if (exe_path.starts_with(FACECAP_BUILD_TREE "/")) return FACECAP_BUILT_DASHBOARD_DIR;
  const std::filesystem::path installed = FACECAP_INSTALLED_DASHBOARD_DIR;
  if (installed.is_absolute() || ec) return installed.string();
  return (exe.parent_path() / installed).lexically_normal().string();
}

// A source of unnamed points cannot be solved without the labeller: it is turned on rather
// than left for the marker mapper to refuse (none of the calibration's names would match).
void label_unlabelled_source(config::DaemonConfig& c, const drivers::SourceInfo& source) {
  if (!source.unlabelled || c.calibration.label_markers) return;
  c.calibration.label_markers = true;
  spdlog::info("the source delivers unlabelled points: calibration.label_markers turned on to label them");
}

}  // namespace

std::string check_rig_and_calibration(const config::DaemonConfig& config) {
  const kernels::KernelTable& kernels = kernels::table(config.solver.kernels);  // throws when the CPU lacks them
  const std::shared_ptr<const Rig> rig = load_configured_rig(config.rig);
  const pipeline::Calibration calibration = pipeline::load_calibration(pipeline::calibration_spec(config), *rig);
  const std::string source_files = drivers::check_source_files(config.source);
  return fmt::format("rig {} ({} vertices, {} shapes), calibration {} ({} markers), {} kernels{}{}", config.rig.path,
                     rig->vertex_count(), rig->shape_count(),
                     config.calibration.file.empty() ? "default marker set" : config.calibration.file,
                     calibration.markers.size(), kKernelPaths.name(kernels.path), source_files.empty() ? "" : ", ",
                     source_files);
}

// Counters at one moment, for figures over a window.
struct Daemon::Sample {
  int64_t time_ns = 0;
  int64_t cpu_ns = 0;
  uint64_t ticks = 0, frames_solved = 0, idle_ticks = 0, missed = 0, late_start = 0, skipped = 0, fold_deadline_stops = 0;
  drivers::SourceHealth source;
  uint64_t outputs_dropped = 0;
  std::array<uint64_t, kSolvedFlagCount> flagged{};
  uint64_t markers_used = 0, markers_expected = 0;
  LatencyHistogram::Snapshot latency;
  std::array<LatencyHistogram::Snapshot, kLatencyStageCount> latency_chain;
  LatencyHistogram::Snapshot residuals_nm;
  MarkerCounts markers;
};

Daemon::Daemon(DaemonOptions options, config::LoadedConfig config)
    : options_(std::move(options)), config_(std::move(config)) {}

Daemon::~Daemon() {
  if (loop_) shutdown("destroyed");
}

void Daemon::start() {
  const config::DaemonConfig& c = config_.values;
  apply_live_settings();
  spdlog::info("configuration: {}", config_.file.empty() ? "defaults" : config_.file);
  for (const std::string& warning : config_.warnings) spdlog::warn("{}", warning);
  if (c.loop.lock_memory) {
    const MemoryLockReport report = lock_memory();
    (report.locked ? spdlog::info("{}", report.describe()) : spdlog::warn("{}", report.describe()));
  }

  rig_ = load_configured_rig(c.rig);
  rig_hash_ = rig_->content_hash();  // hashes every vertex: once, not at every status
  pipeline::Calibration calibration = pipeline::load_calibration(pipeline::calibration_spec(c), *rig_);
  source_ = drivers::make_source(c.source, {.rig = rig_, .markers = pipeline::rest_marker_set(calibration)});
  source_->open();
  spdlog::info("source {}", source_->description());
  const drivers::SourceInfo& info = source_->info();
  label_unlabelled_source(config_.values, info);
  const pipeline::SourceDescription source{info.labels, info.units};
  require_plausible_recorded_units(calibration);

  const int64_t build_start = monotonic_now_ns();
  auto solve = std::make_unique<pipeline::SolvePipeline>(*rig_, calibration, source, pipeline::solve_settings(c, pipeline::SolveContext::kLive));
  log_pipeline(*solve, calibration, ms(monotonic_now_ns() - build_start) / 1000.0);

  const bool lockstep = c.loop.mode == config::LoopMode::kLockstep;
  outputs::SinkContext context;
  context.header = pipeline::make_recording_header(*rig_, calibration, source, source_->description(),
                                                   pipeline::recorded_rate_hz(info.nominal_rate_hz, c.loop.rate_hz, lockstep),
                                                   pipeline::solve_settings_toml(c, pipeline::SolveContext::kLive));
  context.vertex_count = uint32_t(rig_->vertex_count());
  context.loop_rate_hz = c.loop.rate_hz;
  context.pipeline_state_bytes = solve->encoded_state_size();
  io_ = std::make_unique<IoThread>();
  context.io = &io_->context();
  sinks_ = outputs::make_outputs(c, context);
  if (c.control.http.enabled) {
    control::StreamSchema schema{rig_->name, context.header.rig_units, rig_->shape_names, info.labels,
                                 uint32_t(rig_->vertex_count()), {}};
    schema.triangles.reserve(std::size_t(rig_->triangles.size()));
    for (Eigen::Index t = 0; t < rig_->triangles.cols(); ++t)
      for (int corner = 0; corner < 3; ++corner) schema.triangles.push_back(int32_t(rig_->triangles(corner, t)));
    auto stream = std::make_unique<control::StreamSink>(std::move(schema), kStreamSlots);
    stream_ = stream.get();
    sinks_.push_back(std::move(stream));
  }
  start_io_thread(c);
  std::vector<outputs::OutputSink*> sinks;
  for (const auto& sink : sinks_) {
    spdlog::info("output {}", sink->description());
    if (auto* takes = dynamic_cast<outputs::TakeRecorder*>(sink.get())) takes_ = takes;
    sinks.push_back(sink.get());
  }
  if (takes_) recording_file_ = takes_->file();

  LoopOptions loop_options;
  loop_options.rate_hz = c.loop.rate_hz;
  loop_options.lockstep = lockstep;
  loop_options.phase_margin_ns = c.loop.phase_margin_us * kNsPerUs;
  loop_options.prefetch_lead_ns = c.loop.prefetch_lead_us * kNsPerUs;
  loop_options.realtime = {.fifo = c.loop.realtime, .priority = int(c.loop.priority), .cpus = c.loop.cpu_affinity};
  loop_ = std::make_unique<SolveLoop>(loop_options, *source_, std::move(solve), std::move(sinks));
  units_check_.emplace(info.labels, info.units, calibration);
  loop_->sample_markers(true);
  const std::string actor = c.calibration.file.empty() ? std::string() : std::filesystem::path(c.calibration.file).stem().string();
  controller_ = std::make_unique<Controller>(
      ControllerParts{.rig = rig_, .source = source_.get(), .loop = loop_.get(), .takes = takes_, .config = &config_.values},
      std::move(calibration), actor);
  // The run's figures count from before the loop's first tick: in lockstep a short replay
  // can end before this thread runs again.
  start_ns_ = monotonic_now_ns();
  start_sample_ = std::make_unique<Sample>(take_sample());
  loop_->start();
  status_sample_ = std::make_unique<Sample>(*start_sample_);
  stats_sample_ = std::make_unique<Sample>(*start_sample_);
  next_status_ns_ = start_ns_ + int64_t(c.control.status_interval_s * kNsPerSecond);
  next_stats_ns_ = start_ns_ + int64_t(c.logging.stats_interval_s * kNsPerSecond);
  next_watchdog_ns_ = start_ns_;
  spdlog::info("solve loop {} at {:g} Hz{}", loop_options.lockstep ? "in lockstep" : "running", c.loop.rate_hz,
               loop_options.lockstep ? " nominal" : "");
  if (c.control.http.enabled) start_control();
}

// The control API on the I/O thread; its token read once, here.
// The I/O thread sends what the solve thread offered: with loop.realtime it runs at
// SCHED_FIFO below the solve thread and the drivers' threads, so that a frame's way out
// does not wait behind the machine's other work.
void Daemon::start_io_thread(const config::DaemonConfig& c) {
  const int priority = c.loop.realtime ? std::max(1, realtime_priority(int(c.loop.priority)) - 2) : 0;
  const RealtimeReport report = io_->start(priority);
  if (priority == 0) return;
  if (report.fifo_applied)
    spdlog::info("I/O thread (network outputs, control API) runs SCHED_FIFO priority {}", report.priority);
  else
    spdlog::warn("could not make the I/O thread SCHED_FIFO priority {}: {}; network outputs may lag under load",
                 report.priority, std::strerror(report.fifo_errno));
}

void Daemon::start_control() {
  const config::HttpSection& http = config_.values.control.http;
  // The config's checks refused token files others may read.
  auto read_token = [](const std::string& file) {
    if (file.empty()) return std::string();
    const std::vector<char> bytes = read_file_bytes(file);
    std::string token(bytes.begin(), bytes.end());
    token.erase(token.find_last_not_of(" \t\r\n") + 1);
    token.erase(0, token.find_first_not_of(" \t\r\n"));
    if (token.empty()) throw file_error(file, "the control API's token file is empty");
    return token;
  };
  control::AccessOptions access{.operator_token = read_token(http.token_file),
                                .viewer_token = read_token(http.viewer_token_file),
                                .allowed_hosts = split_list(http.allowed_hosts, config::kListSeparators),
                                .allowed_origins = split_list(http.allowed_origins, config::kListSeparators),
                                .session_max_age_s = http.session_max_age_s};
  if (!access.viewer_token.empty() && access.viewer_token == access.operator_token)
    throw file_error(http.viewer_token_file, "the viewer's token is the operator's: give the viewer a token of its own");
  std::optional<control::TlsFiles> tls;
  if (http.tls) {
    tls = control::TlsFiles{.certificate = http.tls_certificate, .key = http.tls_key};
    std::vector<std::string> names{http.address};
    names.insert(names.end(), access.allowed_hosts.begin(), access.allowed_hosts.end());
    const control::TlsIdentity id = control::ensure_tls_identity(*tls, names);
    spdlog::info("control API TLS certificate {} ({}; valid until {}; names {}); SHA-256 fingerprint {}; public key pin "
                 "sha256//{}", tls->certificate, id.generated ? "made now, self-signed" : "loaded", id.not_after,
                 fmt::join(id.names, ", "), id.sha256_fingerprint, id.spki_sha256_base64);
    for (const std::string& warning : id.warnings) spdlog::warn("{}", warning);
  }
  publish_status(monotonic_now_ns());
  const std::string dashboard = http.dashboard_dir.empty() ? default_dashboard_dir() : http.dashboard_dir;
  server_ = std::make_unique<control::ControlServer>(
      io_->context(),
      control::ServerOptions{.address = http.address, .port = uint16_t(http.port), .access = std::move(access),
                             .version = options_.version.empty() ? std::string("facecapd") : options_.version,
                             .dashboard_dir = dashboard,
                             .limits = {.max_connections = std::size_t(http.max_connections),
                                        .max_per_address = std::size_t(http.max_connections_per_address),
                                        .max_stream_clients = std::size_t(http.max_stream_clients)},
                             .tls = std::move(tls)},
      board_, commands_, stream_);
  spdlog::info("control API on {}://{}:{}{}", http.tls ? "https" : "http", http.address.find(':') == std::string::npos ? http.address : "[" + http.address + "]",
               server_->port(), http.token_file.empty() ? "" : " (token or login required)");
}

uint16_t Daemon::control_port() const noexcept { return server_ ? server_->port() : 0; }

// Commands the control API queued, handed to the controller on this thread. One that
// changes what /status says (actor, calibration, take) publishes the status before its
// answer goes out, so a client that asks /status after the answer sees the change.
void Daemon::serve_commands() {
  while (std::optional<control::Command> command = commands_.pop()) {
    if (std::holds_alternative<control::SelectActor>(command->request) ||
        std::holds_alternative<control::Calibrate>(command->request) ||
        std::holds_alternative<control::StartRecording>(command->request) ||
        std::holds_alternative<control::StopRecording>(command->request))
      command->reply = [this, reply = std::move(command->reply)](control::Reply answer) {
        if (server_) publish_status(monotonic_now_ns());
        reply(std::move(answer));
      };
    controller_->execute(std::move(*command));
  }
  controller_->poll();
  if (takes_ && !takes_->file().empty()) recording_file_ = takes_->file();
}

Daemon::Sample Daemon::take_sample() const {
  Sample s;
  s.time_ns = monotonic_now_ns();
  s.cpu_ns = process_cpu_ns();
  const LoopCounters& counters = loop_->counters();
  s.ticks = counters.ticks.load();
  s.frames_solved = counters.frames_solved.load();
  s.idle_ticks = counters.idle_ticks.load();
  s.missed = counters.missed_deadlines.load();
  s.late_start = counters.late_start_misses.load();
  s.skipped = counters.skipped_ticks.load();
  s.fold_deadline_stops = counters.fold_deadline_stops.load();
  s.source = source_->health();
  for (const auto& sink : sinks_)
    if (!sink->drops_by_design()) s.outputs_dropped += sink->health().dropped;
  for (std::size_t bit = 0; bit < kSolvedFlagCount; ++bit) s.flagged[bit] = counters.flagged_frames[bit].load();
  s.markers_used = counters.markers_used.load();
  s.markers_expected = counters.markers_expected.load();
  s.latency = loop_->latency();
  for (std::size_t i = 0; i < kLatencyStageCount; ++i) s.latency_chain[i] = loop_->latency(LatencyStage(i));
  s.residuals_nm = loop_->residuals_nm();
  s.markers = loop_->marker_counts();
  return s;
}

Figures Daemon::figures_between(const Sample& from, const Sample& to) const {
  Figures f;
  f.seconds = double(to.time_ns - from.time_ns) / kNsPerSecond;
  f.ticks = to.ticks - from.ticks;
  f.frames_solved = to.frames_solved - from.frames_solved;
  f.idle_ticks = to.idle_ticks - from.idle_ticks;
  f.missed_deadlines = to.missed - from.missed;
  f.late_start_misses = to.late_start - from.late_start;
  f.skipped_ticks = to.skipped - from.skipped;
  f.fold_deadline_stops = to.fold_deadline_stops - from.fold_deadline_stops;
  f.solved_fps = f.seconds > 0 ? double(f.frames_solved) / f.seconds : 0.0;
  const LatencyHistogram::Snapshot latency = to.latency.since(from.latency);
  f.latency_p50_ns = latency.quantile_ns(0.50);
  f.latency_p99_ns = latency.quantile_ns(0.99);
  f.latency_max_ns = latency.quantile_ns(1.0);
  for (std::size_t i = 0; i < kLatencyStageCount; ++i) {
    const LatencyHistogram::Snapshot stage = to.latency_chain[i].since(from.latency_chain[i]);
    f.latency_chain[i] = {stage.total(), stage.quantile_ns(0.50), stage.quantile_ns(0.99), stage.quantile_ns(1.0)};
  }
  f.cpu_percent = f.seconds > 0 ? 100.0 * double(to.cpu_ns - from.cpu_ns) / (f.seconds * kNsPerSecond) : 0.0;
  f.source_overwritten = to.source.frames_overwritten - from.source.frames_overwritten;
  f.source_late = to.source.frames_late - from.source.frames_late;
  f.source_errors = to.source.errors - from.source.errors;
  f.source_foreign = to.source.foreign - from.source.foreign;
  f.outputs_dropped = to.outputs_dropped - from.outputs_dropped;
  for (std::size_t bit = 0; bit < kSolvedFlagCount; ++bit) f.flagged_frames[bit] = to.flagged[bit] - from.flagged[bit];
  CaptureFigures& capture = f.capture;
  capture.frames = f.frames_solved;
  if (f.frames_solved > 0) {
    const double frames = double(f.frames_solved);
    capture.markers_used = double(to.markers_used - from.markers_used) / frames;
    capture.markers_expected = double(to.markers_expected - from.markers_expected) / frames;
    capture.head_held_fraction = double(f.flagged_frames[std::countr_zero(uint32_t(kSolvedHeadPoseHeld))]) / frames;
    capture.face_held_fraction = double(f.flagged_frames[std::countr_zero(uint32_t(kSolvedTooFewMarkers))]) / frames;
  }
  const LatencyHistogram::Snapshot residuals = to.residuals_nm.since(from.residuals_nm);
  capture.residuals = residuals.total();
  capture.residual_p50_mm = double(residuals.quantile_ns(0.50)) / 1e6;  // nanometres recorded
  capture.residual_p95_mm = double(residuals.quantile_ns(0.95)) / 1e6;
  capture.residual_max_mm = double(residuals.quantile_ns(1.0)) / 1e6;
  if (controller_) capture.markers = marker_quality(marker_figures(to.markers.since(from.markers)));
  // Relabelled every frame, a slot is not one marker: its jitter is not the marker's.
  capture.noise_measured = !config_.values.calibration.label_markers;
  return f;
}

std::vector<MarkerQuality> Daemon::marker_quality(const std::vector<MarkerFigures>& slots) const {
  const pipeline::Calibration& calibration = controller_->calibration();
  const std::vector<std::string>& labels = source_->info().labels;
  // The noise is measured in the source's units, the same as the calibration's take units
  // once the mapper's unit conversion is applied.
  const double mm_per_source_unit =
      millimetres_per_unit(source_->info().units).value_or(calibration.take_mm_per_unit);
  std::vector<MarkerQuality> out;
  for (const align::MarkerCalibration& m : calibration.markers) {
    MarkerQuality q;
    q.label = m.label;
    q.region = marker_region(m.label, m.binding, *rig_);
    const auto slot = std::size_t(std::find(labels.begin(), labels.end(), m.label) - labels.begin());
    if (slot < slots.size()) {  // else the source lacks it: never present
      q.present_fraction = slots[slot].present_fraction;
      q.noise_mm = slots[slot].noise * mm_per_source_unit;
      q.residual_mm = slots[slot].residual_mm;
    }
    out.push_back(std::move(q));
  }
  return out;
}

Figures Daemon::figures_since_start() const { return figures_between(*start_sample_, take_sample()); }

QualityAssessment Daemon::quality(const Figures& window) const {
  QualityAssessment q = assess_quality(window.capture, config_.values.quality);
  if (!units_problem_.empty()) {  // the worst there is: every marker 10 times off
    q.state = CaptureQuality::kBad;
    q.reasons.insert(q.reasons.begin(), "source units: " + units_problem_);
  }
  return q;
}

void Daemon::require_plausible_recorded_units(const pipeline::Calibration& calibration) const {
  const std::span<const MarkerFrame> frames = source_->recorded_frames();
  if (frames.empty()) return;  // a live source: watch_source_units
  const drivers::SourceInfo& info = source_->info();
  const drivers::TakeUnits units = config_.values.source.replay.units;  // the one source with recorded frames
  const pipeline::UnitsCheck check = pipeline::check_frames_units(frames, info.labels, info.units, calibration);
  // A face that fits no unit (another actor's profile, a calibration that is no face's) is
  // not a units mistake: the live check reports it once the loop runs, as for any source.
  if (!check.plausible && check.looks_like)
    throw file_error(config_.values.source.replay.file,
                     pipeline::describe_units(check, units == drivers::TakeUnits::kStated ? "" : info.units, info.units,
                                              "set source.replay.units = \"{}\" if they are"));
}

void Daemon::watch_source_units() {
  if (const uint64_t swaps = loop_->counters().pipeline_swaps.load(); swaps != units_check_swaps_) {
    // Another calibration (an actor, a reload) may have other units or another face.
    units_check_swaps_ = swaps;
    units_check_.emplace(source_->info().labels, source_->info().units, controller_->calibration());
    units_problem_.clear();
    loop_->sample_markers(true);
  }
  rt::SpscSlots<MarkerFrame>& sampled = loop_->sampled_markers();
  for (const MarkerFrame* frame = sampled.front(); frame; frame = sampled.front()) {
    const bool decided = units_check_ && units_check_->add(*frame);
    sampled.pop();
    if (!decided) continue;
    loop_->sample_markers(false);
    const pipeline::UnitsCheck& verdict = *units_check_->verdict();
    if (verdict.plausible) {
      spdlog::info("source units {}: its face is {:.2f} times the size of the calibrated one", source_->info().units.empty()
                   ? "unstated (the calibration's)" : source_->info().units, verdict.size_ratio);
    } else {
      units_problem_ = pipeline::describe_units(verdict, "", source_->info().units,
                                                "check the units the capture system sends, and that the profile is this actor's");
      spdlog::warn("source units implausible: {}; the face is solved as it comes (docs/daemon.md, \"Units\")", units_problem_);
    }
  }
}

std::string Daemon::status_line(const Figures& w) const {
  std::string line = fmt::format("{:.1f} fps, latency p50 {:.2f} ms p99 {:.2f} ms, {} overruns, capture {}", w.solved_fps,
                                 ms(w.latency_p50_ns), ms(w.latency_p99_ns), loop_->counters().missed_deadlines.load(),
                                 quality(w).describe());
  if (w.capture.frames > 0)
    line += fmt::format(", markers {:.1f}/{:.0f}", w.capture.markers_used, w.capture.markers_expected);
  if (w.capture.residuals > 0) line += fmt::format(", residual p95 {:.2f} mm", w.capture.residual_p95_mm);
  if (const std::string chain = latency_chain_text(w); !chain.empty()) line += ", " + chain;
  if (w.source_overwritten + w.source_late > 0)
    line += fmt::format(", source frames lost {}", w.source_overwritten + w.source_late);
  if (w.source_errors > 0) line += fmt::format(", source errors {}", w.source_errors);
  if (w.source_foreign > 0) line += fmt::format(", foreign datagrams {}", w.source_foreign);
  if (w.outputs_dropped > 0) line += fmt::format(", outputs dropped {}", w.outputs_dropped);
  for (const auto& sink : sinks_)
    if (sink->health().failed) line += fmt::format(", output {} FAILED", sink->name());
  if (const std::string flagged = flagged_text(w); !flagged.empty()) line += ", " + flagged;
  if (const drivers::SourceHealth source = source_->health(); !source.state.empty())
    line += fmt::format(", source: {}", source.state.view());
  return line;
}

// "exposure->receive p50 4.12 ms, ->solved 1.20 ms, ->sent 0.02 ms": from a source that
// stamps its exposures (NatNet); "" for others.
std::string Daemon::latency_chain_text(const Figures& w) {
  const LatencyFigures& exposure = w.latency_chain[std::size_t(LatencyStage::kExposureToReceive)];
  if (exposure.frames == 0) return {};
  return fmt::format("exposure->receive p50 {:.2f} ms, ->solved {:.2f} ms, ->sent {:.2f} ms", ms(exposure.p50_ns),
                     ms(w.latency_chain[std::size_t(LatencyStage::kReceiveToSolved)].p50_ns),
                     ms(w.latency_chain[std::size_t(LatencyStage::kSolvedToSent)].p50_ns));
}

// "head_pose_held 12, too_few_markers 3": the frames in a window with each status bit.
std::string Daemon::flagged_text(const Figures& w) {
  std::string text;
  for (std::size_t bit = 0; bit < kSolvedFlagCount; ++bit)
    if (w.flagged_frames[bit] > 0)
      text += fmt::format("{}{} {}", text.empty() ? "" : ", ", solved_flag_name(bit), w.flagged_frames[bit]);
  return text;
}

void Daemon::log_pipeline(const pipeline::SolvePipeline& solve, const pipeline::Calibration& calibration_,
                          double build_seconds) const {
  const pipeline::MarkerMapper& mapper = solve.mapper();
  spdlog::info("{} solver on rig '{}' ({} vertices, {} shapes, weight refinements {}, outer edge hold {:g}, {} kernels "
               "on a CPU with {}) built in {:.2f} s; calibration {}: {} of {} markers in the source, head stabilisation {}{}",
               solve.method(), rig_->name, rig_->vertex_count(), rig_->shape_count(),
               solve.solver_params().weight_refinements, solve.solver_params().boundary_hold,
               kKernelPaths.name(solve.kernel_path()), kernels::cpu_features(), build_seconds, calibration_.source_take, mapper.markers_found(),
               calibration_.markers.size(),
               mapper.stabilising() ? fmt::format("on ({} stable markers)", mapper.stable_markers_found()) : "off",
               mapper.source_to_take() != 1.0 ? fmt::format(", source units scaled by {:g}", mapper.source_to_take()) : "");
  if (!calibration_.unobserved_shapes.empty())
    spdlog::info("{} shapes move no calibrated marker by {} mm at full weight and stay at 0 (left out of the weight "
                 "fit): {}", calibration_.unobserved_shapes.size(), calibration_.observable_shape_mm,
                 fmt::join(calibration_.unfitted_shapes(), ", "));
  if (mapper.markers_found() < calibration_.markers.size())
    spdlog::warn("the source lacks {} of the calibration's markers; they count as missing in every frame",
                 calibration_.markers.size() - mapper.markers_found());
  if (config_.values.calibration.stabilise_head && !mapper.stabilising() && !calibration_.stable_markers.empty())
    spdlog::warn("head stabilisation is off: {} of the calibration's {} stable markers are in the source, 3 are needed",
                 mapper.stable_markers_found(), calibration_.stable_markers.size());
}

void Daemon::apply_live_settings() {
  set_log_level(config_.values.logging.level);
}

bool Daemon::reload() {
  notifier_.reloading();
  spdlog::info("reloading {}", options_.config_file.empty() ? "(defaults)" : options_.config_file);
  const auto reject = [&](std::string_view why, std::string_view problems) {
    spdlog::error("reload rejected ({}); the running configuration stays:", why);
    for (std::size_t at = 0; at < problems.size();) {  // a line each: a message is one line (core/log.cpp)
      const std::size_t end = std::min(problems.find('\n', at), problems.size());
      spdlog::error("  {}", problems.substr(at, end - at));
      at = end + 1;
    }
    notifier_.ready(fmt::format("{} (reload rejected: {})", last_status_, why));
    reloads_rejected_.fetch_add(1, std::memory_order_release);
    return false;
  };
  config::LoadedConfig fresh;
  try {
    fresh = config::load_config(options_.config_file, options_.overrides);
  } catch (const Error& e) {
    return reject("invalid configuration", e.what());
  }
  label_unlabelled_source(fresh.values, source_->info());
  const std::vector<const config::KeySpec*> changed = config::changed_keys(config_.values, fresh.values);
  // Keys that take effect at the next start are checked now, as --check-config does: a
  // reload must not leave a file that a restart (after a crash, at boot) cannot start from.
  if (std::any_of(changed.begin(), changed.end(), [](const auto* key) { return key->reload == config::Reload::kRestart; })) {
    try {
      check_rig_and_calibration(fresh.values);
    } catch (const std::exception& e) {
      return reject("facecapd would not start again with it", e.what());
    }
  }
  bool rebuild = false, calibration_changed = false;
  for (const config::KeySpec* key : changed) {
    const config::Value value = config::get_value(*key, fresh.values);
    switch (key->reload) {
      case config::Reload::kRestart:
        spdlog::warn("{} changed to {}: takes effect after a restart", key->path, config::format_value(value));
        continue;
      case config::Reload::kRebuild:
        rebuild = true;
        calibration_changed = calibration_changed || key->path == "calibration.file";
        break;
      case config::Reload::kLive: break;
    }
    config::set_value(*key, config_.values, value);
    config_.origins[std::size_t(key - config::config_schema().data())] =
        fresh.origins[std::size_t(key - config::config_schema().data())];
    spdlog::info("{} = {}", key->path, config::format_value(value));
  }
  apply_live_settings();
  if (rebuild) controller_->rebuild_for_reload(calibration_changed);
  notifier_.ready(last_status_);
  reloads_accepted_.fetch_add(1, std::memory_order_release);
  return true;
}

void Daemon::supervise_once(int64_t now_ns) {
  const config::DaemonConfig& c = config_.values;
  if (!realtime_logged_ && loop_->realtime_ready()) {
    realtime_logged_ = true;
    const RealtimeReport& report = loop_->realtime_report();
    for (const std::string& line : report.describe(loop_->options().realtime))
      ((report.fifo_applied || !c.loop.realtime) ? spdlog::info("{}", line) : spdlog::warn("{}", line));
  }
  if (!ready_sent_ && loop_->first_frame_solved()) {
    ready_sent_ = true;
    last_status_ = "first frame solved";
    notifier_.ready(last_status_);
    spdlog::info("ready: first frame solved {:.0f} ms after the loop started", ms(now_ns - start_ns_));
  }
  // The watchdog is fed only while the loop keeps ticking: a stuck solve thread lets it expire.
  if (ready_sent_ && notifier_.watchdog_interval_ns() > 0 && now_ns >= next_watchdog_ns_) {
    const uint64_t ticks = loop_->counters().ticks.load(std::memory_order_relaxed);
    if (ticks != ticks_at_last_watchdog_) {
      notifier_.watchdog();
      ticks_at_last_watchdog_ = ticks;
    }
    next_watchdog_ns_ = now_ns + notifier_.watchdog_interval_ns();
  }
  if (now_ns >= next_status_ns_) {
    const Sample sample = take_sample();
    status_window_ = figures_between(*status_sample_, sample);
    last_status_ = status_line(status_window_);
    // Before READY (a device waited for), systemd shows why the service is still starting.
    if (ready_sent_) notifier_.status(last_status_);
    else if (!sample.source.state.empty()) notifier_.status(fmt::format("starting: {}", sample.source.state.view()));
    const CaptureQuality before = quality_hold_.shown().state;
    const int hold_windows = int(std::ceil(c.quality.hold_s / c.control.status_interval_s - 1e-9));
    const QualityAssessment& quality = quality_hold_.update(this->quality(status_window_), hold_windows);
    ++quality_windows_[std::size_t(quality.state)];
    if (quality.state != before) {
      if (quality.state == CaptureQuality::kGood) spdlog::info("capture quality good again");
      else spdlog::warn("capture quality {}", quality.describe());
    }
    *status_sample_ = sample;
    next_status_ns_ = now_ns + int64_t(c.control.status_interval_s * kNsPerSecond);
  }
  if (c.logging.stats_interval_s > 0 && now_ns >= next_stats_ns_) {
    const Sample sample = take_sample();
    const Figures f = figures_between(*stats_sample_, sample);
    spdlog::info("{:.1f} fps over {:.0f} s, latency p50 {:.2f} p99 {:.2f} max {:.2f} ms, {} missed deadlines "
                 "({} started late), {} idle ticks, CPU {:.0f}%", f.solved_fps, f.seconds, ms(f.latency_p50_ns),
                 ms(f.latency_p99_ns), ms(f.latency_max_ns), f.missed_deadlines, f.late_start_misses, f.idle_ticks,
                 f.cpu_percent);
    if (const std::string chain = latency_chain_text(f); !chain.empty()) spdlog::info("latency {}", chain);
    if (f.capture.frames > 0)
      spdlog::info("markers used {:.1f} of {:.0f}, head pose held in {:.1f}% and face in {:.1f}% of frames, fit residual "
                   "p50 {:.2f} p95 {:.2f} max {:.2f} mm; capture {}", f.capture.markers_used, f.capture.markers_expected,
                   100.0 * f.capture.head_held_fraction, 100.0 * f.capture.face_held_fraction, f.capture.residual_p50_mm,
                   f.capture.residual_p95_mm, f.capture.residual_max_mm, quality(f).describe());
    if (const std::string flagged = flagged_text(f); !flagged.empty()) spdlog::warn("frames flagged: {}", flagged);
    if (f.outputs_dropped > 0) spdlog::warn("{} frames dropped by the outputs", f.outputs_dropped);
    if (f.source_errors > 0) spdlog::warn("{} source errors (malformed input, device errors)", f.source_errors);
    if (f.source_foreign > 0)
      spdlog::warn("{} datagrams from senders other than the source's server dropped", f.source_foreign);
    if (!sample.source.state.empty()) spdlog::warn("source: {}", sample.source.state.view());
    *stats_sample_ = sample;
    next_stats_ns_ = now_ns + int64_t(c.logging.stats_interval_s * kNsPerSecond);
  }
  serve_commands();
  watch_source_units();
  loop_->collect_retired();
  if (server_ && now_ns >= next_publish_ns_) publish_status(now_ns);
}

int Daemon::run() {
  const double run_seconds = config_.values.control.run_seconds;
  std::string reason;
  int status = 0;
  while (reason.empty()) {
    if (options_.handle_signals) {
      switch (wait_for_control_signal(kSuperviseSliceNs)) {
        case SIGTERM: reason = "SIGTERM"; break;
        case SIGINT: reason = "SIGINT"; break;
        case SIGHUP: reload(); break;
        default: break;
      }
    } else {
      timespec slice{0, long(kSuperviseSliceNs)};
      nanosleep(&slice, nullptr);
    }
    if (reload_requested_.exchange(false, std::memory_order_acq_rel)) reload();
    const int64_t now = monotonic_now_ns();
    supervise_once(now);
    if (stop_requested_.load(std::memory_order_acquire)) reason = "stop requested";
    else if (loop_->source_finished()) reason = "the source ended";
    else if (run_seconds > 0 && now - start_ns_ >= int64_t(run_seconds * kNsPerSecond)) reason = "run time reached";
    else if (!loop_->running()) {
      reason = "the solve loop exited unexpectedly";
      status = 1;
    }
  }
  shutdown(reason);
  return status;
}

void Daemon::shutdown(const std::string& reason) {
  if (!loop_) return;
  const int64_t begin = monotonic_now_ns();
  notifier_.stopping();
  spdlog::info("stopping: {}", reason);
  if (server_) server_->stop();
  while (std::optional<control::Command> command = commands_.pop()) command->reply(control::error_reply(503, "facecapd is stopping"));
  loop_->request_stop();
  loop_->join();
  source_->stop();
  for (const auto& sink : sinks_) {
    try {
      sink->stop();
      const outputs::SinkHealth h = sink->health();
      std::string delivery;
      if (const LatencyHistogram* d = sink->delivery_latency(); d && h.delivered > 0) {
        const LatencyHistogram::Snapshot snapshot = d->snapshot();
        delivery = fmt::format(", received -> sent p50 {:.2f} p99 {:.2f} ms", ms(snapshot.quantile_ns(0.5)),
                               ms(snapshot.quantile_ns(0.99)));
      }
      // A failed output says so at error level: "0 dropped" must never hide a take not on disk.
      spdlog::log(h.failed ? spdlog::level::err : spdlog::level::info,
                  "output {} {}: {} frames offered, {} delivered, {} dropped{}{}", sink->description(),
                  h.failed ? "FAILED" : "stopped", h.offered, h.delivered, h.dropped,
                  h.errors ? fmt::format(", {} errors", h.errors) : "", delivery);
    } catch (const std::exception& e) {
      spdlog::error("output {}: {}", sink->description(), e.what());
    }
  }
  const Figures run = figures_since_start();
  spdlog::info("run: {} frames solved in {:.1f} s ({:.1f} fps), latency p50 {:.2f} p99 {:.2f} max {:.2f} ms, "
               "{} missed deadlines ({} started late, {} ticks skipped), {} idle ticks, CPU {:.0f}%", run.frames_solved,
               run.seconds, run.solved_fps, ms(run.latency_p50_ns), ms(run.latency_p99_ns), ms(run.latency_max_ns),
               run.missed_deadlines, run.late_start_misses, run.skipped_ticks, run.idle_ticks, run.cpu_percent);
  if (const int64_t margin = loop_->counters().max_jitter_margin_ns.load(); margin > 0)
    spdlog::info("frames arrived late: the ticks waited up to {:.2f} ms longer for them than loop.phase_margin_us",
                 ms(margin));
  if (const std::string chain = latency_chain_text(run); !chain.empty()) spdlog::info("latency {}", chain);
  if (const std::string flagged = flagged_text(run); !flagged.empty()) spdlog::info("frames flagged: {}", flagged);
  if (run.fold_deadline_stops > 0)
    spdlog::info("{} frames' fold stage stopped at the deadline (the rest of their folds left flagged)",
                 run.fold_deadline_stops);
  write_stats_file(run);
  if (takes_ && !takes_->file().empty()) recording_file_ = takes_->file();
  controller_.reset();  // waits for work in flight; replies go to the I/O thread, still running
  loop_.reset();
  server_.reset();
  io_->stop();  // after every sink stopped: none has work left on it
  sinks_.clear();
  io_.reset();
  source_.reset();
  spdlog::info("stopped in {:.0f} ms", ms(monotonic_now_ns() - begin));
}

namespace {

// Every key's value and where it came from.
nlohmann::json config_json(const config::LoadedConfig& loaded) {
  nlohmann::json values = nlohmann::json::object(), origins = nlohmann::json::object();
  for (const config::KeySpec& key : config::config_schema()) {
    const std::string path(key.path);
    std::visit([&](const auto& value) { values[path] = value; }, config::get_value(key, loaded.values));
    const config::KeyOrigin& origin = loaded.origin_of(key.path);
    origins[path] = origin.origin == config::Origin::kFile      ? fmt::format("file {}:{}", origin.where.file, origin.where.line)
                    : origin.origin == config::Origin::kCommandLine ? std::string("--set")
                                                                    : std::string("default");
  }
  return {{"file", loaded.file}, {"values", values}, {"origins", origins}};
}

}  // namespace

// What the control API serves, from the counters now and the last status window.
void Daemon::publish_status(int64_t now_ns) {
  const config::DaemonConfig& c = config_.values;
  const Figures& w = status_window_;
  control::StatusReport r;
  r.version = options_.version;
  r.pid = int64_t(::getpid());
  r.uptime_s = double(now_ns - start_ns_) / kNsPerSecond;
  r.source_driver = drivers::kDriverIds.name(c.source.driver);
  r.source_description = source_->description();
  r.source_rate_hz = source_->info().nominal_rate_hz;
  const Sample now = take_sample();
  const drivers::SourceHealth& source = now.source;
  r.source_delivered = source.frames_delivered;
  r.source_overwritten = source.frames_overwritten;
  r.source_late = source.frames_late;
  r.source_errors = source.errors;
  r.source_foreign = source.foreign;
  r.source_finished = source.finished;
  r.source_units = source_->info().units;
  if (const auto& verdict = units_check_ ? units_check_->verdict() : std::nullopt) {
    r.source_units_check = verdict->plausible ? "plausible" : "implausible";
    r.source_size_ratio = verdict->size_ratio;
    r.source_units_look_like = verdict->looks_like.value_or("");
    r.source_units_problem = units_problem_;
  }
  r.rig_name = rig_->name;
  r.rig_hash = rig_hash_;
  r.rig_vertices = rig_->vertex_count();
  r.rig_shapes = rig_->shape_count();
  r.solver = kSolverMethods.name(c.solver.method);
  r.kernels = kKernelPaths.name(c.solver.kernels == KernelPath::kAuto ? kernels::best_path() : c.solver.kernels);
  r.cpu_features = kernels::cpu_features();
  controller_->report(r);
  r.mode = config::kLoopModes.name(c.loop.mode);
  r.rate_hz = c.loop.rate_hz;
  r.window_s = w.seconds;
  r.solved_fps = w.solved_fps;
  r.cpu_percent = w.cpu_percent;
  r.latency_p50_ms = ms(w.latency_p50_ns);
  r.latency_p99_ms = ms(w.latency_p99_ns);
  r.latency_max_ms = ms(w.latency_max_ns);
  r.window_missed_deadlines = w.missed_deadlines;
  r.markers_used = w.capture.markers_used;
  r.markers_expected = w.capture.markers_expected;
  r.head_held_fraction = w.capture.head_held_fraction;
  r.face_held_fraction = w.capture.face_held_fraction;
  r.residual_p50_mm = w.capture.residual_p50_mm;
  r.residual_p95_mm = w.capture.residual_p95_mm;
  r.residual_max_mm = w.capture.residual_max_mm;
  r.quality = kCaptureQualities.name(quality_hold_.shown().state);
  r.quality_reasons = quality_hold_.shown().reasons;
  r.quality_changes = quality_hold_.changes();
  const pipeline::Calibration& calibration = controller_->calibration();  // the markers' rest places
  for (std::size_t m = 0; m < w.capture.markers.size() && m < calibration.markers.size(); ++m) {
    const MarkerQuality& q = w.capture.markers[m];
    const Eigen::Vector3d& rest = calibration.markers[m].bound_point;
    r.markers.push_back({q.label, q.region, q.present_fraction, q.noise_mm, q.residual_mm, q.missing(), {rest.x(), rest.y(), rest.z()}});
  }
  const LoopCounters& counters = loop_->counters();
  r.ticks = now.ticks;
  r.frames_solved = now.frames_solved;
  r.idle_ticks = now.idle_ticks;
  r.missed_deadlines = now.missed;
  r.late_start_misses = now.late_start;
  r.skipped_ticks = now.skipped;
  r.fold_deadline_stops = now.fold_deadline_stops;
  r.pipeline_swaps = counters.pipeline_swaps.load();
  r.swap_misses = counters.swap_misses.load();
  r.reloads_accepted = reloads_accepted();
  r.reloads_rejected = reloads_rejected();
  for (std::size_t bit = 0; bit < kSolvedFlagCount; ++bit)
    r.flagged_frames.emplace_back(solved_flag_name(bit), now.flagged[bit]);
  for (std::size_t i = 0; i < loop_->sinks().size(); ++i) {
    const outputs::OutputSink& sink = *loop_->sinks()[i];
    const outputs::SinkHealth h = sink.health();
    const LatencyHistogram::Snapshot offer = loop_->sink_timing(i).offer_ns.snapshot();
    r.outputs.push_back({std::string(sink.name()), sink.description(), h.offered, h.delivered, h.dropped, h.errors,
                         h.failed, double(offer.quantile_ns(0.5)) / kNsPerUs, double(offer.quantile_ns(0.99)) / kNsPerUs,
                         double(loop_->sink_timing(i).max_ns.load()) / kNsPerUs});
  }
  auto published = std::make_shared<control::Published>();
  // Text from outside (NatNet marker names, cut to a label's size) may not be UTF-8: replaced, never thrown.
  constexpr auto kReplace = nlohmann::json::error_handler_t::replace;
  published->status_json = control::status_json(r).dump(-1, ' ', false, kReplace) + "\n";
  published->metrics_text = control::metrics_text(r);
  published->config_json = config_json(config_).dump(-1, ' ', false, kReplace) + "\n";
  board_.publish(std::move(published));
  next_publish_ns_ = now_ns + kPublishIntervalNs;
}

void Daemon::write_stats_file(const Figures& f) const {
  const std::string& path = config_.values.logging.stats_file;
  if (path.empty()) return;
  nlohmann::json j;
  j["seconds"] = f.seconds;
  j["rate_hz"] = config_.values.loop.rate_hz;
  j["mode"] = config::kLoopModes.name(config_.values.loop.mode);
  j["rig"] = rig_->name;
  j["solver"] = kSolverMethods.name(config_.values.solver.method);
  j["ticks"] = f.ticks;
  j["frames_solved"] = f.frames_solved;
  j["solved_fps"] = f.solved_fps;
  j["idle_ticks"] = f.idle_ticks;
  j["missed_deadlines"] = f.missed_deadlines;
  j["late_start_misses"] = f.late_start_misses;
  j["skipped_ticks"] = f.skipped_ticks;
  j["fold_deadline_stops"] = f.fold_deadline_stops;
  j["max_wake_late_ms"] = ms(loop_->counters().max_wake_late_ns.load());
  j["max_tick_ms"] = ms(loop_->counters().max_tick_ns.load());
  j["max_jitter_margin_ms"] = ms(loop_->counters().max_jitter_margin_ns.load());
  j["latency_ms"] = {{"p50", ms(f.latency_p50_ns)}, {"p99", ms(f.latency_p99_ns)}, {"max", ms(f.latency_max_ns)}};
  j["cpu_percent"] = f.cpu_percent;
  j["source"] = {{"description", source_->description()}, {"overwritten", f.source_overwritten},
                 {"late", f.source_late}, {"errors", f.source_errors}, {"foreign", f.source_foreign}, {"status", std::string(source_->health().state.view())}};
  nlohmann::json chain = nlohmann::json::object();
  for (std::size_t i = 0; i < kLatencyStageCount; ++i) {
    const LatencyFigures& stage = f.latency_chain[i];
    chain[std::string(latency_stage_name(LatencyStage(i)))] = {
        {"frames", stage.frames}, {"p50", ms(stage.p50_ns)}, {"p99", ms(stage.p99_ns)}, {"max", ms(stage.max_ns)}};
  }
  j["latency_stages_ms"] = chain;
  j["outputs_dropped"] = f.outputs_dropped;
  nlohmann::json flagged = nlohmann::json::object();
  for (std::size_t bit = 0; bit < kSolvedFlagCount; ++bit) flagged[std::string(solved_flag_name(bit))] = f.flagged_frames[bit];
  j["flagged_frames"] = flagged;
  const QualityAssessment run_quality = quality(f);
  j["capture"] = {{"markers_used", f.capture.markers_used},
                  {"markers_expected", f.capture.markers_expected},
                  {"head_held_fraction", f.capture.head_held_fraction},
                  {"face_held_fraction", f.capture.face_held_fraction},
                  {"residual_mm", {{"p50", f.capture.residual_p50_mm}, {"p95", f.capture.residual_p95_mm},
                                   {"max", f.capture.residual_max_mm}}},
                  {"quality", kCaptureQualities.name(run_quality.state)},
                  {"quality_reasons", run_quality.reasons}};
  nlohmann::json windows = nlohmann::json::object();
  for (const auto& entry : kCaptureQualities.entries()) windows[std::string(entry.name)] = quality_windows_[std::size_t(entry.value)];
  j["quality_windows"] = windows;
  // The state shown (after the hold) at the end, and how often it changed.
  j["quality_shown"] = {{"state", kCaptureQualities.name(quality_hold_.shown().state)},
                        {"reasons", quality_hold_.shown().reasons},
                        {"changes", quality_hold_.changes()}};
  nlohmann::json outputs = nlohmann::json::object();
  for (std::size_t i = 0; i < loop_->sinks().size(); ++i) {
    const outputs::OutputSink& sink = *loop_->sinks()[i];
    const outputs::SinkHealth h = sink.health();
    const LatencyHistogram::Snapshot offer = loop_->sink_timing(i).offer_ns.snapshot();
    nlohmann::json& out = outputs[std::string(sink.name())] = {
        {"description", sink.description()}, {"offered", h.offered}, {"delivered", h.delivered},
        {"dropped", h.dropped}, {"errors", h.errors}, {"failed", h.failed}, {"bytes", h.bytes},
        {"offer_us", {{"p50", double(offer.quantile_ns(0.5)) / kNsPerUs}, {"p99", double(offer.quantile_ns(0.99)) / kNsPerUs},
                      {"max", double(loop_->sink_timing(i).max_ns.load()) / kNsPerUs}}}};
    // Sinks that deliver on their own thread: marker frame received -> delivered (sent).
    if (const LatencyHistogram* delivery = sink.delivery_latency()) {
      const LatencyHistogram::Snapshot d = delivery->snapshot();
      out["delivery_ms"] = {{"p50", ms(d.quantile_ns(0.5))}, {"p99", ms(d.quantile_ns(0.99))}, {"max", ms(d.quantile_ns(1.0))}};
    }
  }
  j["outputs"] = outputs;
  nlohmann::json stages;
  const LoopCounters& counters = loop_->counters();
  const double frames = f.frames_solved > 0 ? double(f.frames_solved) : 1.0;
  for (std::size_t s = 0; s < kLoopStageCount; ++s)
    stages[std::string(loop_stage_name(LoopStage(s)))] = {{"mean_ms", ms(counters.stage_total_ns[s].load()) / frames},
                                                           {"max_ms", ms(counters.stage_max_ns[s].load())}};
  for (std::size_t s = 0; s < kSolveStageCount; ++s)
    stages["solver." + std::string(solve_stage_name(SolveStage(s)))] = {
        {"mean_ms", ms(counters.solver_stage_total_ns[s].load()) / frames}};
  j["stages"] = stages;
  std::ofstream out(path, std::ios::trunc);
  out << j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace) << "\n";
  if (!out) spdlog::error("cannot write the stats file {}", path);
}

}  // namespace facecap::daemon
