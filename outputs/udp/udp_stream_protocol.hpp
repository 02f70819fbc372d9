#pragma once
// facecap's own UDP stream (docs/udp-stream.md) as a network output's protocol: every
// frame as one message of one or more chunks, and the schema at start, every second and
// with a stopping flag at the end. The bytes come from outputs/udp/udp_stream_encoding.hpp.
#include <cstdint>
#include <vector>

#include "outputs/udp/udp_stream_encoding.hpp"
#include "outputs/net/net_sink.hpp"

namespace facecap::outputs {

class UdpStreamProtocol final : public NetProtocol {
 public:
  // A random stream id, so that receivers tell a restarted facecapd from the one before.
  // Not RT-safe; throws Error for a rig the stream cannot carry.
  UdpStreamProtocol(udp_stream::StreamSchema schema, bool vertices);

  std::string_view name() const noexcept override { return "udp"; }
  std::string description() const override;
  bool send_frame(const SolvedFrame& frame, UdpSender& out) override;
  void send_periodic(UdpSender& out, bool stopping) override;

  uint32_t stream_id() const noexcept { return stream_id_; }
  uint32_t schema_id() const noexcept { return schema_id_; }

 private:
  bool send_message(udp::MessageKind kind, uint64_t sequence, const std::vector<char>& message, UdpSender& out);

  udp_stream::StreamSchema schema_;
  bool vertices_;
  uint32_t stream_id_;
  uint32_t schema_id_ = 0;
  std::vector<char> schema_message_;
  std::vector<char> frame_message_;  // reused: grows once
  uint64_t frames_sent_ = 0;
  uint64_t schemas_sent_ = 0;
};

}  // namespace facecap::outputs
