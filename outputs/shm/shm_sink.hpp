#pragma once
// The shared-memory ring as an output: inline and wait-free, so it runs on the solve
// thread itself (layout: client/facecap_shm_layout.hpp, docs/shm-format.md).
#include <atomic>
#include <memory>

#include "outputs/api/sink.hpp"
#include "outputs/shm/shm_writer.hpp"

namespace facecap::outputs {

class ShmSink final : public OutputSink {
 public:
  // Creates the segment (ShmWriter). Not RT-safe; throws Error.
  explicit ShmSink(const ShmOutputSpec& spec);

  std::string_view name() const noexcept override { return "shm"; }
  std::string description() const override;
  bool wants_vertices() const noexcept override { return writer_.vertex_count() > 0; }
  void offer(const MarkerFrame& markers, const SolvedFrame& solved) noexcept override;
  void tick(int64_t now_ns) noexcept override { writer_.beat(now_ns); }
  SinkHealth health() const noexcept override;
  // Tells readers no more frames will come; the segment goes with the sink.
  void stop() override { writer_.mark_stopped(); }

  const ShmWriter& writer() const noexcept { return writer_; }

 private:
  ShmWriter writer_;
  uint32_t slot_count_;
  std::atomic<uint64_t> offered_{0};
};

}  // namespace facecap::outputs
