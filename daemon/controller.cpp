#include "daemon/controller.hpp"

#include <algorithm>
#include <ctime>

#include <fmt/format.h>

#include "core/error.hpp"
#include "core/log.hpp"
#include "core/time.hpp"
#include "core/units.hpp"
#include "formats/recording.hpp"
#include "outputs/table.hpp"
#include "pipeline/capture_calibration.hpp"
#include "pipeline/recording_header.hpp"
#include "pipeline/settings.hpp"

namespace facecap::daemon {
namespace fs = std::filesystem;
using control::error_reply;
using control::Reply;
using control::ReplyFn;
using nlohmann::json;

namespace {

double seconds_since(std::chrono::steady_clock::time_point t) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
}

std::string local_stamp() {
  const std::time_t now = std::time(nullptr);
  std::tm local{};
  localtime_r(&now, &local);
  char stamp[32];
  std::strftime(stamp, sizeof stamp, "%Y%m%d-%H%M%S", &local);
  return stamp;
}

// What a solve pipeline made for `calibration` reports about it.
json describe(const pipeline::SolvePipeline& solve, const pipeline::Calibration& calibration, double build_seconds) {
  return {{"calibration", calibration.source_take},
          {"markers", calibration.markers.size()},
          {"markers_in_source", solve.mapper().markers_found()},
          {"head_stabilised", solve.mapper().stabilising()},
          {"build_seconds", build_seconds}};
}

}  // namespace

Controller::Controller(ControllerParts parts, pipeline::Calibration calibration, std::string actor)
    : parts_(std::move(parts)),
      calibration_(std::move(calibration)),
      actor_(std::move(actor)),
      take_started_(std::chrono::steady_clock::now()) {}

Controller::~Controller() {
  const Reply stopping = error_reply(503, "facecapd is stopping");
  for (Job& job : jobs_) job.reply(stopping);
  if (building_reply_) building_reply_(stopping);
  if (calibration_reply_) calibration_reply_(stopping);
  for (const ReplyFn& reply : stop_replies_) reply(stopping);
  if (building_.valid()) building_.wait();  // the pipeline it builds goes with it
}

void Controller::execute(control::Command command) {
  std::visit(
      [&](const auto& request) {
        using T = std::decay_t<decltype(request)>;
        if constexpr (std::is_same_v<T, control::ListActors>) list_actors(std::move(command.reply));
        else if constexpr (std::is_same_v<T, control::SelectActor>) select_actor(request, std::move(command.reply));
        else if constexpr (std::is_same_v<T, control::Calibrate>) calibrate(request, std::move(command.reply));
        else if constexpr (std::is_same_v<T, control::StartRecording>) start_recording(request, std::move(command.reply));
        else if constexpr (std::is_same_v<T, control::StopRecording>) stop_recording(std::move(command.reply));
        else if constexpr (std::is_same_v<T, control::ListRecordings>) list_recordings(std::move(command.reply));
        else read_recording(request, std::move(command.reply));
      },
      command.request);
}

void Controller::poll() {
  for (auto job = jobs_.begin(); job != jobs_.end();) {
    if (job->result.wait_for(std::chrono::seconds(0)) != std::future_status::ready) {
      ++job;
      continue;
    }
    job->reply(job->result.get());
    job = jobs_.erase(job);
  }
  adopt_built();
  step_calibration();
  finish_stopped_take();
}

// ---------------------------------------------------------------- building aside

void Controller::build(std::string what, std::function<Built()> make, ReplyFn reply) {
  if (building_.valid()) {
    if (reply) reply(error_reply(409, fmt::format("busy {}; try again when it is done", building_what_)));
    return;
  }
  spdlog::info("{} aside", what);
  building_what_ = std::move(what);
  building_reply_ = std::move(reply);
  building_ = std::async(std::launch::async, std::move(make));
}

