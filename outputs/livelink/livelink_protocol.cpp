#include "outputs/livelink/livelink_protocol.hpp"

#include <fstream>

#include <fmt/format.h>
#include <unistd.h>

namespace facecap::outputs {

std::string device_id_for(const std::string& subject_name) {
  std::string machine;
  std::ifstream("/etc/machine-id") >> machine;
  if (machine.empty()) {
    char host[256] = {};
    gethostname(host, sizeof host - 1);
    machine = host;
  }
  const auto id = formats::livelink::device_id_from("facecap livelink " + machine + " " + subject_name);
  return std::string(id.data(), id.size());
}

LiveLinkProtocol::LiveLinkProtocol(LiveLinkSpec spec) : spec_(std::move(spec)), arkit_(spec_.rig_shape_names) {
  if (spec_.device_id.empty()) spec_.device_id = device_id_for(spec_.subject_name);
  formats::livelink::encode_packet(spec_.device_id, spec_.subject_name, frame_, packet_);  // checks the lengths
}

std::string LiveLinkProtocol::description() const {
  return fmt::format("Live Link Face subject \"{}\" (device {}, {} of 52 ARKit shapes on the rig)", spec_.subject_name,
                     spec_.device_id, arkit_.realised());
}

bool LiveLinkProtocol::send_frame(const SolvedFrame& frame, UdpSender& out) {
  formats::livelink::set_frame_time(frame.timecode, frame.source_time_ns, spec_.frame_rate_hz, frame_);
  arkit_.map(std::span<const float>(frame.weights.data(), std::size_t(frame.weights.size())),
             std::span<float, formats::kArkitShapeCount>(frame_.values.data(), formats::kArkitShapeCount));
  // Head yaw, pitch, roll; the eyes' angles stay 0: markers do not see the eyes (the
  // eye-look weights carry the gaze the rig solves).
  const std::array<float, 3> head = formats::head_yaw_pitch_roll(frame.head_rotation);
  std::copy(head.begin(), head.end(), frame_.values.begin() + formats::kArkitShapeCount);
  formats::livelink::encode_packet(spec_.device_id, spec_.subject_name, frame_, packet_);
  return out.send(std::span<const char>(packet_));
}

}  // namespace facecap::outputs
