#pragma once
// Unreal Live Link Face packets (formats/livelink_packet.hpp, docs/outputs.md) as a network
// output's protocol: per frame one packet with the 52 ARKit weights mapped from the rig,
// the head's yaw, pitch and roll from the solved head pose, and the frame time from the
// source's timecode.
#include <string>
#include <vector>

#include "formats/arkit.hpp"
#include "formats/livelink_packet.hpp"
#include "outputs/net/net_sink.hpp"

namespace facecap::outputs {

struct LiveLinkSpec {
  std::string device_id;  // empty: device_id_for(subject_name)
  std::string subject_name;
  std::vector<std::string> rig_shape_names;
  double frame_rate_hz = 60.0;  // frames sent per second: the frame time's rate without a timecode
};

// The device id of a subject on this machine: a UUID made from /etc/machine-id (else the
// host name) and the subject name, the same at every start. Not RT-safe.
std::string device_id_for(const std::string& subject_name);

class LiveLinkProtocol final : public NetProtocol {
 public:
  // Not RT-safe; throws Error for a subject name or device id too long for a packet.
  explicit LiveLinkProtocol(LiveLinkSpec spec);

  std::string_view name() const noexcept override { return "livelink"; }
  std::string description() const override;
  bool send_frame(const SolvedFrame& frame, UdpSender& out) override;

  const std::string& device_id() const noexcept { return spec_.device_id; }
  // The packet as last sent (tests).
  const std::vector<char>& packet() const noexcept { return packet_; }

 private:
  LiveLinkSpec spec_;
  formats::ArkitWeights arkit_;
  formats::livelink::LiveLinkFrame frame_;
  std::vector<char> packet_;
};

}  // namespace facecap::outputs
