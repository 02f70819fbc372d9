#pragma once
// Records the raw marker frames and solved frames of a run (.fcrec) on its own thread.
// The solve loop only copies a frame into a pre-sized queue slot; when the queue is full
// the frame is dropped and counted, so a slow disk never delays a solve.
#include <atomic>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <thread>

#include "core/frame.hpp"
#include "core/rt/spsc_slots.hpp"
#include "formats/recording.hpp"

namespace facecap::daemon {

struct RecorderOptions {
  std::filesystem::path file;
  formats::RecordingHeader header;
  std::size_t queue_frames = 512;
  bool markers = true;
  bool solved = true;
};

struct RecorderCounters {
  uint64_t marker_frames = 0;  // written
  uint64_t solved_frames = 0;  // written
  uint64_t dropped = 0;        // loop frames not queued (queue full)
  uint64_t errors = 0;         // write failures (the run continues; the recording stops)
};

class Recorder {
 public:
  // Creates the file (an existing file is an error) and starts the writer thread. The
  // prototype sizes the queue's marker slots like the loop's frames; shape_count sizes
  // the weights. Not RT-safe; throws Error.
  Recorder(RecorderOptions options, const MarkerFrame& marker_prototype, Eigen::Index shape_count);
  // stop() if still running. Not RT-safe.
  ~Recorder();
  Recorder(const Recorder&) = delete;
  Recorder& operator=(const Recorder&) = delete;

  // Queues copies of one loop frame (either may be null); false when dropped (counted).
  // Solved frames are recorded without vertices (a re-solve from the weights and markers
  // reproduces them). RT-safe.
  bool offer(const MarkerFrame* markers, const SolvedFrame* solved) noexcept;
  // Whether offer() would queue now. Producer side only. RT-safe.
  bool has_room() noexcept { return queue_.begin_push() != nullptr; }

  // Writes what is queued, then the index, syncs and closes. Not RT-safe; idempotent.
  void stop();

  RecorderCounters counters() const noexcept;
  const std::filesystem::path& file() const noexcept { return options_.file; }

 private:
  struct Entry {
    bool has_markers = false;
    bool has_solved = false;
    MarkerFrame markers;
    SolvedFrame solved;
  };
  void run();

  RecorderOptions options_;
  std::unique_ptr<formats::RecordingWriter> writer_;
  rt::SpscSlots<Entry> queue_;
  std::thread thread_;
  std::atomic<bool> stop_requested_{false};
  std::atomic<uint64_t> marker_frames_{0}, solved_frames_{0}, dropped_{0}, errors_{0};
};

// "facecapd-20240131-142501.fcrec" (local time), made unique with -2, -3, ... if taken.
std::filesystem::path new_recording_path(const std::filesystem::path& directory);

}  // namespace facecap::daemon
