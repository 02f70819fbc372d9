#include "outputs/udp/udp_stream_protocol.hpp"

#include <array>
#include <random>

#include <fmt/format.h>

#include "core/time.hpp"

namespace facecap::outputs {

UdpStreamProtocol::UdpStreamProtocol(udp_stream::StreamSchema schema, bool vertices)
    : schema_(std::move(schema)), vertices_(vertices), stream_id_(std::random_device{}()) {
  if (!vertices_) schema_.vertex_count = 0;
  schema_id_ = udp_stream::encode_schema(schema_, 0, schema_message_);
  frame_message_.reserve(udp::frame_message_bytes(schema_.shape_names.size(), schema_.vertex_count));
}

std::string UdpStreamProtocol::description() const {
  const uint64_t bytes = udp::frame_message_bytes(schema_.shape_names.size(), schema_.vertex_count);
  return fmt::format("UDP stream {:08x} ({} shapes{}, {} bytes in {} datagram{} a frame)", stream_id_,
                     schema_.shape_names.size(), vertices_ ? fmt::format(", {} vertices", schema_.vertex_count) : "",
                     bytes, udp::chunks_for(bytes), udp::chunks_for(bytes) > 1 ? "s" : "");
}

bool UdpStreamProtocol::send_frame(const SolvedFrame& frame, UdpSender& out) {
  const udp_stream::FrameStamp stamp{schema_id_, schema_.rig_hash, monotonic_now_ns()};
  udp_stream::encode_frame(frame, stamp, vertices_, frame_message_);
  return send_message(udp::kFrameMessage, ++frames_sent_, frame_message_, out);
}

void UdpStreamProtocol::send_periodic(UdpSender& out, bool stopping) {
  if (stopping) {
    std::vector<char> goodbye;
    udp_stream::encode_schema(schema_, udp::kSchemaStopping, goodbye);
    send_message(udp::kSchemaMessage, ++schemas_sent_, goodbye, out);
    return;
  }
  send_message(udp::kSchemaMessage, ++schemas_sent_, schema_message_, out);
}

bool UdpStreamProtocol::send_message(udp::MessageKind kind, uint64_t sequence, const std::vector<char>& message,
                                     UdpSender& out) {
  const uint32_t count = udp::chunks_for(message.size());
  for (uint32_t i = 0; i < count; ++i) {
    const udp::ChunkHeader header =
        udp_stream::chunk_header(kind, stream_id_, sequence, uint32_t(message.size()), uint16_t(i));
    const std::span<const char> payload = udp_stream::chunk_payload(message, uint16_t(i));
    const std::array<boost::asio::const_buffer, 2> parts = {boost::asio::buffer(&header, sizeof header),
                                                            boost::asio::buffer(payload.data(), payload.size())};
    // The rest of a message whose chunk was refused could not be reassembled: stop here.
    if (!out.send(parts)) return false;
  }
  return true;
}

}  // namespace facecap::outputs
