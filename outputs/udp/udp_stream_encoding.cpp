#include "outputs/udp/udp_stream_encoding.hpp"

#include <algorithm>
#include <bit>
#include <cstring>

#include <fmt/format.h>

#include "core/error.hpp"

namespace facecap::outputs::udp_stream {
namespace {

static_assert(std::endian::native == std::endian::little, "the stream's layout is the host's: little-endian");

void copy_name(std::string_view name, char (&out)[udp::kNameBytes]) noexcept {
  const std::size_t n = std::min<std::size_t>(name.size(), udp::kNameBytes - 1);
  std::memcpy(out, name.data(), n);
  std::memset(out + n, 0, udp::kNameBytes - n);
}

// FNV-1a, 32 bits.
uint32_t fnv1a(std::span<const char> bytes) noexcept {
  uint32_t h = 0x811c9dc5u;
  for (const char c : bytes) {
    h ^= uint8_t(c);
    h *= 0x01000193u;
  }
  return h;
}

template <typename T>
void put(std::vector<char>& out, std::size_t at, const T& value) noexcept {
  std::memcpy(out.data() + at, &value, sizeof(T));
}

}  // namespace

uint32_t encode_schema(const StreamSchema& schema, uint32_t flags, std::vector<char>& message) {
  if (schema.shape_names.size() > udp::kMaxShapes || schema.vertex_count > udp::kMaxVertices)
    throw Error(fmt::format("the UDP stream carries at most {} shapes and {} vertices, not {} and {}", udp::kMaxShapes,
                            udp::kMaxVertices, schema.shape_names.size(), schema.vertex_count));
  const uint32_t shape_count = uint32_t(schema.shape_names.size());
  message.assign(udp::schema_message_bytes(shape_count), '\0');
  udp::SchemaHeader h{};
  h.rig_hash = schema.rig_hash;
  h.shape_count = shape_count;
  h.vertex_count = schema.vertex_count;
  h.interval_ms = schema.interval_ms;
  h.frame_rate_hz = schema.frame_rate_hz;
  copy_name(schema.rig_name, h.rig_name);
  for (uint32_t i = 0; i < shape_count; ++i) {
    udp::ShapeName names{};
    copy_name(schema.shape_names[i], names.rig);
    copy_name(i < schema.arkit_names.size() ? std::string_view(schema.arkit_names[i]) : std::string_view(), names.arkit);
    put(message, sizeof(udp::SchemaHeader) + std::size_t(i) * sizeof(udp::ShapeName), names);
  }
  put(message, 0, h);  // schema_id and flags still 0: the id hashes the rest
  h.schema_id = fnv1a(message);
  h.flags = flags;
  put(message, 0, h);
  return h.schema_id;
}

void encode_frame(const SolvedFrame& frame, const FrameStamp& stamp, bool with_vertices, std::vector<char>& message) {
  const uint32_t shape_count = uint32_t(frame.weights.size());
  const uint32_t vertex_count = with_vertices ? uint32_t(frame.vertices.cols()) : 0;
  message.resize(udp::frame_message_bytes(shape_count, vertex_count));
  udp::FrameHeader h{};
  h.frame_no = frame.frame_no;
  h.source_time_ns = frame.source_time_ns;
  h.receive_time_ns = frame.receive_time_ns;
  h.solve_start_ns = frame.solve_start_ns;
  h.solve_end_ns = frame.solve_end_ns;
  h.publish_time_ns = stamp.publish_time_ns;
  const Eigen::Quaternionf q = frame.head_rotation.cast<float>();
  h.head_rotation_wxyz[0] = q.w();
  h.head_rotation_wxyz[1] = q.x();
  h.head_rotation_wxyz[2] = q.y();
  h.head_rotation_wxyz[3] = q.z();
  for (int i = 0; i < 3; ++i) h.head_translation[i] = float(frame.head_translation[i]);
  h.flags = frame.flags;
  h.markers_used = frame.markers_used;
  h.shape_count = shape_count;
  h.vertex_count = vertex_count;
  h.schema_id = stamp.schema_id;
  h.rig_hash = stamp.rig_hash;
  h.timecode_hours = frame.timecode.hours;
  h.timecode_minutes = frame.timecode.minutes;
  h.timecode_seconds = frame.timecode.seconds;
  h.timecode_frames = frame.timecode.frames;
  h.timecode_rate_hz = frame.timecode.rate_hz;
  h.timecode_subframe = frame.timecode.subframe;
  put(message, 0, h);
  std::memcpy(message.data() + sizeof(h), frame.weights.data(), std::size_t(shape_count) * 4);
  // Matrix3Xf is column-major: x, y, z of each vertex in turn, as the layout has them.
  if (vertex_count > 0)
    std::memcpy(message.data() + sizeof(h) + std::size_t(shape_count) * 4, frame.vertices.data(),
                std::size_t(vertex_count) * 12);
}

udp::ChunkHeader chunk_header(udp::MessageKind kind, uint32_t stream_id, uint64_t sequence, uint32_t message_bytes,
                              uint16_t index) noexcept {
  udp::ChunkHeader h{};
  h.magic = udp::kMagic;
  h.version = udp::kProtocolVersion;
  h.kind = kind;
  h.stream_id = stream_id;
  h.message_bytes = message_bytes;
  h.sequence = sequence;
  h.chunk_offset = uint32_t(index) * udp::kMaxChunkBytes;
  h.chunk_index = index;
  h.chunk_count = uint16_t(udp::chunks_for(message_bytes));
  return h;
}

std::span<const char> chunk_payload(std::span<const char> message, uint16_t index) noexcept {
  const std::size_t begin = std::min<std::size_t>(std::size_t(index) * udp::kMaxChunkBytes, message.size());
  const std::size_t end = std::min<std::size_t>(begin + udp::kMaxChunkBytes, message.size());
  return message.subspan(begin, end - begin);
}

std::vector<std::vector<char>> datagrams(udp::MessageKind kind, uint32_t stream_id, uint64_t sequence,
                                         std::span<const char> message) {
  std::vector<std::vector<char>> out;
  const uint32_t count = udp::chunks_for(message.size());
  for (uint32_t i = 0; i < count; ++i) {
    const udp::ChunkHeader h = chunk_header(kind, stream_id, sequence, uint32_t(message.size()), uint16_t(i));
    const std::span<const char> payload = chunk_payload(message, uint16_t(i));
    std::vector<char>& d = out.emplace_back(sizeof(h) + payload.size());
    std::memcpy(d.data(), &h, sizeof(h));
    std::copy(payload.begin(), payload.end(), d.begin() + sizeof(h));
  }
  return out;
}

}  // namespace facecap::outputs::udp_stream
