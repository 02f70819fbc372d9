#include "outputs/table.hpp"

#include <fmt/format.h>

#include "core/error.hpp"
#include "outputs/recording/take_recorder.hpp"
#include "outputs/shm/shm_sink.hpp"

namespace facecap::outputs {
namespace {

std::unique_ptr<OutputSink> make_shm(const config::DaemonConfig& c, const SinkContext& context) {
  if (!c.outputs.shm.enabled) return nullptr;
  ShmOutputSpec spec;
  spec.name = c.outputs.shm.name;
  spec.shape_names = context.header.shape_names;
  spec.vertex_count = c.outputs.shm.vertices ? context.vertex_count : 0;
  spec.slot_count = uint32_t(c.outputs.shm.slots);
  spec.nominal_rate_hz = context.loop_rate_hz;
  spec.rig_name = context.header.rig_name;
  spec.rig_hash = context.header.rig_hash;
  return std::make_unique<ShmSink>(spec);
}

// Present when recording from the start or when the control API may start takes.
std::unique_ptr<OutputSink> make_recording(const config::DaemonConfig& c, const SinkContext& context) {
  const config::RecordingSection& s = c.outputs.recording;
  if (!s.enabled && !c.control.http.enabled) return nullptr;
  auto takes = std::make_unique<TakeRecorder>(context.vertex_count, s.solved && s.vertices);
  if (s.enabled) takes->start_take(take_options(c, context.header, new_recording_path(s.directory)));
  return takes;
}

const OutputEntry kOutputs[] = {
    {"shm", "shared-memory ring for renderers on this machine (docs/shm-format.md)", &make_shm},
    {"recording", "the run recorded to a .fcrec file (docs/recording-format.md)", &make_recording},
};

}  // namespace

std::span<const OutputEntry> output_table() noexcept { return kOutputs; }

RecorderOptions take_options(const config::DaemonConfig& c, formats::RecordingHeader header, std::filesystem::path file) {
  const config::RecordingSection& s = c.outputs.recording;
  RecorderOptions options;
  options.file = std::move(file);
  options.header = std::move(header);
  options.queue_frames = std::size_t(s.queue_frames);
  options.markers = s.markers;
  options.solved = s.solved;
  options.vertices = s.vertices;
  return options;
}

std::vector<std::unique_ptr<OutputSink>> make_outputs(const config::DaemonConfig& config, const SinkContext& context) {
  std::vector<std::unique_ptr<OutputSink>> sinks;
  for (const OutputEntry& entry : kOutputs) {
    try {
      if (auto sink = entry.make(config, context)) sinks.push_back(std::move(sink));
    } catch (const Error& e) {
      throw Error(fmt::format("[outputs.{}]: {}", entry.name, e.what()));
    }
  }
  return sinks;
}

}  // namespace facecap::outputs
