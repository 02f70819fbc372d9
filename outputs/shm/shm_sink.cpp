#include "outputs/shm/shm_sink.hpp"

#include <fmt/format.h>

namespace facecap::outputs {

ShmSink::ShmSink(const ShmOutputSpec& spec) : writer_(spec), slot_count_(spec.slot_count) {}

std::string ShmSink::description() const {
  return fmt::format("shared memory {} ({} slots{})", writer_.name(), slot_count_,
                     writer_.vertex_count() ? ", with vertices" : "");
}

void ShmSink::offer(const MarkerFrame&, const SolvedFrame& solved) noexcept {
  offered_.store(offered_.load(std::memory_order_relaxed) + 1, std::memory_order_relaxed);
  writer_.publish(solved);
}

SinkHealth ShmSink::health() const noexcept {
  SinkHealth h;
  h.offered = offered_.load(std::memory_order_relaxed);
  h.delivered = h.offered;  // publishing cannot fail; a reader that falls behind loses frames on its side
  return h;
}

}  // namespace facecap::outputs
