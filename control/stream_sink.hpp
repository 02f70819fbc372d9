#pragma once
// The WebSocket stream's feed (GET /stream): an output like any other, offered every
// solved frame by the loop. While a client listens it copies frames, no more often than
// the fastest client asks, into pre-sized slots of a bounded SPSC queue that the I/O
// thread drains (full: the frame is dropped and counted); with no client it does nothing.
// Message layouts: docs/control-api.md.
#include <atomic>
#include <cstdint>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/frame.hpp"
#include "core/rt/spsc_slots.hpp"
#include "outputs/api/sink.hpp"

namespace facecap::control {

// What a 3D view needs to know once: shape names, marker slots, the mesh.
struct StreamSchema {
  std::string rig_name, rig_units;
  std::vector<std::string> shape_names;
  std::vector<std::string> marker_labels;  // the source's marker slots
  uint32_t vertex_count = 0;
  std::vector<int32_t> triangles;          // 3 vertex indices each
};

class StreamSink final : public outputs::OutputSink {
 public:
  struct Entry {
    MarkerFrame markers;
    SolvedFrame solved;
  };

  // Slots sized like the loop's frames (the source's marker slots, the rig's shapes and
  // vertices). Not RT-safe.
  StreamSink(StreamSchema schema, std::size_t slots);

  std::string_view name() const noexcept override { return "stream"; }
  // A browser too slow for the rate it asked for sees the newest frame.
  bool drops_by_design() const noexcept override { return true; }
  std::string description() const override;
  // Clients may ask for vertices. RT-safe.
  bool wants_vertices() const noexcept override { return true; }
  // Copies the frame when a client listens and its interval has passed. RT-safe.
  void offer(const MarkerFrame& markers, const SolvedFrame& solved) noexcept override;
  outputs::SinkHealth health() const noexcept override;
  void stop() override {}

  // I/O thread: how often to copy frames (0: no client, copy nothing).
  void set_rate(double hz) noexcept;
  // I/O thread (the consumer): the oldest copied frame, or nullptr; pop() releases it.
  Entry* front() noexcept { return queue_.front(); }
  void pop() noexcept;
  // I/O thread: a frame taken but not sent to anyone (every client still busy).
  void count_undelivered() noexcept { dropped_.fetch_add(1, std::memory_order_relaxed); }

  const StreamSchema& schema() const noexcept { return schema_; }

 private:
  StreamSchema schema_;
  rt::SpscSlots<Entry> queue_;
  std::atomic<int64_t> interval_ns_{0};  // 0: no client
  int64_t last_copied_ns_ = 0;           // solve thread only
  std::atomic<uint64_t> offered_{0}, copied_{0}, delivered_{0}, dropped_{0};
};

// {"type": "schema", ...}: sent first on every connection (triangles only with vertices).
nlohmann::json schema_message(const StreamSchema& schema, double rate_hz, bool vertices);
// {"type": "frame", ...}: one solved frame and its telemetry (vertices on request).
nlohmann::json frame_message(const StreamSink::Entry& entry, const StreamSchema& schema, bool vertices);

}  // namespace facecap::control
