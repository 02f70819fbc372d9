// NatNet messages out of captures: the real Motive 2.1 session, and synthetic sessions
// whose bitstream comes from a client request, a server's info, an option, or a switch.
#include <map>

#include <fmt/format.h>
#include <catch2/catch.hpp>

#include "drivers/capture/capture_file.hpp"
#include "tests/capture_test_support.hpp"
#include "tests/test_support.hpp"

using namespace facecap;
using namespace facecap::capture;
using namespace facecap::formats;
using namespace facecap::formats::natnet;
using namespace facecap::test;

namespace {

constexpr std::array<uint8_t, 4> kServer{10, 0, 0, 1};
constexpr std::array<uint8_t, 4> kClient{10, 0, 0, 2};
constexpr uint16_t kClientPort = 50123;

FrameOfData frame_numbered(int32_t number, Version bitstream) {
  FrameOfData f;
  f.frame_number = number;
  f.timestamp_s = number / 240.0;
  f.labelled_markers = {{1 << 16 | 1, {0.1f * float(number), 1.f, 2.f}, 0.02f, 0x0a, 0.f}};
  if (bitstream >= kBitstream41) f.assets = {{3, {}, {{7, {1.f, 2.f, 3.f}, 0.01f, 0, 0.f}}}};
  return f;
}

// One UDP datagram per message, fragmented when over an Ethernet MTU.
void add(std::vector<PcapRecord>& records, int64_t time_ns, const Message& message, Version bitstream,
         std::array<uint8_t, 4> from, uint16_t from_port, std::array<uint8_t, 4> to, uint16_t to_port) {
  const Bytes segment = udp_segment(from_port, to_port, bytes_of(encode_message(message, bitstream)));
  for (const Bytes& ip : ipv4_fragments(from, to, segment, uint16_t(records.size()), 1480)) {
    records.push_back({time_ns, ethernet_frame(0x0800, ip)});
  }
}

std::map<MessageId, std::size_t> kinds(const NatNetCapture& capture) {
  std::map<MessageId, std::size_t> count;
  for (const auto& m : capture.messages) ++count[m.message.id];
  return count;
}

std::vector<const FrameOfData*> frames_of(const NatNetCapture& capture) {
  std::vector<const FrameOfData*> frames;
  for (const auto& m : capture.messages) {
    if (const auto* f = std::get_if<FrameOfData>(&m.message.body)) frames.push_back(f);
  }
  return frames;
}

}  // namespace

TEST_CASE("The real Motive 2.1 session capture decodes to 550 NatNet messages at bitstream 3.0",
          "[natnet][pcap][shared]") {
  // Message kinds counted from the first two bytes of each UDP payload as tshark shows
  // them (`tshark -T fields -e data.data`), frame numbers and timestamps with Python's
  // struct module, run once by hand.
  FACECAP_REQUIRE_SHARED_DATA(path, "natnet/traffic.pcapng");
  const NatNetCapture capture = read_natnet_capture(path);
  CHECK(capture.messages.size() == 550);
  CHECK(capture.undecodable == 0);
  CHECK(capture.other_ports == 0);
  CHECK(capture.errors.empty());
  CHECK_FALSE(capture.damage);
  CHECK(capture.bitstream == Version{3, 0, 0, 0});
  CHECK(capture.bitstream_source == BitstreamSource::kServerInfo);
  REQUIRE(capture.server_info);
  CHECK(capture.server_info->sender.name.text() == "Motive");
  CHECK(capture.server_info->sender.app_version == Version{2, 1, 0, 0});
  const std::map<MessageId, std::size_t> expected{
      {MessageId::kFrameOfData, 518},
      {MessageId::kEchoRequest, 9},
      {MessageId::kEchoResponse, 9},
      {MessageId::kRequest, 4},
      {MessageId::kResponse, 3},
      {MessageId::kServerInfo, 2},
      {MessageId::kConnect, 1},
      {MessageId::kDiscovery, 1},
      {MessageId::kRequestModelDef, 1},
      {MessageId::kModelDef, 1},
      {MessageId::kUnrecognizedRequest, 1},
  };
  CHECK(kinds(capture) == expected);
  const auto frames = frames_of(capture);
  REQUIRE(frames.size() == 518);
  CHECK(frames.front()->frame_number == 162734);
  CHECK(frames.back()->frame_number == 163251);
  CHECK(frames.back()->timestamp_s == 1360.425);
  CHECK(frame_rate_hz(capture) == Approx(120.0).epsilon(1e-9));
  // The reply to "FrameRate" (the next NAT_RESPONSE; an echo comes between) is a float.
  const auto message_after = [&](auto from, MessageId id) {
    return std::find_if(from, capture.messages.end(), [&](const auto& m) { return m.message.id == id; });
  };
  const auto frame_rate = std::find_if(capture.messages.begin(), capture.messages.end(), [](const auto& m) {
    const auto* request = std::get_if<Text>(&m.message.body);
    return request && request->text == "FrameRate";
  });
  const auto reply = message_after(frame_rate, MessageId::kResponse);
  REQUIRE(reply != capture.messages.end());
  CHECK(std::get<RawPayload>(reply->message.body).as_float() == 120.0f);
  // Ports and addresses as tshark shows them.
  const CapturedMessage& first_frame = *message_after(capture.messages.begin(), MessageId::kFrameOfData);
  CHECK(first_frame.source.to_string() == "192.168.0.106");
  CHECK(first_frame.destination.to_string() == "239.255.42.99");
  CHECK(first_frame.destination_port == 1511);
  CHECK(first_frame.capture_time_ns == 1'509'244'025'141'882'000);
}

