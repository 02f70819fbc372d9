#pragma once
// facecapd's UDP stream as bytes: frame and schema messages and the chunks they travel in.
// The layout is the published header client/facecap_udp_layout.hpp (docs/udp-stream.md);
// the client library reassembles and reads it.
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "client/facecap_udp_layout.hpp"
#include "core/frame.hpp"

namespace facecap::outputs::udp_stream {

// What a receiver needs to name the weights of every frame.
struct StreamSchema {
  uint64_t rig_hash = 0;
  std::string rig_name;
  std::vector<std::string> shape_names;  // rig order: the weights' order
  std::vector<std::string> arkit_names;  // parallel to shape_names, "" where none
  uint32_t vertex_count = 0;             // per frame, 0 when not sent
  double frame_rate_hz = 0.0;
  uint32_t interval_ms = 1000;
};

// Replaces `message` with the schema message (names longer than 63 bytes truncated).
// Returns its schema id: a hash of everything in it besides the flags, so it changes
// whenever the schema does. Not RT-safe.
uint32_t encode_schema(const StreamSchema& schema, uint32_t flags, std::vector<char>& message);

// What a frame message carries besides the solved frame.
struct FrameStamp {
  uint32_t schema_id = 0;
  uint64_t rig_hash = 0;
  int64_t publish_time_ns = 0;
};

// Replaces `message` with the frame message: its header, the weights, and every vertex of
// the frame when with_vertices. Allocates only when `message` must grow.
void encode_frame(const SolvedFrame& frame, const FrameStamp& stamp, bool with_vertices, std::vector<char>& message);

// The header of chunk `index` of a message of message_bytes bytes. RT-safe.
udp::ChunkHeader chunk_header(udp::MessageKind kind, uint32_t stream_id, uint64_t sequence, uint32_t message_bytes,
                              uint16_t index) noexcept;
// The bytes chunk `index` carries. RT-safe.
std::span<const char> chunk_payload(std::span<const char> message, uint16_t index) noexcept;

// A whole message as datagrams (header and payload each), for tests and tools that send
// without scatter-gather. Not RT-safe.
std::vector<std::vector<char>> datagrams(udp::MessageKind kind, uint32_t stream_id, uint64_t sequence,
                                         std::span<const char> message);

}  // namespace facecap::outputs::udp_stream
