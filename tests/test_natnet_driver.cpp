// The NatNet server of `facecap natnet-serve` answered datagram by datagram (no sockets),
// the server clock followed through echoes, and the NatNet driver in-process against a
// natnet-serve process on loopback: frames with their markers and exposure times, bad
// datagrams counted exactly and dropped while frames keep coming, and datagrams from
// senders other than the server dropped unread and counted.
#include <catch2/catch.hpp>
#include <fmt/format.h>

#include "core/error.hpp"
#include "drivers/natnet/natnet_source.hpp"
#include "drivers/natnet/server_clock.hpp"
#include "formats/natnet_markers.hpp"
#include "formats/natnet_request.hpp"
#include "tests/process_test_support.hpp"
#include "tools/natnet_server.hpp"

using namespace facecap;
using namespace facecap::formats::natnet;
using drivers::natnet::Endpoint;
using Catch::Contains;
namespace fs = std::filesystem;

namespace {

constexpr int64_t kSecond = kNsPerSecond;
const Endpoint kClient{0x7f000001, 50000};

// Two actors' markers in one take, in cm: "A:" and "B:" prefixes; A:Chin missing in frame 1.
formats::MarkerTake two_actor_take() {
  formats::MarkerTake take;
  take.format = formats::TakeFormat::kTrc;
  take.labels = {"A:Brow", "A:Chin", "B:Brow"};
  take.rate_hz = 60;
  take.units = "cm";
  for (int i = 0; i < 3; ++i) {
    MarkerFrame& f = formats::append_empty_frame(take, i + 1, i * kSecond / 60);
    for (int k = 0; k < 3; ++k) {
      f.markers[std::size_t(k)].position = Eigen::Vector3d(10.0 * k + i, 150.0 + k, -80.0 - i);
      f.markers[std::size_t(k)].flags = 0;
    }
  }
  formats::set_missing(take.frames[1].markers[1]);
  return take;
}

std::vector<char> packet(MessageId id, MessageBody body = RawPayload{}, Version bitstream = kBitstream41) {
  return encode_message({id, std::move(body)}, bitstream);
}

std::vector<char> request(std::string text) { return packet(MessageId::kRequest, Text{std::move(text)}); }

Message reply_of(const std::vector<tools::Outgoing>& out, Version bitstream = kBitstream41) {
  REQUIRE(out.size() == 1);
  return parse_message(out[0].bytes, bitstream, "reply");
}

Connect connect_body(std::optional<ConnectOptions> options = std::nullopt) {
  Connect c;
  c.sender.name = NameField::from_text("test client");
  c.sender.natnet_version = {4, 1, 0, 0};
  c.options = options;
  return c;
}

tools::NatNetServer two_actor_server(tools::ServeMode mode) {
  tools::ServeOptions o;
  o.mode = mode;
  o.data_port = 41511;
  o.marker_sets = {{"Anna", "A:"}, {"Ben", "B:"}};
  o.exposure_latency_ms = 3;
  return tools::NatNetServer(o, two_actor_take());
}

}  // namespace

