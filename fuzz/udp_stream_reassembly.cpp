// libFuzzer target: datagrams of facecapd's UDP stream through the client library's
// reassembly and message checks (client/udp_stream_reader.hpp). The input is a sequence of
// datagrams, each a little-endian u16 length and that many bytes. Whatever completes must
// be exactly as long as its chunks said, and a frame or schema that passes its checks must
// be readable to its last byte (ASan and UBSan watch). The message limit is lowered to
// 1 MiB so that inputs claiming huge messages stay fast. Seeds: a schema and a frame with
// vertices (fuzz_seeds).
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <vector>

#include "client/udp_stream_reader.hpp"

using namespace facecap::udp;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  Reassembler reassembler(1u << 20);
  std::size_t at = 0;
  while (at + 2 <= size) {
    const std::size_t length = std::size_t(data[at]) | std::size_t(data[at + 1]) << 8;
    at += 2;
    const std::size_t n = length < size - at ? length : size - at;
    const std::optional<Message> message = reassembler.add({data + at, n});
    at += n;
    if (!message) continue;
    if (message->bytes.size() > (1u << 20)) std::abort();
    volatile float sink = 0;
    if (message->kind == kFrameMessage) {
      FrameView view;
      if (!read_frame(message->bytes, view)) continue;
      const std::size_t floats = std::size_t(view.header.shape_count) + std::size_t(view.header.vertex_count) * 3;
      std::vector<float> copy(floats);
      std::memcpy(copy.data(), view.weights, floats * sizeof(float));  // weights and vertices are contiguous
      if (!copy.empty()) sink = copy.back();
    } else {
      SchemaView view;
      if (!read_schema(message->bytes, view)) continue;
      std::vector<ShapeName> names(view.header.shape_count);
      std::memcpy(names.data(), view.names, names.size() * sizeof(ShapeName));
      if (!names.empty()) sink = float(names.back().arkit[kNameBytes - 1]);
    }
    (void)sink;
  }
  const ReassemblyCounters& c = reassembler.counters();
  if (c.completed > c.chunks) std::abort();
  return 0;
}
