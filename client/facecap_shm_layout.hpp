#pragma once
// The published byte layout of facecapd's shared-memory output (docs/shm-format.md).
// Readers in any language can follow the offsets asserted below; C and C++ readers use
// the client library (facecap_client.h) instead of touching these structs directly.
//
// A segment is one Header at offset 0, then shape_count names of shape_name_bytes each
// (NUL-padded), then as many ARKit names ("" for a shape without one), then slot_count
// slots of slot_bytes each. A slot is a SlotHeader, then
// shape_count float weights, then vertex_count * 3 float vertex coordinates (x, y, z per
// vertex); each part starts on a 64-byte boundary. All integers little-endian (the host).
//
// Concurrency: one writer, any number of read-only readers. Each slot is a seqlock: the
// writer makes SlotHeader::seqlock odd, writes, then makes it even again; a reader that
// sees the same even value before and after copying has a consistent frame. The writer
// never waits for readers.
//
// This header depends only on the C++ standard library: the client library (no Eigen,
// no facecap core) and the daemon's writer both include it.
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <string_view>

namespace facecap::shm {

// "FCSHM\0\0\1" read as a little-endian integer.
inline constexpr uint64_t kMagic = 0x0100004d48534346ull;
// Bumped on any incompatible change; readers refuse other versions.
inline constexpr uint32_t kLayoutVersion = 2;  // 2: ARKit names
inline constexpr uint32_t kAlignment = 64;
inline constexpr uint32_t kShapeNameBytes = 64;  // 63 characters and a NUL, truncated
inline constexpr uint32_t kRigNameBytes = 64;
inline constexpr uint32_t kStageCount = 8;       // per-stage timings, in SolveStage order

// Set by the writer; readers treat anything but kRunning as "no fresh frames".
enum WriterState : uint32_t {
  kWriterStarting = 0,  // segment created, first frame not yet published
  kWriterRunning = 1,
  kWriterStopped = 2,   // clean shutdown: the segment is about to be unlinked
};

struct alignas(64) Header {
  // Fixed at creation, before the segment name becomes visible to readers.
  uint64_t magic;                 // kMagic
  uint32_t layout_version;        // kLayoutVersion
  uint32_t header_bytes;          // sizeof(Header)
  uint64_t total_bytes;           // whole segment
  uint32_t slot_count;
  uint32_t slot_bytes;            // stride between slots
  uint32_t shape_count;           // M
  uint32_t vertex_count;          // N, 0 when vertices are not published
  uint32_t shape_name_bytes;      // kShapeNameBytes
  uint32_t slot_weights_offset;   // from the start of a slot
  uint32_t slot_vertices_offset;  // from the start of a slot
  uint32_t reserved0;
  uint64_t shape_names_offset;    // from the start of the segment
  uint64_t slots_offset;          // from the start of the segment
  int32_t writer_pid;
  uint32_t reserved1;
  uint64_t writer_generation;     // random per writer start: a new value means a new writer
  int64_t writer_start_ns;        // CLOCK_MONOTONIC when the writer created the segment
  double nominal_rate_hz;         // the loop's configured rate
  uint64_t rig_hash;              // Rig::content_hash() of the solved rig
  char rig_name[kRigNameBytes];   // NUL-terminated
  // Updated while running.
  std::atomic<int64_t> heartbeat_ns;     // CLOCK_MONOTONIC of the writer's latest loop tick
  std::atomic<uint64_t> last_published;  // sequence of the newest complete slot, 0 = none yet
  std::atomic<uint32_t> writer_state;    // WriterState
  uint32_t reserved2;
  uint64_t arkit_names_offset;  // from the start of the segment
  uint8_t reserved_tail[248];   // room to grow without moving the slots
};

struct alignas(64) SlotHeader {
  std::atomic<uint64_t> seqlock;  // odd while the writer is inside this slot
  uint64_t sequence;              // publish counter (1, 2, ...); lives in slot (sequence - 1) % slot_count
  int64_t frame_no;               // the source's frame number
  int64_t source_time_ns;         // the source's clock
  int64_t receive_time_ns;        // CLOCK_MONOTONIC: the frame reached facecapd
  int64_t solve_start_ns;         // CLOCK_MONOTONIC
  int64_t solve_end_ns;           // CLOCK_MONOTONIC
  int64_t publish_time_ns;        // CLOCK_MONOTONIC, just before the slot was released
  float head_rotation_wxyz[4];    // head in world (unit quaternion)
  float head_translation[3];      // head in world, rig units
  uint32_t flags;                 // SolvedFlags (core/frame.hpp)
  uint32_t markers_used;
  uint32_t collision_constraints;
  uint8_t timecode_hours, timecode_minutes, timecode_seconds, timecode_frames;
  uint16_t timecode_rate_hz;      // 0: no timecode
  uint16_t reserved0;
  float timecode_subframe;
  uint32_t reserved1;
  int64_t stage_ns[kStageCount];  // solver stage durations
  uint8_t reserved_tail[64];
};

// Offsets readers in other languages rely on. Changing any is a new layout version.
static_assert(std::atomic<uint64_t>::is_always_lock_free && std::atomic<int64_t>::is_always_lock_free &&
              std::atomic<uint32_t>::is_always_lock_free, "shared-memory atomics must be address-free");
static_assert(sizeof(std::atomic<uint64_t>) == 8 && sizeof(std::atomic<uint32_t>) == 4);
static_assert(offsetof(Header, magic) == 0);
static_assert(offsetof(Header, layout_version) == 8);
static_assert(offsetof(Header, total_bytes) == 16);
static_assert(offsetof(Header, slot_count) == 24);
static_assert(offsetof(Header, shape_count) == 32);
static_assert(offsetof(Header, slot_weights_offset) == 44);
static_assert(offsetof(Header, shape_names_offset) == 56);
static_assert(offsetof(Header, slots_offset) == 64);
static_assert(offsetof(Header, writer_pid) == 72);
static_assert(offsetof(Header, writer_generation) == 80);
static_assert(offsetof(Header, nominal_rate_hz) == 96);
static_assert(offsetof(Header, rig_name) == 112);
static_assert(offsetof(Header, heartbeat_ns) == 176);
static_assert(offsetof(Header, last_published) == 184);
static_assert(offsetof(Header, writer_state) == 192);
static_assert(offsetof(Header, arkit_names_offset) == 200);
static_assert(sizeof(Header) == 512);

static_assert(offsetof(SlotHeader, seqlock) == 0);
static_assert(offsetof(SlotHeader, sequence) == 8);
static_assert(offsetof(SlotHeader, frame_no) == 16);
static_assert(offsetof(SlotHeader, receive_time_ns) == 32);
static_assert(offsetof(SlotHeader, publish_time_ns) == 56);
static_assert(offsetof(SlotHeader, head_rotation_wxyz) == 64);
static_assert(offsetof(SlotHeader, head_translation) == 80);
static_assert(offsetof(SlotHeader, flags) == 92);
static_assert(offsetof(SlotHeader, timecode_hours) == 104);
static_assert(offsetof(SlotHeader, timecode_subframe) == 112);
static_assert(offsetof(SlotHeader, stage_ns) == 120);
static_assert(sizeof(SlotHeader) == 256);

constexpr uint64_t align_up(uint64_t bytes) noexcept { return (bytes + kAlignment - 1) / kAlignment * kAlignment; }

// Where everything goes for a given shape; the writer and readers compute it the same way.
struct Geometry {
  uint32_t slot_weights_offset = 0;
  uint32_t slot_vertices_offset = 0;
  uint32_t slot_bytes = 0;
  uint64_t shape_names_offset = 0;
  uint64_t arkit_names_offset = 0;
  uint64_t slots_offset = 0;
  uint64_t total_bytes = 0;
};

constexpr Geometry compute_geometry(uint32_t shape_count, uint32_t vertex_count, uint32_t slot_count) noexcept {
  Geometry g;
  g.slot_weights_offset = uint32_t(align_up(sizeof(SlotHeader)));
  g.slot_vertices_offset = uint32_t(g.slot_weights_offset + align_up(uint64_t(shape_count) * sizeof(float)));
  g.slot_bytes = uint32_t(g.slot_vertices_offset + align_up(uint64_t(vertex_count) * 3 * sizeof(float)));
  g.shape_names_offset = align_up(sizeof(Header));
  g.arkit_names_offset = g.shape_names_offset + align_up(uint64_t(shape_count) * kShapeNameBytes);
  g.slots_offset = g.arkit_names_offset + align_up(uint64_t(shape_count) * kShapeNameBytes);
  g.total_bytes = g.slots_offset + uint64_t(slot_count) * g.slot_bytes;
  return g;
}

// Segment names (without the leading '/'): 1 to 200 of [A-Za-z0-9._-].
constexpr bool valid_name(std::string_view name) noexcept {
  if (!name.empty() && name[0] == '/') name.remove_prefix(1);
  if (name.empty() || name.size() > 200) return false;
  for (const char c : name) {
    const bool ok = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '-' || c == '_' || c == '.';
    if (!ok) return false;
  }
  return true;
}

// Limits a reader checks before trusting a header from a segment it did not create.
inline constexpr uint32_t kMaxShapes = 4096;
inline constexpr uint32_t kMaxVertices = 1u << 22;
inline constexpr uint32_t kMaxSlots = 1024;

}  // namespace facecap::shm
