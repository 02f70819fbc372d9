#pragma once
// The recording output: takes started and stopped while facecapd runs, one .fcrec file
// each (a Recorder with its own writer thread). The supervisor makes a take's Recorder
// aside and hands it over through an rt::Handoff; the solve thread adopts it between two
// frames (tick) and gives a stopped one back the same way, so starting and stopping never
// takes a lock on the solve thread or drops a frame of the loop. Between takes, offer()
// does nothing.
#include <filesystem>
#include <memory>
#include <mutex>
#include <optional>
#include <string>

#include "core/rt/handoff.hpp"
#include "outputs/api/sink.hpp"
#include "outputs/recording/recorder.hpp"

namespace facecap::outputs {

// What a finished take recorded.
struct TakeSummary {
  std::filesystem::path file;
  RecorderCounters counters;
  SinkHealth health;
  std::string failure;  // why the take stopped early ("" when it did not)
};

class TakeRecorder final : public OutputSink {
 public:
  // vertex_count: the rig's; record_vertices: whether takes may record solved vertices
  // (the loop solves them only when some output wants them); start_state_bytes: the
  // solve's encoded state, which takes of solved frames store before their first frame.
  // Not RT-safe.
  TakeRecorder(Eigen::Index vertex_count, bool record_vertices, std::size_t start_state_bytes);
  // stop(). Not RT-safe.
  ~TakeRecorder() override;
  TakeRecorder(const TakeRecorder&) = delete;
  TakeRecorder& operator=(const TakeRecorder&) = delete;

  std::string_view name() const noexcept override { return "recording"; }
  std::string description() const override;
  bool wants_vertices() const noexcept override { return record_vertices_; }
  // Adopts a take started or stopped since the last tick. RT-safe.
  void tick(int64_t now_ns) noexcept override;
  // The take being recorded's (Recorder::wants_start_state). RT-safe.
  bool wants_start_state() const noexcept override;
  void offer_start_state(std::span<const char> state) noexcept override;
  // Queues the frame into the take being recorded, if any. RT-safe.
  void offer(const MarkerFrame& markers, const SolvedFrame& solved) noexcept override;
  bool ready() noexcept override;
  // Every take's counters added up. Any thread.
  SinkHealth health() const noexcept override;
  // Closes the take being recorded and any stopped one. Call once the loop has stopped.
  // Not RT-safe; throws Error when a file's last write fails.
  void stop() override;

  // The supervisor's side (one thread, not RT-safe):
  // Creates the take's file and writer thread and hands it to the loop, which records
  // from its next tick. Throws Error (a take is being recorded or still closing, the file
  // cannot be created).
  void start_take(RecorderOptions options);
  // The solve's encoded state size after the loop was given a new pipeline: the room
  // takes started from now on keep for it.
  void set_start_state_bytes(std::size_t bytes);
  // Asks the loop to let go of the take being recorded; false when there is none.
  bool stop_take();
  // Once the loop has let go of a stopped take: writes what it queued, closes the file
  // and says what it holds. Empty while the loop still holds it, or when none was stopped.
  // Throws Error when the file's last write fails (the take is gone all the same).
  std::optional<TakeSummary> finish_stopped();
  // Whether a take is being recorded (started, not stopped).
  bool recording() const;
  // The take being recorded or closing, or the last one (empty before the first).
  std::filesystem::path file() const;
  // The counters of the take being recorded (zeros when none).
  RecorderCounters take_counters() const;

 private:
  struct Take {
    std::unique_ptr<Recorder> recorder;  // null: the loop records nothing
  };

  Eigen::Index vertex_count_;
  bool record_vertices_;
  std::size_t start_state_bytes_;  // under mutex_
  rt::Handoff<Take> handoff_;
  std::unique_ptr<Take> current_;  // the solve thread's; the supervisor's once the loop stopped

  mutable std::mutex mutex_;  // the supervisor's view below, read by health() from any thread
  Recorder* live_ = nullptr;  // the take handed to the loop and not finished yet
  bool stopping_ = false;     // live_ was stopped and waits for the loop to let go
  std::filesystem::path last_file_;
  SinkHealth finished_;       // the finished takes' counters added up
};

}  // namespace facecap::outputs
