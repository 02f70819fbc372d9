#include "udp_stream_reader.hpp"

#include <algorithm>
#include <cstring>

namespace facecap::udp {

std::optional<Message> Reassembler::add(std::span<const unsigned char> datagram) {
  ChunkHeader h;
  if (datagram.size() < sizeof(h)) {
    ++counters_.malformed;
    return std::nullopt;
  }
  std::memcpy(&h, datagram.data(), sizeof(h));
  const std::span<const unsigned char> payload = datagram.subspan(sizeof(h));
  // Every size is checked against the others and the limit before anything is allocated.
  const bool ours = h.magic == kMagic && h.version == kProtocolVersion &&
                    (h.kind == kFrameMessage || h.kind == kSchemaMessage) && h.message_bytes <= max_message_bytes_ &&
                    h.chunk_count == chunks_for(h.message_bytes) && h.chunk_index < h.chunk_count &&
                    h.chunk_offset == uint32_t(h.chunk_index) * kMaxChunkBytes &&
                    payload.size() == std::min<uint64_t>(kMaxChunkBytes, uint64_t(h.message_bytes) - h.chunk_offset);
  if (!ours) {
    ++counters_.malformed;
    return std::nullopt;
  }
  const Newest& newest = newest_[h.kind];
  if (newest.known && newest.stream_id == h.stream_id && h.sequence <= newest.sequence) {
    ++counters_.stale;
    return std::nullopt;
  }
  Slot* slot = slot_for(h);
  if (slot->have[h.chunk_index]) {
    ++counters_.stale;
    return std::nullopt;
  }
  slot->have[h.chunk_index] = 1;
  ++slot->received;
  ++counters_.chunks;
  if (!payload.empty()) std::memcpy(slot->bytes.data() + h.chunk_offset, payload.data(), payload.size());
  if (slot->received < slot->chunk_count) return std::nullopt;

  // Whole. Older messages of this kind and stream still in flight will not be wanted.
  slot->busy = false;
  ++counters_.completed;
  newest_[h.kind] = {true, h.stream_id, h.sequence};
  for (Slot& other : slots_)
    if (other.busy && other.kind == h.kind && other.stream_id == h.stream_id && other.sequence < h.sequence)
      give_up(other);
  return Message{MessageKind(h.kind), h.stream_id, h.sequence, std::span<const unsigned char>(slot->bytes.data(), slot->message_bytes)};
}

Reassembler::Slot* Reassembler::slot_for(const ChunkHeader& h) {
  Slot* free_slot = nullptr;
  Slot* oldest = &slots_[0];
  for (Slot& slot : slots_) {
    if (slot.busy && slot.kind == h.kind && slot.stream_id == h.stream_id && slot.sequence == h.sequence) {
      if (slot.message_bytes == h.message_bytes) return &slot;
      give_up(slot);  // the same message with another size: a broken sender; start again
    }
    if (!slot.busy && !free_slot) free_slot = &slot;
    if (slot.busy && (!oldest->busy || slot.started < oldest->started)) oldest = &slot;
  }
  Slot* slot = free_slot ? free_slot : oldest;
  if (slot->busy) give_up(*slot);
  if (slot->bytes.size() < h.message_bytes) slot->bytes.resize(h.message_bytes);
  slot->have.assign(h.chunk_count, 0);
  slot->busy = true;
  slot->kind = h.kind;
  slot->stream_id = h.stream_id;
  slot->sequence = h.sequence;
  slot->message_bytes = h.message_bytes;
  slot->chunk_count = h.chunk_count;
  slot->received = 0;
  slot->started = ++started_;
  return slot;
}

void Reassembler::give_up(Slot& slot) noexcept {
  slot.busy = false;
  ++counters_.incomplete;
}

void Reassembler::reset() noexcept {
  for (Slot& slot : slots_)
    if (slot.busy) give_up(slot);
  newest_ = {};
}

bool read_frame(std::span<const unsigned char> message, FrameView& out) noexcept {
  if (message.size() < sizeof(FrameHeader)) return false;
  std::memcpy(&out.header, message.data(), sizeof(FrameHeader));
  const FrameHeader& h = out.header;
  if (h.shape_count > kMaxShapes || h.vertex_count > kMaxVertices ||
      message.size() != frame_message_bytes(h.shape_count, h.vertex_count))
    return false;
  out.weights = message.data() + sizeof(FrameHeader);
  out.vertices = h.vertex_count ? out.weights + std::size_t(h.shape_count) * 4 : nullptr;
  return true;
}

bool read_schema(std::span<const unsigned char> message, SchemaView& out) noexcept {
  if (message.size() < sizeof(SchemaHeader)) return false;
  std::memcpy(&out.header, message.data(), sizeof(SchemaHeader));
  const SchemaHeader& h = out.header;
  if (h.shape_count > kMaxShapes || h.vertex_count > kMaxVertices || message.size() != schema_message_bytes(h.shape_count))
    return false;
  out.names = message.data() + sizeof(SchemaHeader);
  return true;
}

}  // namespace facecap::udp
