// libFuzzer target: one UDP payload through the NatNet packet parser at each bitstream
// layout (3.0, 4.0, 4.1, 4.2). Bad input must give facecap::Error and nothing else;
// whatever parses must encode, and its encoding must read back to the same encoding.
#include <cstdint>
#include <cstdlib>
#include <span>

#include "core/error.hpp"
#include "formats/natnet.hpp"

using namespace facecap::formats::natnet;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::span<const char> bytes(reinterpret_cast<const char*>(data), size);
  for (const Version bitstream : {kBitstream30, kBitstream40, kBitstream41, kBitstream42}) {
    Message message;
    try {
      message = parse_message(bytes, bitstream, "fuzz");
    } catch (const facecap::Error&) {
      continue;
    }
    // Not inside the try: an Error from the encoder is a bug here.
    const auto encoded = encode_message(message, bitstream);
    if (encode_message(parse_message(encoded, bitstream, "re-encoded"), bitstream) != encoded) std::abort();
  }
  return 0;
}
