#pragma once
// The published byte layout of facecapd's UDP stream (docs/udp-stream.md). Readers in any
// language can follow the offsets asserted below; C and C++ readers use the client library
// (facecap_client.h, facecap_client_open_udp) instead of touching these structs.
//
// Two kinds of message travel in UDP datagrams of at most kMaxDatagramBytes: frames (one
// per solved frame: FrameHeader, then shape_count float weights, then vertex_count * 3
// float vertex coordinates) and the schema (SchemaHeader, then shape_count ShapeName
// entries), repeated every second. A message longer than one datagram's payload is cut
// into chunks; every datagram is a ChunkHeader followed by one chunk. All integers and
// floats little-endian; no padding besides the fields named reserved.
//
// This header depends only on the C++ standard library: the client library and the
// daemon's encoder (outputs/udp/udp_stream_encoding.hpp) both include it.
#include <cstddef>
#include <cstdint>

namespace facecap::udp {

// "FCUD" read as a little-endian integer.
inline constexpr uint32_t kMagic = 0x44554346u;
// Bumped on any incompatible change; receivers ignore other versions.
inline constexpr uint16_t kProtocolVersion = 1;
// Whole UDP payload, header included: fits a 1,500-byte Ethernet MTU with IPv6 and tunnel
// headers to spare.
inline constexpr uint32_t kMaxDatagramBytes = 1400;
inline constexpr uint32_t kNameBytes = 64;  // 63 characters and a NUL, truncated

enum MessageKind : uint16_t {
  kFrameMessage = 1,
  kSchemaMessage = 2,
};

// Schema flags.
enum SchemaFlags : uint32_t {
  kSchemaStopping = 1u << 0,  // the sender is stopping: no more frames from this stream
};

struct ChunkHeader {
  uint32_t magic;          // kMagic
  uint16_t version;        // kProtocolVersion
  uint16_t kind;           // MessageKind
  uint32_t stream_id;      // random per sender start: a new value means a new sender
  uint32_t message_bytes;  // the whole message this chunk is part of
  uint64_t sequence;       // message number per kind and stream: 1, 2, ...
  uint32_t chunk_offset;   // where this chunk goes in the message: chunk_index * kMaxChunkBytes
  uint16_t chunk_index;    // 0 .. chunk_count - 1
  uint16_t chunk_count;    // chunks_for(message_bytes)
};

// Payload bytes of one datagram after its header.
inline constexpr uint32_t kMaxChunkBytes = kMaxDatagramBytes - uint32_t(sizeof(ChunkHeader));

struct FrameHeader {
  int64_t frame_no;             // the source's frame number
  int64_t source_time_ns;       // the source's own clock
  int64_t receive_time_ns;      // CLOCK_MONOTONIC of the sending host: the frame reached facecapd
  int64_t solve_start_ns;       // CLOCK_MONOTONIC of the sending host
  int64_t solve_end_ns;
  int64_t publish_time_ns;      // CLOCK_MONOTONIC of the sending host, just before the first chunk went out
  float head_rotation_wxyz[4];  // head in world (unit quaternion)
  float head_translation[3];    // head in world, rig units
  uint32_t flags;               // SolvedFlags (docs/shm-format.md, "Frame flags")
  uint32_t markers_used;
  uint32_t shape_count;         // weights that follow
  uint32_t vertex_count;        // vertices that follow the weights; 0 when not sent
  uint32_t schema_id;           // the schema whose shapes these weights follow
  uint64_t rig_hash;            // identity of the solved rig
  uint8_t timecode_hours, timecode_minutes, timecode_seconds, timecode_frames;
  uint16_t timecode_rate_hz;    // 0: no timecode
  uint16_t reserved0;
  float timecode_subframe;
  uint32_t reserved1;
};

struct SchemaHeader {
  uint64_t rig_hash;
  uint32_t schema_id;         // changes whenever anything in the schema changes
  uint32_t flags;             // SchemaFlags
  uint32_t shape_count;       // ShapeName entries that follow, and weights per frame
  uint32_t vertex_count;      // vertices per frame, 0 when not sent
  uint32_t interval_ms;       // the schema is sent again this often: hearing nothing for 3 intervals means the sender is gone
  uint32_t reserved0;
  double frame_rate_hz;       // frames sent per second (the loop's rate, or less when limited)
  char rig_name[kNameBytes];  // NUL-terminated
};

struct ShapeName {
  char rig[kNameBytes];    // the rig's shape name, NUL-terminated
  char arkit[kNameBytes];  // its ARKit name ("JawOpen"), empty when it has none
};

// Offsets readers in other languages rely on. Changing any is a new protocol version.
static_assert(offsetof(ChunkHeader, magic) == 0);
static_assert(offsetof(ChunkHeader, version) == 4);
static_assert(offsetof(ChunkHeader, kind) == 6);
static_assert(offsetof(ChunkHeader, stream_id) == 8);
static_assert(offsetof(ChunkHeader, message_bytes) == 12);
static_assert(offsetof(ChunkHeader, sequence) == 16);
static_assert(offsetof(ChunkHeader, chunk_offset) == 24);
static_assert(offsetof(ChunkHeader, chunk_index) == 28);
static_assert(offsetof(ChunkHeader, chunk_count) == 30);
static_assert(sizeof(ChunkHeader) == 32);
static_assert(kMaxChunkBytes == 1368);

static_assert(offsetof(FrameHeader, frame_no) == 0);
static_assert(offsetof(FrameHeader, receive_time_ns) == 16);
static_assert(offsetof(FrameHeader, publish_time_ns) == 40);
static_assert(offsetof(FrameHeader, head_rotation_wxyz) == 48);
static_assert(offsetof(FrameHeader, head_translation) == 64);
static_assert(offsetof(FrameHeader, flags) == 76);
static_assert(offsetof(FrameHeader, shape_count) == 84);
static_assert(offsetof(FrameHeader, vertex_count) == 88);
static_assert(offsetof(FrameHeader, schema_id) == 92);
static_assert(offsetof(FrameHeader, rig_hash) == 96);
static_assert(offsetof(FrameHeader, timecode_hours) == 104);
static_assert(offsetof(FrameHeader, timecode_rate_hz) == 108);
static_assert(offsetof(FrameHeader, timecode_subframe) == 112);
static_assert(sizeof(FrameHeader) == 120);

static_assert(offsetof(SchemaHeader, schema_id) == 8);
static_assert(offsetof(SchemaHeader, flags) == 12);
static_assert(offsetof(SchemaHeader, shape_count) == 16);
static_assert(offsetof(SchemaHeader, vertex_count) == 20);
static_assert(offsetof(SchemaHeader, interval_ms) == 24);
static_assert(offsetof(SchemaHeader, frame_rate_hz) == 32);
static_assert(offsetof(SchemaHeader, rig_name) == 40);
static_assert(sizeof(SchemaHeader) == 104);
static_assert(sizeof(ShapeName) == 128);

// Limits a receiver checks before trusting sizes from a datagram.
inline constexpr uint32_t kMaxShapes = 4096;
inline constexpr uint32_t kMaxVertices = 1u << 20;
inline constexpr uint64_t kMaxMessageBytes = 16u << 20;

constexpr uint64_t frame_message_bytes(uint64_t shape_count, uint64_t vertex_count) noexcept {
  return sizeof(FrameHeader) + shape_count * 4 + vertex_count * 12;
}
constexpr uint64_t schema_message_bytes(uint64_t shape_count) noexcept {
  return sizeof(SchemaHeader) + shape_count * sizeof(ShapeName);
}
// Chunks of a message (an empty message still takes one datagram).
constexpr uint32_t chunks_for(uint64_t message_bytes) noexcept {
  return message_bytes == 0 ? 1 : uint32_t((message_bytes + kMaxChunkBytes - 1) / kMaxChunkBytes);
}
static_assert(frame_message_bytes(kMaxShapes, kMaxVertices) <= kMaxMessageBytes);
static_assert(chunks_for(kMaxMessageBytes) <= 0xffff, "chunk indices are 16-bit");

}  // namespace facecap::udp