void Controller::adopt_built() {
  if (!building_.valid() || building_.wait_for(std::chrono::seconds(0)) != std::future_status::ready) return;
  ReplyFn reply = std::exchange(building_reply_, nullptr);
  try {
    Built built = building_.get();
    if (parts_.takes) parts_.takes->set_start_state_bytes(built.pipeline->encoded_state_size());
    parts_.loop->offer_pipeline(std::move(built.pipeline));
    calibration_ = std::move(built.calibration);
    actor_ = std::move(built.actor);
    spdlog::info("new solver handed to the loop ({}, calibration {}{})", kSolverMethods.name(parts_.config->solver.method),
                 calibration_.source_take, actor_.empty() ? "" : fmt::format(", actor {}", actor_));
    if (reply) reply({200, std::move(built.report)});
  } catch (const std::exception& e) {
    spdlog::error("{} failed; the running solver stays: {}", building_what_, e.what());
    if (reply) reply(error_reply(422, e.what()));
  }
  if (calibration_step_ == CalibrationStep::kSolving) {
    calibration_step_ = CalibrationStep::kIdle;
    calibration_reply_ = nullptr;
  }
  building_what_.clear();
  if (std::exchange(rebuild_again_, false)) rebuild_for_reload(std::exchange(rebuild_with_config_calibration_, false));
}

void Controller::rebuild_for_reload(bool calibration_changed) {
  if (building_.valid()) {
    rebuild_again_ = true;
    rebuild_with_config_calibration_ = rebuild_with_config_calibration_ || calibration_changed;
    return;
  }
  const config::DaemonConfig& c = *parts_.config;
  const drivers::SourceInfo info = parts_.source->info();
  const pipeline::SolveSettings settings = pipeline::solve_settings(c, pipeline::SolveContext::kLive);
  std::optional<pipeline::CalibrationSpec> spec;
  if (calibration_changed) spec = pipeline::calibration_spec(c);
  build("rebuilding the solver",
        [rig = parts_.rig, info, settings, spec, calibration = calibration_, actor = actor_]() mutable {
          Built built;
          built.calibration = spec ? pipeline::load_calibration(*spec, *rig) : std::move(calibration);
          built.actor = spec ? (spec->file.empty() ? std::string() : fs::path(spec->file).stem().string()) : actor;
          built.pipeline = std::make_unique<pipeline::SolvePipeline>(*rig, built.calibration,
                                                                     pipeline::SourceDescription{info.labels, info.units}, settings);
          return built;
        },
        nullptr);
}

// ---------------------------------------------------------------- actors

void Controller::list_actors(ReplyFn reply) {
  const fs::path directory = parts_.config->calibration.profiles_directory;
  jobs_.push_back({std::async(std::launch::async,
                              [rig = parts_.rig, directory, current = actor_]() -> Reply {
                                json actors = json::array();
                                std::error_code ec;
                                std::vector<fs::path> files;
                                for (const auto& entry : fs::directory_iterator(directory, ec))
                                  if (entry.path().extension() == ".toml") files.push_back(entry.path());
                                std::sort(files.begin(), files.end());
                                for (const fs::path& file : files) {
                                  json actor = {{"name", file.stem().string()}, {"file", file.string()}};
                                  try {
                                    const pipeline::Calibration c = pipeline::load_calibration({.file = file.string()}, *rig);
                                    actor["usable"] = true;
                                    actor["markers"] = c.markers.size();
                                    actor["stable_markers"] = c.stable_markers.size();
                                    actor["calibrated_from"] = c.source_take;
                                  } catch (const std::exception& e) {
                                    actor["usable"] = false;
                                    actor["error"] = e.what();
                                  }
                                  actors.push_back(std::move(actor));
                                }
                                return {200, {{"directory", directory.string()}, {"current", current}, {"actors", actors}}};
                              }),
                   std::move(reply)});
}

std::string Controller::conflict_for_calibration() const {
  if (parts_.takes && parts_.takes->recording()) return "a take is being recorded: stop it before changing the calibration";
  if (calibration_step_ != CalibrationStep::kIdle) return "a calibration is in progress";
  if (building_.valid()) return fmt::format("busy {}", building_what_);
  return {};
}

