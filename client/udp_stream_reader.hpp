#pragma once
// Reading facecapd's UDP stream (facecap_udp_layout.hpp, docs/udp-stream.md): datagrams in,
// whole messages out, and the checks that make a message's sizes trustworthy. The client
// library's UDP receiver is built on it; a libFuzzer target (fuzz/udp_stream_reassembly.cpp)
// feeds it arbitrary datagrams. Standard library only.
#include <array>
#include <cstdint>
#include <optional>
#include <span>
#include <vector>

#include "facecap_udp_layout.hpp"

namespace facecap::udp {

struct ReassemblyCounters {
  uint64_t chunks = 0;      // datagrams taken into a message
  uint64_t malformed = 0;   // not this protocol or version, or sizes that do not add up
  uint64_t stale = 0;       // a chunk already held, or of a message already completed or given up
  uint64_t completed = 0;   // whole messages
  uint64_t incomplete = 0;  // messages given up with chunks missing
};

struct Message {
  MessageKind kind = kFrameMessage;
  uint32_t stream_id = 0;
  uint64_t sequence = 0;
  std::span<const unsigned char> bytes;
};

// Collects the chunks of up to kInFlight messages at once. A message is given up (counted
// incomplete) when a newer message of its kind and stream completes first, or when its slot
// is needed for a newer message; chunks of messages older than the newest completed one
// are stale. Not thread-safe.
class Reassembler {
 public:
  static constexpr std::size_t kInFlight = 4;

  explicit Reassembler(uint64_t max_message_bytes = kMaxMessageBytes) : max_message_bytes_(max_message_bytes) {}

  // Takes one datagram; returns the message it completed, which stays valid until the next
  // call. Allocates only for a message larger than any before (at most max_message_bytes,
  // checked before allocating); throws std::bad_alloc when that fails.
  std::optional<Message> add(std::span<const unsigned char> datagram);

  // Gives up every message in flight (counted incomplete) and forgets what completed:
  // the next stream starts afresh.
  void reset() noexcept;

  const ReassemblyCounters& counters() const noexcept { return counters_; }

 private:
  struct Slot {
    bool busy = false;
    uint16_t kind = 0;
    uint32_t stream_id = 0;
    uint64_t sequence = 0;
    uint32_t message_bytes = 0;
    uint16_t chunk_count = 0;
    uint16_t received = 0;
    uint64_t started = 0;                // order of starting, to give up the oldest
    std::vector<unsigned char> have;     // per chunk: received
    std::vector<unsigned char> bytes;    // never shrinks; message_bytes of it in use
  };
  struct Newest {
    bool known = false;
    uint32_t stream_id = 0;
    uint64_t sequence = 0;
  };

  Slot* slot_for(const ChunkHeader& h);
  void give_up(Slot& slot) noexcept;

  uint64_t max_message_bytes_;
  std::array<Slot, kInFlight> slots_;
  std::array<Newest, 3> newest_;  // by MessageKind
  uint64_t started_ = 0;
  ReassemblyCounters counters_;
};

// A frame message whose sizes add up: its header, and where its weights and vertices are
// (4-byte floats, not necessarily aligned: copy them out with memcpy).
struct FrameView {
  FrameHeader header{};
  const unsigned char* weights = nullptr;   // header.shape_count floats
  const unsigned char* vertices = nullptr;  // header.vertex_count * 3 floats, or nullptr
};
// False when the message is not a whole frame within the limits. RT-safe.
bool read_frame(std::span<const unsigned char> message, FrameView& out) noexcept;

struct SchemaView {
  SchemaHeader header{};
  const unsigned char* names = nullptr;  // header.shape_count ShapeName entries
};
// False when the message is not a whole schema within the limits. RT-safe.
bool read_schema(std::span<const unsigned char> message, SchemaView& out) noexcept;

}  // namespace facecap::udp
