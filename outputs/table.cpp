#include "outputs/table.hpp"

#include <fmt/format.h>

#include "core/error.hpp"
#include "core/time.hpp"
#include "formats/arkit.hpp"
#include "outputs/livelink/livelink_protocol.hpp"
#include "outputs/net/net_sink.hpp"
#include "outputs/recording/take_recorder.hpp"
#include "outputs/shm/shm_sink.hpp"
#include "outputs/udp/udp_stream_protocol.hpp"
#include "outputs/vmc/vmc_protocol.hpp"

namespace facecap::outputs {
namespace {

std::unique_ptr<OutputSink> make_shm(const config::DaemonConfig& c, const SinkContext& context) {
  if (!c.outputs.shm.enabled) return nullptr;
  ShmOutputSpec spec;
  spec.name = c.outputs.shm.name;
  spec.shape_names = context.header.shape_names;
  spec.arkit_names = formats::arkit_names_of(context.header.shape_names);
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
  auto takes = std::make_unique<TakeRecorder>(context.vertex_count, s.solved && s.vertices, context.pipeline_state_bytes);
  if (s.enabled) takes->start_take(take_options(c, context.header, new_recording_path(s.directory)));
  return takes;
}

// What the network outputs share: the destination, the queue's frames, the rate limit.
NetSinkSpec net_spec(const config::NetworkOutput& section, const SinkContext& context, bool vertices) {
  if (!context.io) throw Error("no I/O thread to send on");
  NetSinkSpec spec;
  spec.destination.address = section.address;
  spec.destination.port = uint16_t(section.port);
  spec.shape_count = Eigen::Index(context.header.shape_names.size());
  spec.vertex_count = vertices ? Eigen::Index(context.vertex_count) : 0;
  spec.send_every = send_every_for(context.loop_rate_hz, section.max_rate_hz);
  return spec;
}

double sent_rate_hz(const NetSinkSpec& spec, const SinkContext& context) { return context.loop_rate_hz / spec.send_every; }

std::unique_ptr<OutputSink> make_udp(const config::DaemonConfig& c, const SinkContext& context) {
  const config::UdpSection& s = c.outputs.udp;
  if (!s.enabled) return nullptr;
  NetSinkSpec spec = net_spec(s, context, s.vertices);
  spec.destination.multicast_ttl = int(s.multicast_ttl);
  spec.destination.multicast_interface = s.multicast_interface;
  // Room for a few frames of datagrams in the kernel while the receivers catch up.
  const uint64_t frame_bytes = udp::frame_message_bytes(spec.shape_count, spec.vertex_count);
  spec.destination.send_buffer_bytes = int(std::min<uint64_t>(4 * frame_bytes + (256 << 10), 8 << 20));
  spec.periodic_interval_ns = kNsPerSecond;  // the schema
  udp_stream::StreamSchema schema;
  schema.rig_hash = context.header.rig_hash;
  schema.rig_name = context.header.rig_name;
  schema.shape_names = context.header.shape_names;
  schema.arkit_names = formats::arkit_names_of(context.header.shape_names);
  schema.vertex_count = uint32_t(spec.vertex_count);
  schema.frame_rate_hz = sent_rate_hz(spec, context);
  schema.interval_ms = uint32_t(spec.periodic_interval_ns / kNsPerMs);
  auto protocol = std::make_unique<UdpStreamProtocol>(std::move(schema), s.vertices);
  return std::make_unique<NetSink>(*context.io, std::move(spec), std::move(protocol));
}

std::unique_ptr<OutputSink> make_vmc(const config::DaemonConfig& c, const SinkContext& context) {
  const config::VmcSection& s = c.outputs.vmc;
  if (!s.enabled) return nullptr;
  const std::vector<std::string>& rig = context.header.shape_names;
  std::vector<VmcShape> shapes;
  switch (s.names) {
    case config::VmcNames::kArkit: shapes = arkit_vmc_shapes(rig); break;
    case config::VmcNames::kRig: shapes = rig_vmc_shapes(rig); break;
    case config::VmcNames::kMap: shapes = mapped_vmc_shapes(rig, s.map_file); break;
  }
  auto protocol = std::make_unique<VmcProtocol>(std::move(shapes), VmcRootPose{s.root_pose, s.root_scale});
  return std::make_unique<NetSink>(*context.io, net_spec(s, context, false), std::move(protocol));
}

std::unique_ptr<OutputSink> make_livelink(const config::DaemonConfig& c, const SinkContext& context) {
  const config::LiveLinkSection& s = c.outputs.livelink;
  if (!s.enabled) return nullptr;
  NetSinkSpec spec = net_spec(s, context, false);
  LiveLinkSpec livelink{s.device_id, s.subject_name, context.header.shape_names, sent_rate_hz(spec, context)};
  auto protocol = std::make_unique<LiveLinkProtocol>(std::move(livelink));
  return std::make_unique<NetSink>(*context.io, std::move(spec), std::move(protocol));
}

const OutputEntry kOutputs[] = {
    {"shm", "shared-memory ring for renderers on this machine (docs/shm-format.md)", &make_shm},
    {"recording", "the run recorded to a .fcrec file (docs/recording-format.md)", &make_recording},
    {"udp", "facecap's UDP stream, unicast or multicast (docs/udp-stream.md)", &make_udp},
    {"vmc", "OSC with the VMC protocol (docs/outputs.md)", &make_vmc},
    {"livelink", "Unreal Live Link Face packets (docs/outputs.md)", &make_livelink},
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
