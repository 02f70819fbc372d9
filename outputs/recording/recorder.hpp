#pragma once
// Records the raw marker frames and solved frames of a run (.fcrec) on its own thread.
// The solve loop only copies a frame into a pre-sized queue slot; when the queue is full
// the frame is dropped and counted, so a slow disk never delays a solve.
#include <atomic>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <span>
#include <thread>
#include <vector>

#include "core/frame.hpp"
#include "core/rt/spsc_slots.hpp"
#include "formats/recording.hpp"
#include "outputs/api/sink.hpp"

namespace facecap::outputs {

struct RecorderOptions {
  std::filesystem::path file;
  formats::RecordingHeader header;
  std::size_t queue_frames = 512;
  bool markers = true;
  bool solved = true;
  bool vertices = false;  // solved meshes too (large); a re-solve reproduces them otherwise
  // Room for the solve's state before the first frame (OutputSink::offer_start_state),
  // stored so that the recording re-solves to itself from its first frame; 0: not stored.
  std::size_t start_state_bytes = 0;
  formats::RecordingWriter::WriteFn write = nullptr;  // tests inject write failures; null: pwrite(2)
};

struct RecorderCounters {
  uint64_t marker_frames = 0;  // written
  uint64_t solved_frames = 0;  // written
  uint64_t dropped = 0;        // loop frames that did not reach the file (queue full, a failed write lost
                               // them, the recording stopped, or the file was deleted)
  uint64_t errors = 0;         // write failures and a deleted file (the run continues; the recording stops)
};

class Recorder final : public OutputSink {
 public:
  // Creates the file (an existing file is an error) and starts the writer thread. The
  // queue's slots are sized from the header: its marker labels and shape names, and
  // vertex_count vertices when options.vertices. Not RT-safe; throws Error.
  Recorder(RecorderOptions options, Eigen::Index vertex_count);
  // stop() if still running. Not RT-safe.
  ~Recorder() override;
  Recorder(const Recorder&) = delete;
  Recorder& operator=(const Recorder&) = delete;

  std::string_view name() const noexcept override { return "recording"; }
  std::string description() const override;
  bool wants_vertices() const noexcept override { return options_.solved && options_.vertices; }
  // Queues copies of one loop frame; drops it (counted) when the queue is full. RT-safe.
  void offer(const MarkerFrame& markers, const SolvedFrame& solved) noexcept override;
  // Until the first frame is offered, when options.start_state_bytes. RT-safe.
  bool wants_start_state() const noexcept override { return options_.start_state_bytes > 0 && !first_offered_; }
  // Keeps the state for the writer thread, which stores it before the first frame. RT-safe.
  void offer_start_state(std::span<const char> state) noexcept override;
  // Whether offer() would queue now. Producer side only. RT-safe.
  bool ready() noexcept override { return queue_.begin_push() != nullptr; }
  SinkHealth health() const noexcept override;
  // Writes what is queued, then the index, syncs and closes. Not RT-safe; idempotent.
  // Throws Error when the last write fails (counted like any other).
  void stop() override;

  RecorderCounters counters() const noexcept;
  // Why the recording stopped early ("" when it did not). Read it after stop().
  const std::string& failure() const noexcept { return failure_; }
  const std::filesystem::path& file() const noexcept { return options_.file; }

 private:
  struct Entry {
    bool has_markers = false;
    bool has_solved = false;
    bool has_start_state = false;  // the first frame, start_state_ to be stored before it
    MarkerFrame markers;
    SolvedFrame solved;
  };
  void run();
  // Stores the start state the solve thread offered before the first frame, or says why
  // there is none. Writer thread only.
  void store_start_state();
  // The writer failed with what: the frames it lost become dropped, the recording stops.
  // Writer thread (or stop() after it) only.
  void fail(const std::string& what);
  // The counters from the writer's frames after a successful append or flush.
  void count_written();

  RecorderOptions options_;
  std::unique_ptr<formats::RecordingWriter> writer_;
  rt::SpscSlots<Entry> queue_;
  std::thread thread_;
  // The solve thread's until the first frame is queued, the writer thread's after.
  std::vector<char> start_state_;  // capacity options.start_state_bytes
  bool start_state_offered_ = false;
  bool start_state_too_large_ = false;
  bool first_offered_ = false;  // the solve thread's
  std::atomic<bool> stop_requested_{false};
  std::atomic<uint64_t> offered_{0}, written_{0}, marker_frames_{0}, solved_frames_{0}, dropped_{0}, errors_{0};
  std::string failure_;  // the writer thread's, then stop()'s
};

// "facecapd-20240131-142501.fcrec" (local time), made unique with -2, -3, ... if taken.
std::filesystem::path new_recording_path(const std::filesystem::path& directory);
// A take's file from its slate: "<scene>_<shot>_<take>.fcrec" (the fields given, each
// reduced to letters, digits, '.', '-' and at most 64 bytes; other bytes become '-').
// A slate is never reused: throws Error, naming the file and the next free take number,
// when that file exists, and when the take is empty.
std::filesystem::path take_path(const std::filesystem::path& directory, const formats::RecordingHeader& slate);
// The next take number of a scene and shot: one more than the largest take number among
// directory's "<scene>_<shot>_<number>.fcrec" files; "1" when there is none.
std::string next_take_number(const std::filesystem::path& directory, const std::string& scene, const std::string& shot);

}  // namespace facecap::outputs