void Controller::select_actor(const control::SelectActor& request, ReplyFn reply) {
  if (const std::string conflict = conflict_for_calibration(); !conflict.empty()) return reply(error_reply(409, conflict));
  // Both only name a file in the profiles directory (the API refuses paths).
  const fs::path file = fs::path(parts_.config->calibration.profiles_directory) /
                        (request.name.empty() ? request.file : request.name + ".toml");
  std::error_code ec;
  if (!fs::is_regular_file(file, ec))
    return reply(error_reply(404, request.name.empty() ? fmt::format("no file {}", file.string())
                                                       : fmt::format("no profile \"{}\" ({} does not exist)", request.name,
                                                                     file.string())));
  const std::string actor = request.name.empty() ? file.stem().string() : request.name;
  const drivers::SourceInfo info = parts_.source->info();
  build(fmt::format("loading actor {}", actor),
        [rig = parts_.rig, info, settings = pipeline::solve_settings(*parts_.config, pipeline::SolveContext::kLive), file, actor] {
          const int64_t begin = monotonic_now_ns();
          Built built;
          built.calibration = pipeline::load_calibration({.file = file.string()}, *rig);
          built.pipeline = std::make_unique<pipeline::SolvePipeline>(*rig, built.calibration,
                                                                     pipeline::SourceDescription{info.labels, info.units}, settings);
          built.actor = actor;
          built.report = describe(*built.pipeline, built.calibration, double(monotonic_now_ns() - begin) / kNsPerSecond);
          built.report["actor"] = actor;
          built.report["file"] = file.string();
          return built;
        },
        std::move(reply));
}

// ---------------------------------------------------------------- calibration on the box

void Controller::calibrate(const control::Calibrate& request, ReplyFn reply) {
  if (!parts_.takes) return reply(error_reply(409, "this facecapd has no recording output to capture with"));
  if (const std::string conflict = conflict_for_calibration(); !conflict.empty()) return reply(error_reply(409, conflict));
  const fs::path profile = fs::path(parts_.config->calibration.profiles_directory) / (request.save + ".toml");
  std::error_code ec;
  if (!request.save.empty() && !request.replace && fs::exists(profile, ec))
    return reply(error_reply(409, fmt::format("profile \"{}\" exists ({}): choose another name, or replace it (\"replace\": true, "
                                              "facecap ctl calibrate --save NAME --force; the old one is kept as a backup)",
                                              request.save, profile.string())));
  control::StartRecording capture;
  capture.take = "calibration-" + local_stamp();
  capture.actor = request.save;
  capture.markers_only = true;
  const formats::RecordingHeader header = take_header(capture);
  try {
    capture_file_ = outputs::take_path(parts_.config->outputs.recording.directory, header);
    outputs::RecorderOptions options = outputs::take_options(*parts_.config, header, capture_file_);
    options.markers = true;
    options.solved = false;
    parts_.takes->start_take(std::move(options));
  } catch (const Error& e) {
    return reply(error_reply(500, fmt::format("cannot capture: {}", e.what())));
  }
  spdlog::info("calibrating: capturing {:g} s of markers into {}", request.seconds, capture_file_.string());
  calibration_request_ = request;
  calibration_reply_ = std::move(reply);
  capture_until_ = std::chrono::steady_clock::now() + std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                                                          std::chrono::duration<double>(request.seconds));
  calibration_step_ = CalibrationStep::kCapturing;
}

