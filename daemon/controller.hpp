#pragma once
// What changes while facecapd runs, carried out on the supervisor's thread: the
// calibration (an actor's profile, one calibrated on the box from the live source, or a
// reload's) built aside and handed to the solve loop between two frames; takes started and
// stopped; and the control API's commands, which arrive through a bounded queue. Long work
// (loading profiles, calibrating, building a solve pipeline, closing a take) runs on
// worker threads; nothing here waits on the solve thread or the I/O thread. Not real-time
// code.
#include <chrono>
#include <cstdint>
#include <future>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "config/daemon_config.hpp"
#include "control/bounded_workers.hpp"
#include "control/commands.hpp"
#include "control/recordings.hpp"
#include "control/status.hpp"
#include "daemon/solve_loop.hpp"
#include "drivers/api/marker_source.hpp"
#include "outputs/recording/take_recorder.hpp"
#include "pipeline/calibration.hpp"
#include "pipeline/solve_pipeline.hpp"
#include "solver/rig.hpp"

namespace facecap::daemon {

struct ControllerParts {
  std::shared_ptr<const Rig> rig;
  const drivers::MarkerSource* source = nullptr;
  SolveLoop* loop = nullptr;
  outputs::TakeRecorder* takes = nullptr;  // null: no recording output
  const config::DaemonConfig* config = nullptr;  // the running configuration; reloads change it
};

// Reads of recordings run at most this many at a time, and this many more wait; beyond
// that a read is answered 503 with Retry-After (docs/control-api.md, "Limits").
inline constexpr std::size_t kReplayWorkers = 2;
inline constexpr std::size_t kReplayQueue = 8;

class Controller {
 public:
  // actor: the profile's name when the calibration is one ("" otherwise).
  Controller(ControllerParts parts, pipeline::Calibration calibration, std::string actor);
  // Waits for work in flight; commands still waiting are answered 503.
  ~Controller();
  Controller(const Controller&) = delete;
  Controller& operator=(const Controller&) = delete;

  // A reload changed keys the solve depends on: builds a new pipeline aside, with the
  // configuration's calibration when calibration_changed, else with the one in use.
  void rebuild_for_reload(bool calibration_changed);
  // Starts a control command (answered through its reply, now or later).
  void execute(control::Command command);
  // Each supervisor slice: hands over finished builds, steps a calibration, closes
  // stopped takes, answers what is done.
  void poll();

  const pipeline::Calibration& calibration() const noexcept { return calibration_; }
  // The current actor's name and calibration, the take and any work in flight.
  void report(control::StatusReport& report) const;

 private:
  struct Built {
    std::unique_ptr<pipeline::SolvePipeline> pipeline;
    pipeline::Calibration calibration;
    std::string actor;
    nlohmann::json report;  // the command's answer
  };
  struct Job {
    std::future<control::Reply> result;
    control::ReplyFn reply;
  };
  enum class CalibrationStep : uint8_t { kIdle, kCapturing, kClosingCapture, kSolving };

  void list_actors(control::ReplyFn reply);
  void select_actor(const control::SelectActor& request, control::ReplyFn reply);
  void calibrate(const control::Calibrate& request, control::ReplyFn reply);
  void start_recording(const control::StartRecording& request, control::ReplyFn reply);
  void stop_recording(control::ReplyFn reply);
  // The replay page's reads of outputs.recording.directory, on replay_workers_; a worker
  // answers itself, so that neither the read nor its answer's encoding waits for this thread.
  void list_recordings(control::ReplyFn reply);
  void read_recording(const control::ReadRecording& request, control::ReplyFn reply);
  void read_on_worker(std::function<control::Reply()> read, control::ReplyFn reply);
  // Builds a solve pipeline aside (one at a time) from what `make` returns.
  void build(std::string what, std::function<Built()> make, control::ReplyFn reply);
  void adopt_built();
  void step_calibration();
  void finish_stopped_take();
  // Who else is using the loop's calibration or the recorder (409 text), or "".
  std::string conflict_for_calibration() const;
  formats::RecordingHeader take_header(const control::StartRecording& slate) const;

  ControllerParts parts_;
  pipeline::Calibration calibration_;
  std::string actor_;

  std::future<Built> building_;
  std::string building_what_;
  control::ReplyFn building_reply_;
  bool rebuild_again_ = false;  // a reload arrived while a build was in flight
  bool rebuild_with_config_calibration_ = false;

  std::vector<Job> jobs_;
  std::shared_ptr<const control::ReplayRig> replay_rig_;  // made at the first read_recording

  CalibrationStep calibration_step_ = CalibrationStep::kIdle;
  control::Calibrate calibration_request_;
  control::ReplyFn calibration_reply_;
  std::chrono::steady_clock::time_point capture_until_;
  std::filesystem::path capture_file_;

  control::StartRecording slate_;  // of the take being recorded
  std::chrono::steady_clock::time_point take_started_;
  std::vector<control::ReplyFn> stop_replies_;  // answered once the take is closed
  bool stop_pending_ = false;                  // stop asked while the take was still starting

  // Last, so that it stops (its queued reads answered 503) before anything else goes.
  control::BoundedWorkers replay_workers_{kReplayWorkers, kReplayQueue};
};

}  // namespace facecap::daemon
