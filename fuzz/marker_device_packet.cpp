// libFuzzer target: the bytes as what a USB or HID marker device sends (formats/marker_device.hpp):
// an info block, a control block, and a stream of chunks reassembled into frame bodies.
// Bad input must give facecap::Error (info, control) or a counted DeviceError (chunks,
// bodies) and nothing else; every body that parses must encode back to the same bytes.
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <span>

#include "core/error.hpp"
#include "formats/marker_device.hpp"

using namespace facecap::formats::device;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::span<const uint8_t> bytes(data, size);
  try {
    const DeviceInfo info = parse_info(bytes, "fuzz");
    // The reserved tail is not read; everything before it must round-trip.
    if (std::memcmp(encode_info(info).data(), data, 24) != 0) std::abort();
  } catch (const facecap::Error&) {
  }
  try {
    const Control control = parse_control(bytes, "fuzz");
    if (std::memcmp(encode_control(control).data(), data, 1) != 0) std::abort();
  } catch (const facecap::Error&) {
  }

  FrameAssembler assembler(frame_body_bytes(256));
  DeviceFrame frame;
  frame.markers.reserve(256);
  for (std::span<const uint8_t> rest = bytes; !rest.empty();) {
    const FrameAssembler::Result r = assembler.push(rest);
    if (r.used == 0 || r.used > rest.size()) std::abort();  // must always make progress
    rest = rest.subspan(r.used);
    if (r.status != FrameAssembler::Status::kComplete) continue;
    const std::span<const uint8_t> body = assembler.body();
    if (!parse_frame_body(body, 256, frame).ok()) continue;
    const std::vector<uint8_t> encoded = encode_frame_body(frame);
    if (encoded.size() != body.size() || std::memcmp(encoded.data(), body.data(), body.size()) != 0) std::abort();
  }
  return 0;
}