void Controller::step_calibration() {
  if (calibration_step_ == CalibrationStep::kCapturing && std::chrono::steady_clock::now() >= capture_until_) {
    if (parts_.takes->stop_take()) calibration_step_ = CalibrationStep::kClosingCapture;
    return;
  }
  if (calibration_step_ != CalibrationStep::kClosingCapture) return;
  std::optional<outputs::TakeSummary> summary;
  try {
    summary = parts_.takes->finish_stopped();
  } catch (const Error& e) {
    calibration_step_ = CalibrationStep::kIdle;
    std::exchange(calibration_reply_, nullptr)(error_reply(500, fmt::format("the capture failed: {}", e.what())));
    return;
  }
  if (!summary) return;
  spdlog::info("calibrating: {} frames captured; solving the calibration aside", summary->counters.marker_frames);
  calibration_step_ = CalibrationStep::kSolving;
  const drivers::SourceInfo info = parts_.source->info();
  const fs::path profile_dir = parts_.config->calibration.profiles_directory;
  // The reply is the build's; calibration_reply_ stays set only to answer 503 on a stop.
  build("calibrating",
        [rig = parts_.rig, info, settings = pipeline::solve_settings(*parts_.config, pipeline::SolveContext::kLive), file = summary->file,
         request = calibration_request_, profile_dir, min_presence = parts_.config->calibration.neutral_min_presence] {
          const int64_t begin = monotonic_now_ns();
          formats::MarkerTake take = formats::take_from_recording(formats::RecordingReader(file));
          if (take.rate_hz <= 0) take.rate_hz = info.nominal_rate_hz;
          const pipeline::CaptureCalibration calibrated = pipeline::calibrate_capture(*rig, take, file.filename().string(), min_presence);
          Built built;
          built.calibration = calibrated.result.calibration;
          built.pipeline = std::make_unique<pipeline::SolvePipeline>(*rig, built.calibration,
                                                                     pipeline::SourceDescription{info.labels, info.units}, settings);
          json markers = json::object();
          for (const auto& m : built.calibration.markers) markers[m.label] = m.residual_mm;
          built.report = describe(*built.pipeline, built.calibration, double(monotonic_now_ns() - begin) / kNsPerSecond);
          built.report.update({{"capture", file.string()},
                               {"frames", take.frames.size()},
                               {"neutral_frame", built.calibration.source_frame},
                               {"averaged_frames", calibrated.result.count},
                               {"units", unit_name(built.calibration.take_mm_per_unit)},
                               {"scale", built.calibration.take_to_rig.scale},
                               {"hull_rms_mm", built.calibration.hull_rms_mm},
                               {"trimmed_rms_mm", built.calibration.trimmed_rms_mm},
                               {"residual_mm", {{"median", calibrated.residual_median_mm}, {"max", calibrated.residual_max_mm}}},
                               {"marker_residual_mm", markers},
                               {"stable_markers", built.calibration.stable_markers},
                               {"notes", built.calibration.notes},
                               {"warnings", calibrated.warnings},
                               {"profile", nullptr},
                               {"backup", nullptr}});
          for (const auto& w : calibrated.warnings) spdlog::warn("calibration: {}", w);
          if (!request.save.empty()) {
            const fs::path profile = profile_dir / (request.save + ".toml");
            if (const auto backup = pipeline::save_profile(profile, built.calibration, request.replace))
              built.report["backup"] = backup->string();
            built.report["profile"] = profile.string();
            built.actor = request.save;
          }
          built.report["actor"] = built.actor;
          return built;
        },
        std::exchange(calibration_reply_, nullptr));
}

// ---------------------------------------------------------------- takes

formats::RecordingHeader Controller::take_header(const control::StartRecording& slate) const {
  const config::DaemonConfig& c = *parts_.config;
  const drivers::SourceInfo& info = parts_.source->info();
  formats::RecordingHeader h = pipeline::make_recording_header(
      *parts_.rig, calibration_, {info.labels, info.units}, parts_.source->description(),
      pipeline::recorded_rate_hz(info.nominal_rate_hz, c.loop.rate_hz, c.loop.mode == config::LoopMode::kLockstep),
      pipeline::solve_settings_toml(c, pipeline::SolveContext::kLive));
  h.take = slate.take;
  h.actor = slate.actor.empty() ? actor_ : slate.actor;
  h.scene = slate.scene;
  h.shot = slate.shot;
  h.notes = slate.notes;
  if (slate.markers_only) {
    // Raw markers for an actor without a profile: nothing about a solve applies.
    h.rig_name.clear();
    h.rig_hash = 0;
    h.rig_units.clear();
    h.calibration.clear();
    h.shape_names.clear();
    h.solver_settings.clear();
  }
  return h;
}

