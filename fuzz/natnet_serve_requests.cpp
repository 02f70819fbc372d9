// libFuzzer target: what `facecap natnet-serve` answers (tools/natnet_server.hpp), i.e.
// NatNet command packets from a client and the NAT_REQUEST texts in them
// (formats/natnet_request.hpp). The input is a conversation from one client: datagrams,
// each a 2-byte little-endian length and that many bytes, answered in turn by a fresh
// unicast server of two marker sets. NatNetServer::answer must never throw, and each of
// its replies must parse as NatNet at one of the bitstreams it serves.
#include <cstdint>
#include <cstdlib>

#include "fuzz/fuzz_support.hpp"
#include "tools/natnet_server.hpp"

namespace {

using namespace facecap;
namespace nn = formats::natnet;

formats::MarkerTake small_take() {
  formats::MarkerTake take;
  take.format = formats::TakeFormat::kTrc;
  take.labels = {"A:Brow", "A:Chin", "B:Brow"};
  take.rate_hz = 60;
  take.units = "mm";
  for (int i = 0; i < 2; ++i) {
    MarkerFrame& f = formats::append_empty_frame(take, i + 1, i * 16'666'667);
    for (std::size_t k = 0; k < f.markers.size(); ++k) {
      f.markers[k].position = Eigen::Vector3d(10.0 * double(k) + i, 150.0, -80.0);
      f.markers[k].flags = 0;
    }
  }
  return take;
}

bool parses_at_a_served_bitstream(const std::vector<char>& bytes) {
  for (const nn::Version bitstream : {nn::kBitstream30, nn::kBitstream31, nn::kBitstream40, nn::kBitstream41}) {
    try {
      nn::parse_message(bytes, bitstream, "reply");
      return true;
    } catch (const Error&) {
    }
  }
  return false;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static const formats::MarkerTake take = small_take();
  tools::ServeOptions options;
  options.mode = tools::ServeMode::kUnicast;
  options.marker_sets = {{"Anna", "A:"}, {"Ben", "B:"}};
  tools::NatNetServer server(options, take);
  const drivers::natnet::Endpoint client{0x7f000001, 50000};
  const std::span<const char> input = fuzz::bytes_of(data, size);
  int64_t now_ns = 0;
  for (std::size_t at = 0; at + 2 <= input.size();) {
    const std::size_t length = uint8_t(input[at]) | std::size_t(uint8_t(input[at + 1])) << 8;
    at += 2;
    const std::span<const char> datagram = input.subspan(at, std::min(length, input.size() - at));
    at += datagram.size();
    now_ns += 1'000'000;
    for (const tools::Outgoing& reply : server.answer(datagram, client, now_ns))
      if (!parses_at_a_served_bitstream(reply.bytes)) std::abort();
  }
  return 0;
}