TEST_CASE("A 4.x session's bitstream comes from the client's request and follows a Bitstream switch",
          "[natnet][pcap]") {
  std::vector<PcapRecord> records;
  int64_t t = 1'000'000'000;
  Connect connect;
  connect.sender.name = NameField::from_text("facecap test");
  connect.options = ConnectOptions{false, kBitstream41};
  add(records, t, {MessageId::kConnect, connect}, kBitstream41, kClient, kClientPort, kServer, kCommandPort);
  ServerInfo info;
  info.sender = {NameField::from_text("Motive"), {3, 1, 0, 0}, {4, 2, 0, 0}};  // the server could do 4.2
  info.connection = ServerConnection{10'000'000, kDataPort, false, {}};
  add(records, t, {MessageId::kServerInfo, info}, kBitstream41, kServer, kCommandPort, kClient, kClientPort);
  // Model definitions over an MTU: three IP fragments.
  ModelDefinitions models;
  for (int i = 0; i < 40; ++i) {
    models.models.push_back(RigidBodyDescription{
        fmt::format("body {}", i), i, -1, {}, {0, 0, 0, 1}, {{{0.1f, 0.f, 0.f}, 0, "a"}, {{0.f, 0.1f, 0.f}, 0, "b"}}});
  }
  add(records, t, {MessageId::kModelDef, models}, kBitstream41, kServer, kCommandPort, kClient, kClientPort);
  // 4.x unicast: frames to the client's command socket.
  for (int32_t n = 1; n <= 3; ++n) {
    add(records, t += 4'166'667, {MessageId::kFrameOfData, frame_numbered(n, kBitstream41)}, kBitstream41, kServer,
        kCommandPort, kClient, kClientPort);
  }
  add(records, t, {MessageId::kRequest, Text{"Bitstream,3.0"}}, kBitstream41, kClient, kClientPort, kServer,
      kCommandPort);
  for (int32_t n = 4; n <= 5; ++n) {
    add(records, t += 4'166'667, {MessageId::kFrameOfData, frame_numbered(n, kBitstream30)}, kBitstream30, kServer,
        kCommandPort, kClient, kClientPort);
  }
  // Traffic on other ports is counted, not decoded.
  records.push_back(
      {t, ethernet_frame(0x0800, ipv4_packet(kServer, kClient, 17, udp_segment(53, 5353, Bytes(20, 0))))});

  const auto file = pcap_file(1, records);
  const NatNetCapture capture = read_natnet_capture(file, "session.pcap");
  CHECK(capture.bitstream == kBitstream41);
  CHECK(capture.bitstream_source == BitstreamSource::kClientRequest);
  CHECK(capture.undecodable == 0);
  CHECK(capture.other_ports == 1);
  CHECK(capture.records.reassembled == 1);
  CHECK(capture.file_format == "pcap");
  CHECK(capture.link_type == "EN10MB");
  const auto* decoded_models = std::get_if<ModelDefinitions>(&capture.messages[2].message.body);
  REQUIRE(decoded_models);
  CHECK(*decoded_models == models);
  const auto frames = frames_of(capture);
  REQUIRE(frames.size() == 5);
  for (int32_t n = 1; n <= 5; ++n) {
    INFO("frame " << n);
    CHECK(*frames[std::size_t(n - 1)] == frame_numbered(n, n <= 3 ? kBitstream41 : kBitstream30));
  }
  CHECK(frame_rate_hz(capture) == Approx(240.0));

  // Without the CONNECT the server's version (4.2, same frame layout as 4.1) is used.
  const std::vector<PcapRecord> without_connect(records.begin() + 1, records.end());
  const NatNetCapture served = read_natnet_capture(pcap_file(1, without_connect), "served.pcap");
  CHECK(served.bitstream == Version{4, 2, 0, 0});
  CHECK(served.bitstream_source == BitstreamSource::kServerInfo);
  CHECK(frames_of(served).size() == 5);
}

TEST_CASE("Without a session start the option chooses the layout, and misreads are counted with their place",
          "[natnet][pcap]") {
  std::vector<PcapRecord> records;
  for (int32_t n = 1; n <= 4; ++n) {
    add(records, n * 1'000'000, {MessageId::kFrameOfData, frame_numbered(n, kBitstream41)}, kBitstream41, kServer,
        kDataPort, kClient, kDataPort);
  }
  const auto file = pcap_file(1, records);
  CaptureOptions options;
  options.default_bitstream = kBitstream41;
  const NatNetCapture right = read_natnet_capture(file, "frames.pcap", options);
  CHECK(right.bitstream_source == BitstreamSource::kOption);
  CHECK(frames_of(right).size() == 4);

  const NatNetCapture wrong = read_natnet_capture(file, "frames.pcap");  // 3.0 by default
  CHECK(wrong.messages.empty());
  CHECK(wrong.undecodable == 4);
  REQUIRE(wrong.errors.size() == 4);
  CHECK_THAT(wrong.errors[0], Catch::StartsWith("frames.pcap record 1 @ byte "));

  // Datagrams on other ports are tried only when asked.
  std::vector<PcapRecord> elsewhere;
  add(elsewhere, 0, {MessageId::kFrameOfData, frame_numbered(1, kBitstream30)}, kBitstream30, kServer, 7000, kClient,
      7001);
  CHECK(read_natnet_capture(pcap_file(1, elsewhere), "x.pcap").other_ports == 1);
  options = {};
  options.any_port = true;
  CHECK(frames_of(read_natnet_capture(pcap_file(1, elsewhere), "x.pcap", options)).size() == 1);
}