void Controller::start_recording(const control::StartRecording& request, ReplyFn reply) {
  if (!parts_.takes) return reply(error_reply(409, "this facecapd has no recording output"));
  if (calibration_step_ != CalibrationStep::kIdle) return reply(error_reply(409, "a calibration is capturing; try again after it"));
  if (parts_.takes->recording()) return reply(error_reply(409, "a take is being recorded: stop it first"));
  const fs::path directory = parts_.config->outputs.recording.directory;
  control::StartRecording slate = request;
  if (slate.take.empty()) slate.take = outputs::next_take_number(directory, slate.scene, slate.shot);
  const formats::RecordingHeader header = take_header(slate);
  fs::path file;
  try {
    file = outputs::take_path(directory, header);
  } catch (const Error& e) {
    return reply(error_reply(409, e.what()));
  }
  try {
    outputs::RecorderOptions options = outputs::take_options(*parts_.config, header, file);
    if (request.markers_only) options.solved = false, options.markers = true;
    parts_.takes->start_take(std::move(options));
  } catch (const Error& e) {
    return reply(error_reply(e.what() == std::string_view("the last take is still closing") ? 409 : 500, e.what()));
  }
  slate_ = slate;
  slate_.actor = header.actor;
  take_started_ = std::chrono::steady_clock::now();
  spdlog::info("recording take {} to {}{}", slate.take, file.string(), request.markers_only ? " (markers only)" : "");
  reply({200,
         {{"file", file.string()}, {"take", header.take}, {"actor", header.actor}, {"scene", header.scene},
          {"shot", header.shot}, {"markers_only", request.markers_only}, {"rate_hz", header.rate_hz}}});
}

void Controller::stop_recording(ReplyFn reply) {
  if (!parts_.takes || !parts_.takes->recording() || calibration_step_ != CalibrationStep::kIdle)
    return reply(error_reply(409, "no take is being recorded"));
  stop_replies_.push_back(std::move(reply));
  if (!parts_.takes->stop_take()) stop_pending_ = true;  // still starting: stopped at the next poll
}

void Controller::finish_stopped_take() {
  if (!parts_.takes || calibration_step_ == CalibrationStep::kClosingCapture || stop_replies_.empty()) return;
  if (stop_pending_ && parts_.takes->stop_take()) stop_pending_ = false;
  Reply answer;
  try {
    const std::optional<outputs::TakeSummary> summary = parts_.takes->finish_stopped();
    if (!summary) return;
    if (summary->failure.empty())
      spdlog::info("take {} stopped: {} marker frames, {} solved frames, {} dropped", summary->file.string(),
                   summary->counters.marker_frames, summary->counters.solved_frames, summary->counters.dropped);
    else
      spdlog::error("take {} FAILED: {}; it holds {} marker frames and {} solved frames, {} frames dropped",
                    summary->file.string(), summary->failure, summary->counters.marker_frames,
                    summary->counters.solved_frames, summary->counters.dropped);
    answer = {200,
              {{"file", summary->file.string()}, {"take", slate_.take}, {"seconds", seconds_since(take_started_)},
               {"marker_frames", summary->counters.marker_frames}, {"solved_frames", summary->counters.solved_frames},
               {"dropped", summary->counters.dropped}, {"errors", summary->counters.errors},
               {"failure", summary->failure}}};
  } catch (const Error& e) {
    answer = error_reply(500, fmt::format("the take's file could not be finished: {}", e.what()));
  }
  for (const ReplyFn& reply : stop_replies_) reply(answer);
  stop_replies_.clear();
}