TEST_CASE("natnet-serve answers connect, model definitions and requests as Motive does", "[natnet]") {
  tools::NatNetServer server = two_actor_server(tools::ServeMode::kUnicast);
  const auto info = std::get<ServerInfo>(reply_of(server.answer(packet(MessageId::kConnect, connect_body()), kClient, 0)).body);
  CHECK(info.sender.name.text() == "facecap natnet-serve");
  CHECK(info.sender.natnet_version == Version{4, 1, 0, 0});
  REQUIRE(info.connection);
  CHECK(info.connection->high_res_clock_hz == 1'000'000'000);
  CHECK(info.connection->data_port == 41511);
  CHECK_FALSE(info.connection->multicast);
  CHECK(server.clients() == 1);

  const auto models = std::get<ModelDefinitions>(reply_of(server.answer(packet(MessageId::kRequestModelDef), kClient, 0)).body);
  REQUIRE(models.models.size() == 4);
  CHECK(std::get<MarkerSetDescription>(models.models[0]) == MarkerSetDescription{"Anna", {"Brow", "Chin"}});
  const auto& anna = std::get<AssetDescription>(models.models[1]);  // 4.1: a trained marker set
  CHECK(anna.name == "Anna");
  CHECK(anna.id == 1);
  REQUIRE(anna.markers.size() == 2);
  CHECK(anna.markers[1].name == "Chin");
  CHECK(anna.markers[1].id == 2);
  CHECK(std::get<MarkerSetDescription>(models.models[2]) == MarkerSetDescription{"Ben", {"Brow"}});

  CHECK(reply_of(server.answer(request("FrameRate"), kClient, 0)).id == MessageId::kResponse);
  CHECK(std::get<RawPayload>(reply_of(server.answer(request("FrameRate"), kClient, 0)).body).as_float() == 60.0f);
  CHECK(std::get<RawPayload>(reply_of(server.answer(request("Bitstream"), kClient, 0)).body).as_text() == "Bitstream,4.1");
  CHECK(reply_of(server.answer(request("TimelinePlay"), kClient, 0)).id == MessageId::kUnrecognizedRequest);
  const auto echo =
      std::get<EchoResponse>(reply_of(server.answer(packet(MessageId::kEchoRequest, EchoRequest{1234}), kClient, 0)).body);
  CHECK(echo.client_time == 1234);
  CHECK(echo.server_time > 0);
  CHECK(server.answer(std::vector<char>{'\x07', '\x00', '\x09'}, kClient, 0).empty());
  CHECK(server.counts().bad_requests == 1);

  // The client asks for 3.1: its frames and models come in 3.1's layout from now on.
  CHECK(std::get<RawPayload>(reply_of(server.answer(request("Bitstream,3.1"), kClient, 0)).body).as_int32() == kRequestDone);
  CHECK(std::get<RawPayload>(reply_of(server.answer(request("Bitstream,2.5"), kClient, 0), kBitstream31).body).as_int32() ==
        kRequestRefused);
  const auto models31 =
      std::get<ModelDefinitions>(reply_of(server.answer(packet(MessageId::kRequestModelDef), kClient, 0), kBitstream31).body);
  CHECK(std::get<RigidBodyDescription>(models31.models[1]).id == 1);  // before 4.1: a rigid body owns the markers
  const auto frames = server.next_frame(kSecond, kSecond);
  REQUIRE(frames.size() == 1);
  CHECK(frames[0].to == kClient);  // 4.x unicast: to the command socket it connected from
  CHECK_NOTHROW(parse_message(frames[0].bytes, kBitstream31, "frame"));
}

TEST_CASE("natnet-serve frames carry each actor's markers in metres, occlusion flagged, and the three stamps",
          "[natnet]") {
  tools::NatNetServer server = two_actor_server(tools::ServeMode::kUnicastDataPort);
  server.answer(packet(MessageId::kConnect, connect_body()), kClient, 0);
  const auto models = std::get<ModelDefinitions>(reply_of(server.answer(packet(MessageId::kRequestModelDef), kClient, 0)).body);
  FrameConverter anna({.marker_set = "Anna"}, models, "serve"), ben({.marker_set = "Ben"}, models, "serve");
  MarkerFrame a = make_marker_frame(anna.labels()), b = make_marker_frame(ben.labels());
  const formats::MarkerTake take = two_actor_take();
  for (int i = 0; i < 3; ++i) {
    const int64_t due = (10 + i) * kSecond / 60;
    const auto out = server.next_frame(due, due + 200'000);
    REQUIRE(out.size() == 1);
    CHECK(out[0].to == Endpoint{kClient.address, 41511});  // 3.x style: the client's host, data port
    const auto frame = std::get<FrameOfData>(parse_message(out[0].bytes, kBitstream41, "frame").body);
    CHECK(frame.frame_number == i + 1);
    CHECK(frame.camera_mid_exposure == uint64_t(due - 3'000'000));
    CHECK(frame.camera_data_received == uint64_t(due));
    CHECK(frame.transmit == uint64_t(due + 200'000));
    REQUIRE(frame.assets.size() == 2);
    anna.convert(frame, a);
    ben.convert(frame, b);
    CHECK(a.frame_no == i + 1);
    CHECK(a.markers[0].position.isApprox(take.frames[std::size_t(i)].markers[0].position * 0.01, 1e-6));
    CHECK(b.markers[0].position.isApprox(take.frames[std::size_t(i)].markers[2].position * 0.01, 1e-6));
    CHECK(a.markers[1].present() == (i != 1));
  }
  CHECK(server.counts().frames == 3);
}

TEST_CASE("natnet-serve in multicast streams one frame to the group, refuses per-client bitstreams, forgets silent "
          "unicast clients", "[natnet]") {
  tools::NatNetServer multicast = two_actor_server(tools::ServeMode::kMulticast);
  CHECK(std::get<RawPayload>(reply_of(multicast.answer(request("Bitstream,3.1"), kClient, 0)).body).as_int32() ==
        kRequestRefused);
  const auto out = multicast.next_frame(0, 0);
  REQUIRE(out.size() == 1);
  CHECK(out[0].to == Endpoint{0xefff2a63, 41511});  // 239.255.42.99
  CHECK(multicast.clients() == 0);

  tools::NatNetServer unicast = two_actor_server(tools::ServeMode::kUnicast);
  unicast.answer(packet(MessageId::kConnect, connect_body(ConnectOptions{false, kBitstream31})), kClient, 0);
  unicast.answer(packet(MessageId::kKeepAlive), kClient, 4 * kSecond);
  CHECK(unicast.next_frame(8 * kSecond, 8 * kSecond).size() == 1);  // seen 4 s ago: still served
  const auto last = unicast.next_frame(10 * kSecond, 10 * kSecond);
  REQUIRE(last.size() == 1);
  CHECK(parse_message(last[0].bytes, kBitstream31, "bye").id == MessageId::kDisconnectByTimeout);
  CHECK(unicast.clients() == 0);

  formats::MarkerTake take = two_actor_take();
  CHECK_THROWS_WITH(tools::NatNetServer({.marker_sets = {{"Anna", "A:"}, {"Ben", ""}}}, take),
                    Contains("several marker sets need a label prefix each"));
  CHECK_THROWS_WITH(tools::NatNetServer({.marker_sets = {{"Cleo", "C:"}}}, take), Contains("no label of the take begins"));
  take.units = "";
  CHECK_THROWS_WITH(tools::NatNetServer({}, take), Contains("not mm, cm or m"));
}

TEST_CASE("the server clock is followed through echoes: the shortest round trip gives the offset", "[natnet]") {
  drivers::natnet::ServerClock clock;
  clock.set_rate(10'000'000);  // Motive's 10 MHz clock
  CHECK_FALSE(clock.synchronised());
  CHECK(clock.to_local_ns(123) == 0);
  // Server time = our time - 5 s. Echoes with queueing on one leg: 2 ms there, 0.2 ms back.
  const auto ticks_at = [](int64_t local_ns) { return uint64_t((local_ns - 5 * kSecond) / 100); };
  clock.add_echo(100 * kSecond, ticks_at(100 * kSecond + 2'000'000), 100 * kSecond + 2'200'000);
  CHECK(clock.synchronised());
  // The stamp came late in the round trip; the midpoint taken for it is 0.9 ms early.
  CHECK(clock.to_local_ns(ticks_at(200 * kSecond)) == 200 * kSecond - 900'000);
  // A quick echo (0.1 ms each way) wins over the slow one.
  clock.add_echo(101 * kSecond, ticks_at(101 * kSecond + 100'000), 101 * kSecond + 200'000);
  CHECK(clock.round_trip_ns() == 200'000);
  CHECK(clock.to_local_ns(ticks_at(200 * kSecond)) == 200 * kSecond);
  CHECK(clock.ticks_to_ns(10'000'000) == kSecond);
  CHECK(clock.ticks_to_ns(uint64_t(1) << 62) == int64_t((static_cast<unsigned __int128>(1) << 62) * 100));
}

TEST_CASE("the natnet driver takes frames from natnet-serve and counts and drops bad datagrams", "[natnet]") {
  const fs::path dir = test::scratch_dir("natnet-driver");
  const uint16_t port = uint16_t(20000 + ::getpid() % 20000 * 2 % 20000);
  // A take written for the server: the two actors above, looped at 60 Hz.
  formats::write_take(dir / "take.trc", two_actor_take());
  test::ChildProcess serve("tools/facecap",
                           {"natnet-serve", (dir / "take.trc").string(), "--loop", "--seconds", "20", "--mode", "unicast",
                            "--address", "127.0.0.1", "--command-port", std::to_string(port), "--data-port",
                            std::to_string(port + 1), "--marker-set", "Anna=A:", "--marker-set", "Ben=B:",
                            "--exposure-latency-ms", "4"},
                           {}, dir / "serve.log");
  INFO(serve.log());
  REQUIRE(serve.wait_for_log("commands on 127.0.0.1", 10 * kSecond));

  drivers::NatNetOptions o;
  o.server_address = "127.0.0.1";
  o.command_port = port;
  o.data_port = port + 1;
  o.local_interface = "127.0.0.1";
  o.marker_set = "Ben";
  o.connect_timeout_s = 5;
  o.silence_timeout_s = 1;
  o.timecode_rate_hz = 30;
  drivers::NatNetSource source(o);
  source.open();
  CHECK(source.info().labels == std::vector<std::string>{"Brow"});
  CHECK(source.info().units == "m");
  CHECK(source.info().nominal_rate_hz == 60.0);
  CHECK_FALSE(source.multicast());
  CHECK_THAT(source.description(), Contains("marker set 'Ben' (1 markers)") && Contains("bitstream 4.1"));
  source.start({});

  MarkerFrame frame = make_marker_frame(source.info().labels);
  const auto wait_frames = [&](uint64_t n) {
    const int64_t give_up = monotonic_now_ns() + 10 * kSecond;
    while (source.counts().frames < n && monotonic_now_ns() < give_up) usleep(5000);
    return source.counts().frames >= n;
  };
  REQUIRE(wait_frames(80));  // past the first echo: exposure times known
  REQUIRE(source.take_frame(monotonic_now_ns(), frame));
  const formats::MarkerTake take = two_actor_take();
  const auto& expected = take.frames[std::size_t((frame.frame_no - 1) % 3)].markers[2].position;
  CHECK(frame.markers[0].position.isApprox(expected * 0.01, 1e-6));
  REQUIRE(frame.exposure_time_ns != 0);
  const double exposure_ms = double(frame.receive_time_ns - frame.exposure_time_ns) / kNsPerMs;
  INFO("exposure -> receive " << exposure_ms << " ms");
  CHECK(exposure_ms > 3.9);
  CHECK(exposure_ms < 30.0);

  // Bad datagrams at the data port from the server's address (frames may come from any of
  // its ports): each kind counted, none delivered as a frame.
  drivers::natnet::UdpSocket attacker(0x7f000001, 0, false, "test");
  const Endpoint data_port{0x7f000001, uint16_t(port + 1)};
  const auto send = [&](std::vector<char> bytes) { CHECK(attacker.send_to(bytes, data_port)); };
  send({'\x07', '\x00'});                                        // shorter than a header
  send({'\x07', '\x00', '\x64', '\x00', '\x01', '\x02'});        // says 100 bytes, has 2
  send({'\x07', '\x00', '\x04', '\x00', '\x01', '\x00', '\x00', '\x00', '\x00', '\x00'});  // 2 bytes more than it says
  send({'\x07', '\x00', '\x04', '\x00', '\x01', '\x00', '\x00', '\x00'});  // a frame cut after its number
  // Not the server: a message other than a frame from another port than its command port,
  // and anything from another address, dropped unread.
  send({'\x4d', '\x00', '\x00', '\x00'});                        // message id 77
  drivers::natnet::UdpSocket stranger(0x7f000009, 0, false, "stranger");
  ServerInfo spoofed = two_actor_server(tools::ServeMode::kUnicast).server_info();
  spoofed.sender.natnet_version = {3, 0, 0, 0};
  CHECK(stranger.send_to(packet(MessageId::kServerInfo, spoofed), data_port));
  CHECK(stranger.send_to(packet(MessageId::kMessageString, Text{"evil\n<0>facecapd: EMERGENCY"}), data_port));
  const uint64_t frames_before = source.counts().frames;
  const int64_t give_up = monotonic_now_ns() + 5 * kSecond;
  while ((source.health().errors < 4 || source.health().foreign < 3) && monotonic_now_ns() < give_up) usleep(5000);
  REQUIRE(wait_frames(frames_before + 30));
  const drivers::NatNetCounts counts = source.counts();
  CHECK(counts.truncated == 2);
  CHECK(counts.oversize == 1);
  CHECK(counts.malformed == 1);
  CHECK(source.health().errors == 4);
  CHECK(counts.foreign == 3);
  CHECK(source.health().foreign == 3);
  CHECK(source.bitstream().major_minor() == "4.1");  // the spoofed SERVERINFO changed nothing
  CHECK(counts.stale == 0);
  CHECK(source.health().state.empty());
  source.stop();
}