void Controller::report(control::StatusReport& r) const {
  r.actor = actor_;
  r.calibration = calibration_.source_take;
  r.calibration_markers = calibration_.markers.size();
  const std::vector<std::string>& labels = parts_.source->info().labels;
  auto in_source = [&](const std::string& label) { return std::find(labels.begin(), labels.end(), label) != labels.end(); };
  r.calibration_markers_found = uint64_t(std::count_if(calibration_.markers.begin(), calibration_.markers.end(),
                                                       [&](const auto& m) { return in_source(m.label); }));
  r.head_stabilised = parts_.config->calibration.stabilise_head &&
                      std::count_if(calibration_.stable_markers.begin(), calibration_.stable_markers.end(), in_source) >= 3;
  r.unobserved_shapes = calibration_.unfitted_shapes();
  switch (calibration_step_) {
    case CalibrationStep::kCapturing: r.busy = "calibrating: capturing the neutral"; break;
    case CalibrationStep::kClosingCapture:
    case CalibrationStep::kSolving: r.busy = "calibrating"; break;
    case CalibrationStep::kIdle: r.busy = building_what_; break;
  }
  if (!parts_.takes || !parts_.takes->recording() || calibration_step_ != CalibrationStep::kIdle) return;
  control::TakeReport& t = r.recording;
  t.active = true;
  t.file = parts_.takes->file().string();
  t.take = slate_.take;
  t.actor = slate_.actor;
  t.scene = slate_.scene;
  t.shot = slate_.shot;
  t.notes = slate_.notes;
  t.markers_only = slate_.markers_only;
  t.seconds = seconds_since(take_started_);
  const outputs::RecorderCounters counters = parts_.takes->take_counters();
  t.frames_written = std::max(counters.marker_frames, counters.solved_frames);
  t.frames_dropped = counters.dropped;
  t.failed = counters.errors > 0;
}

// ---------------------------------------------------------------- recordings

void Controller::read_on_worker(std::function<Reply()> read, ReplyFn reply) {
  // The reply is shared: run and drop each may be the one to answer.
  auto answer = std::make_shared<ReplyFn>(std::move(reply));
  const bool queued = replay_workers_.try_submit(
      [read = std::move(read), answer] {
        Reply result;
        try {
          result = read();
        } catch (const std::exception& e) {
          result = error_reply(500, fmt::format("reading the recording failed: {}", e.what()));
        }
        (*answer)(std::move(result));
      },
      [answer] { (*answer)(error_reply(503, "facecapd is stopping")); });
  if (!queued) {
    Reply busy = error_reply(503, fmt::format("{} reads of recordings are already running or waiting; try again",
                                              kReplayWorkers + kReplayQueue));
    busy.retry_after_s = 1;
    (*answer)(std::move(busy));
  }
}

void Controller::list_recordings(ReplyFn reply) {
  read_on_worker([directory = parts_.config->outputs.recording.directory] { return control::list_recordings(directory); },
                 std::move(reply));
}

void Controller::read_recording(const control::ReadRecording& request, ReplyFn reply) {
  if (!replay_rig_) {
    auto rig = std::make_shared<control::ReplayRig>();
    rig->hash = parts_.rig->content_hash();
    rig->vertex_count = uint32_t(parts_.rig->vertex_count());
    rig->triangles.assign(parts_.rig->triangles.data(), parts_.rig->triangles.data() + parts_.rig->triangles.size());
    rig->blend = [face = parts_.rig](const Eigen::VectorXf& weights, Eigen::Matrix3Xf& vertices) {
      vertices = face->linear_blend(weights.cast<double>()).cast<float>();
    };
    replay_rig_ = std::move(rig);
  }
  read_on_worker([directory = parts_.config->outputs.recording.directory, request, rig = replay_rig_] {
    return control::recording_frames(directory, request, *rig);
  }, std::move(reply));
}

}  // namespace facecap::daemon
