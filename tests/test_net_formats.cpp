// The network outputs' bytes: OSC 1.0 (against the spec's own examples), Unreal Live Link
// Face packets (from the documented layout), facecap's UDP stream (offsets of the
// published layout, chunking, and reassembly with loss, duplicates, reordering and junk),
// and the ARKit mapping they share.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <random>

#include <catch2/catch.hpp>

#include "client/udp_stream_reader.hpp"
#include "core/error.hpp"
#include "formats/arkit.hpp"
#include "formats/livelink_packet.hpp"
#include "formats/osc.hpp"
#include "outputs/udp/udp_stream_encoding.hpp"

using namespace facecap;
using namespace facecap::formats;
namespace udp_stream = facecap::outputs::udp_stream;

namespace {

std::vector<char> bytes(std::initializer_list<int> values) {
  std::vector<char> out;
  for (const int v : values) out.push_back(char(v));
  return out;
}

void append(std::vector<char>& out, const std::vector<char>& more) { out.insert(out.end(), more.begin(), more.end()); }

void append_text(std::vector<char>& out, std::string_view text) {
  for (const char c : text) out.push_back(c);
}

std::vector<char> be32(uint32_t v) { return bytes({int(v >> 24), int((v >> 16) & 0xff), int((v >> 8) & 0xff), int(v & 0xff)}); }
std::vector<char> be_float(float f) {
  uint32_t u = 0;
  std::memcpy(&u, &f, 4);
  return be32(u);
}

template <typename T>
T read_le(const std::vector<char>& b, std::size_t at) {
  T v;
  std::memcpy(&v, b.data() + at, sizeof v);
  return v;
}

SolvedFrame test_frame(Eigen::Index shapes, Eigen::Index vertices, int64_t n = 7) {
  SolvedFrame f;
  f.resize(shapes, vertices);
  f.frame_no = n;
  f.source_time_ns = 1'000'000 * n;
  f.receive_time_ns = 5'000'000 + n;
  f.solve_start_ns = 5'100'000 + n;
  f.solve_end_ns = 5'200'000 + n;
  f.timecode = {1, 2, 3, 4, 0.5f, 30};
  f.head_rotation = Eigen::Quaterniond(Eigen::AngleAxisd(0.3, Eigen::Vector3d(1, 2, 3).normalized()));
  f.head_translation = {1.5, -2.25, 3.125};
  f.flags = kSolvedHeadPoseHeld;
  f.markers_used = 44;
  for (Eigen::Index i = 0; i < shapes; ++i) f.weights[i] = float(n) + 0.001f * float(i);
  for (Eigen::Index i = 0; i < f.vertices.size(); ++i) f.vertices.data()[i] = float(i) * 0.5f - 3.0f;
  return f;
}

std::span<const unsigned char> as_unsigned(const std::vector<char>& d) {
  return {reinterpret_cast<const unsigned char*>(d.data()), d.size()};
}

}  // namespace

// ---- OSC ----

TEST_CASE("OSC messages are byte-exact with the OSC 1.0 specification's examples") {
  // "/oscillator/4/frequency" 440.0: the 32-byte message of the spec's first example.
  std::vector<char> one;
  osc::OscWriter w1(one);
  w1.begin_message("/oscillator/4/frequency", "f");
  w1.float32(440.0f);
  w1.end_message();
  std::vector<char> expected_one;
  append_text(expected_one, "/oscillator/4/frequency");
  append(expected_one, bytes({0, 0x2c, 0x66, 0, 0, 0x43, 0xdc, 0, 0}));
  CHECK(one == expected_one);
  CHECK(one.size() == 32);

  // "/foo" 1000, -1, "hello", 1.234, 5.678: the spec's second example, 40 bytes.
  std::vector<char> two;
  osc::OscWriter w2(two);
  w2.begin_message("/foo", "iisff");
  w2.int32(1000);
  w2.int32(-1);
  w2.string("hello");
  w2.float32(1.234f);
  w2.float32(5.678f);
  w2.end_message();
  CHECK(two == bytes({0x2f, 0x66, 0x6f, 0x6f, 0, 0, 0, 0, 0x2c, 0x69, 0x69, 0x73, 0x66, 0x66, 0, 0, 0, 0, 0x03, 0xe8,
                      0xff, 0xff, 0xff, 0xff, 0x68, 0x65, 0x6c, 0x6c, 0x6f, 0, 0, 0, 0x3f, 0x9d, 0xf3, 0xb6, 0x40, 0xb5,
                      0xb2, 0x2d}));
}

TEST_CASE("OSC strings end in one to four NULs and bundles carry each element's size") {
  for (std::size_t n = 0; n < 9; ++n) CHECK(osc::string_size(std::string(n, 'x')) == (n / 4 + 1) * 4);

  std::vector<char> b;
  osc::OscWriter w(b);
  w.begin_bundle();
  w.begin_message("/VMC/Ext/Blend/Val", "sf");
  w.string("JawOpen");
  const std::size_t value_at = w.float32(0.25f);
  w.end_message();
  w.begin_message("/VMC/Ext/Blend/Apply", "");
  w.end_message();
  w.end_bundle();

  std::vector<char> expected;
  append_text(expected, "#bundle");
  append(expected, bytes({0, 0, 0, 0, 0, 0, 0, 0, 1}));  // NUL, time tag 1: immediately
  append(expected, be32(20 + 4 + 8 + 4));                 // element: address 20, ",sf" 4, "JawOpen" 8, float 4
  append_text(expected, "/VMC/Ext/Blend/Val");
  append(expected, bytes({0, 0, ',', 's', 'f', 0}));
  append_text(expected, "JawOpen");
  append(expected, bytes({0}));
  append(expected, be_float(0.25f));
  append(expected, be32(24 + 4));                         // "/VMC/Ext/Blend/Apply" 24, "," 4
  append_text(expected, "/VMC/Ext/Blend/Apply");
  append(expected, bytes({0, 0, 0, 0, ',', 0, 0, 0}));
  CHECK(b == expected);
  CHECK(b.size() % 4 == 0);

  osc::patch_float32(b, value_at, 0.75f);
  CHECK(std::vector<char>(b.begin() + long(value_at), b.begin() + long(value_at) + 4) == be_float(0.75f));
}

TEST_CASE("OSC writing refuses arguments that do not follow the type tags") {
  std::vector<char> b;
  osc::OscWriter w(b);
  w.begin_message("/a", "sf");
  CHECK_THROWS_AS(w.float32(1.0f), Error);  // a string comes first
  w.string("x");
  CHECK_THROWS_AS(w.end_message(), Error);   // the float is missing
  w.float32(1.0f);
  w.end_message();
  CHECK_THROWS_AS(osc::OscWriter(b).begin_message("no-slash", ""), Error);
  osc::OscWriter nul(b);
  nul.begin_message("/b", "s");
  CHECK_THROWS_AS(nul.string(std::string_view("a\0b", 3)), Error);
}

// ---- Live Link Face ----

TEST_CASE("a Live Link Face packet is byte-exact with the version 6 layout") {
  livelink::LiveLinkFrame f;
  f.frame_number = 123456;
  f.subframe = 0.25f;
  f.fps_numerator = 60;
  f.fps_denominator = 1;
  for (std::size_t i = 0; i < livelink::kValueCount; ++i) f.values[i] = float(i) / 64.0f - 0.5f;
  const std::string device = "8F2D5C1A-0B3E-4F6A-9D7C-112233445566";
  std::vector<char> packet;
  livelink::encode_packet(device, "face", f, packet);

  std::vector<char> expected = bytes({6});
  append(expected, be32(36));
  append_text(expected, device);
  append(expected, be32(4));
  append_text(expected, "face");
  append(expected, be32(123456));
  append(expected, be_float(0.25f));
  append(expected, be32(60));
  append(expected, be32(1));
  append(expected, bytes({61}));
  for (const float v : f.values) append(expected, be_float(v));
  CHECK(packet == expected);
  CHECK(packet.size() == 270 + 36 + 4);
  CHECK(packet.size() == livelink::packet_size(device, "face"));
  CHECK_THROWS_AS(livelink::encode_packet(std::string(2000, 'x'), "face", f, packet), Error);
}

TEST_CASE("Live Link frame times come from the timecode, else from the source clock") {
  livelink::LiveLinkFrame f;
  livelink::set_frame_time(Timecode{1, 2, 3, 4, 0.5f, 30}, 0, 240.0, f);
  CHECK(f.frame_number == (3600 + 2 * 60 + 3) * 30 + 4);
  CHECK(f.subframe == 0.5f);
  CHECK(f.fps_numerator == 30);
  CHECK(f.fps_denominator == 1);
  // No timecode: 2.5 s and a third of a frame on a 240 Hz clock.
  livelink::set_frame_time(Timecode{}, 2'500'000'000 + 1'388'889, 240.0, f);
  CHECK(f.frame_number == 600);
  CHECK(f.subframe == Approx(1.0 / 3.0).margin(1e-3));
  CHECK(f.fps_numerator == 240);
  livelink::set_frame_time(Timecode{}, 0, 59.94, f);
  CHECK(f.fps_numerator == 59940);
  CHECK(f.fps_denominator == 1000);
}

TEST_CASE("Live Link device ids are 36-character UUIDs, a pure function of their seed") {
  const auto a = livelink::device_id_from("machine-1 facecap");
  const std::string id(a.data(), a.size());
  CHECK(id.size() == 36);
  for (std::size_t i = 0; i < id.size(); ++i) {
    if (i == 8 || i == 13 || i == 18 || i == 23) CHECK(id[i] == '-');
    else CHECK(std::isxdigit(static_cast<unsigned char>(id[i])));
  }
  CHECK(id[14] == '8');                                         // UUID version 8
  CHECK(std::string("89AB").find(id[19]) != std::string::npos);  // RFC variant
  CHECK(livelink::device_id_from("machine-1 facecap") == a);
  CHECK(livelink::device_id_from("machine-2 facecap") != a);
}

// ---- ARKit ----

TEST_CASE("head yaw, pitch and roll decompose R = Ry Rx Rz") {
  for (const auto& [yaw, pitch, roll] : {std::tuple{0.3, -0.2, 0.1}, std::tuple{-1.2, 0.7, -2.5}, std::tuple{2.9, -1.4, 0.0}}) {
    const Eigen::Quaterniond q = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitY()) *
                                 Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitX()) *
                                 Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitZ());
    const auto angles = head_yaw_pitch_roll(q);
    CHECK(angles[0] == Approx(yaw).margin(1e-5));
    CHECK(angles[1] == Approx(pitch).margin(1e-5));
    CHECK(angles[2] == Approx(roll).margin(1e-5));
  }
  CHECK(head_yaw_pitch_roll(Eigen::Quaterniond::Identity()) == std::array<float, 3>{0, 0, 0});
}

TEST_CASE("ARKit weights average split rig shapes and are 0 where the rig has none") {
  const std::vector<std::string> rig = {"jawOpen", "browInnerUp_L", "browInnerUp_R", "eyeBlink_L", "notArkit"};
  const ArkitWeights arkit(rig);
  const std::vector<float> w = {0.5f, 0.2f, 0.4f, 1.0f, 0.9f};
  std::array<float, kArkitShapeCount> out{};
  arkit.map(w, out);
  CHECK(out[*arkit_shape_index("JawOpen")] == 0.5f);
  CHECK(out[*arkit_shape_index("BrowInnerUp")] == Approx(0.3f));
  CHECK(out[*arkit_shape_index("EyeBlinkLeft")] == 1.0f);
  CHECK(out[*arkit_shape_index("TongueOut")] == 0.0f);
  CHECK(arkit.realised() == 3);
  CHECK(arkit_names_of(rig) == std::vector<std::string>{"JawOpen", "", "", "EyeBlinkLeft", ""});
}

// ---- the UDP stream ----

TEST_CASE("a UDP stream frame message has the published layout's offsets") {
  const SolvedFrame f = test_frame(3, 2);
  std::vector<char> m;
  udp_stream::encode_frame(f, {0xabcdef01u, 0x1122334455667788ull, 999}, true, m);
  REQUIRE(m.size() == 120 + 3 * 4 + 2 * 12);
  CHECK(read_le<int64_t>(m, 0) == 7);
  CHECK(read_le<int64_t>(m, 8) == 7'000'000);
  CHECK(read_le<int64_t>(m, 16) == 5'000'007);
  CHECK(read_le<int64_t>(m, 24) == 5'100'007);
  CHECK(read_le<int64_t>(m, 32) == 5'200'007);
  CHECK(read_le<int64_t>(m, 40) == 999);
  CHECK(read_le<float>(m, 48) == float(f.head_rotation.w()));
  CHECK(read_le<float>(m, 52) == float(f.head_rotation.x()));
  CHECK(read_le<float>(m, 64) == 1.5f);
  CHECK(read_le<float>(m, 72) == 3.125f);
  CHECK(read_le<uint32_t>(m, 76) == kSolvedHeadPoseHeld);
  CHECK(read_le<uint32_t>(m, 80) == 44);
  CHECK(read_le<uint32_t>(m, 84) == 3);
  CHECK(read_le<uint32_t>(m, 88) == 2);
  CHECK(read_le<uint32_t>(m, 92) == 0xabcdef01u);
  CHECK(read_le<uint64_t>(m, 96) == 0x1122334455667788ull);
  CHECK(std::vector<char>(m.begin() + 104, m.begin() + 108) == bytes({1, 2, 3, 4}));
  CHECK(read_le<uint16_t>(m, 108) == 30);
  CHECK(read_le<float>(m, 112) == 0.5f);
  CHECK(read_le<float>(m, 120 + 8) == f.weights[2]);
  CHECK(read_le<float>(m, 132) == f.vertices(0, 0));
  CHECK(read_le<float>(m, 132 + 20) == f.vertices(2, 1));

  // Without vertices the message stops after the weights.
  udp_stream::encode_frame(f, {}, false, m);
  CHECK(m.size() == 132);
  CHECK(read_le<uint32_t>(m, 88) == 0);
}

TEST_CASE("UDP stream datagrams are at most 1,400 bytes and carry the chunk header's fields") {
  const SolvedFrame f = test_frame(57, 6706);  // the ICT face's size
  std::vector<char> m;
  udp_stream::encode_frame(f, {}, true, m);
  CHECK(m.size() == 120 + 57 * 4 + 6706 * 12);
  const auto grams = udp_stream::datagrams(udp::kFrameMessage, 0x01020304u, 9, m);
  CHECK(grams.size() == (m.size() + 1367) / 1368);
  std::size_t payload = 0;
  for (std::size_t i = 0; i < grams.size(); ++i) {
    const std::vector<char>& d = grams[i];
    CHECK(d.size() <= 1400);
    CHECK(std::string(d.data(), 4) == "FCUD");
    CHECK(read_le<uint16_t>(d, 4) == 1);
    CHECK(read_le<uint16_t>(d, 6) == udp::kFrameMessage);
    CHECK(read_le<uint32_t>(d, 8) == 0x01020304u);
    CHECK(read_le<uint32_t>(d, 12) == m.size());
    CHECK(read_le<uint64_t>(d, 16) == 9);
    CHECK(read_le<uint32_t>(d, 24) == i * 1368);
    CHECK(read_le<uint16_t>(d, 28) == i);
    CHECK(read_le<uint16_t>(d, 30) == grams.size());
    payload += d.size() - 32;
  }
  CHECK(payload == m.size());
}

TEST_CASE("UDP stream messages reassemble in any order; duplicates, junk and stale chunks are ignored") {
  const SolvedFrame f = test_frame(57, 500);
  std::vector<char> m;
  udp_stream::encode_frame(f, {5, 6, 7}, true, m);
  auto grams = udp_stream::datagrams(udp::kFrameMessage, 77, 1, m);
  REQUIRE(grams.size() == 5);
  std::mt19937 rng(3);
  std::shuffle(grams.begin(), grams.end(), rng);
  udp::Reassembler r;
  std::optional<udp::Message> whole;
  for (std::size_t i = 0; i < grams.size(); ++i) {
    if (i == 2) CHECK_FALSE(r.add(as_unsigned(grams[0])));  // a duplicate
    std::vector<char> junk = grams[i];
    junk[0] = 'X';                                          // not our magic
    CHECK_FALSE(r.add(as_unsigned(junk)));
    whole = r.add(as_unsigned(grams[i]));
    CHECK(whole.has_value() == (i + 1 == grams.size()));
  }
  REQUIRE(whole);
  CHECK(whole->kind == udp::kFrameMessage);
  CHECK(whole->stream_id == 77);
  CHECK(whole->sequence == 1);
  CHECK(std::equal(whole->bytes.begin(), whole->bytes.end(), m.begin(), m.end(),
                   [](unsigned char a, char b) { return a == (unsigned char)b; }));
  udp::FrameView view;
  REQUIRE(udp::read_frame(whole->bytes, view));
  CHECK(view.header.frame_no == 7);
  CHECK(view.header.schema_id == 5);
  float w = 0;
  std::memcpy(&w, view.weights + 4 * 56, 4);
  CHECK(w == f.weights[56]);
  // A late copy of a chunk of the completed message is stale.
  CHECK_FALSE(r.add(as_unsigned(grams[1])));
  CHECK(r.counters().completed == 1);
  CHECK(r.counters().stale == 2);
  CHECK(r.counters().malformed == grams.size());
  CHECK(r.counters().incomplete == 0);
}

TEST_CASE("a UDP stream frame with a chunk lost is given up and counted when a newer one completes") {
  const SolvedFrame f = test_frame(10, 300);
  std::vector<char> m;
  udp_stream::encode_frame(f, {}, true, m);
  udp::Reassembler r;
  auto first = udp_stream::datagrams(udp::kFrameMessage, 1, 1, m);
  REQUIRE(first.size() == 3);
  CHECK_FALSE(r.add(as_unsigned(first[0])));
  CHECK_FALSE(r.add(as_unsigned(first[2])));  // chunk 1 never comes
  const auto second = udp_stream::datagrams(udp::kFrameMessage, 1, 2, m);
  std::optional<udp::Message> whole;
  for (const auto& d : second) whole = r.add(as_unsigned(d));
  REQUIRE(whole);
  CHECK(whole->sequence == 2);
  CHECK(r.counters().incomplete == 1);
  CHECK_FALSE(r.add(as_unsigned(first[1])));  // too late: stale
  CHECK(r.counters().stale == 1);
}

TEST_CASE("UDP stream chunks whose sizes do not add up are refused before anything is allocated") {
  std::vector<char> m(3000, 'a');
  auto grams = udp_stream::datagrams(udp::kFrameMessage, 1, 1, m);
  auto patched = [&](std::size_t at, uint32_t value, int bytes_wide) {
    std::vector<char> d = grams[0];
    std::memcpy(d.data() + at, &value, std::size_t(bytes_wide));
    return d;
  };
  udp::Reassembler r(4096);
  CHECK_FALSE(r.add(as_unsigned(patched(12, 1u << 30, 4))));   // a message beyond the limit
  CHECK_FALSE(r.add(as_unsigned(patched(30, 7, 2))));          // a chunk count that does not fit the size
  CHECK_FALSE(r.add(as_unsigned(patched(24, 5, 4))));          // an offset that is not index * 1368
  CHECK_FALSE(r.add(as_unsigned(patched(28, 3, 2))));          // an index past the count
  CHECK_FALSE(r.add(as_unsigned(patched(4, 2, 2))));           // another version
  std::vector<char> short_payload = grams[0];
  short_payload.pop_back();
  CHECK_FALSE(r.add(as_unsigned(short_payload)));
  CHECK_FALSE(r.add(as_unsigned(std::vector<char>(10, 0))));  // shorter than a header
  CHECK(r.counters().malformed == 7);
  CHECK(r.counters().chunks == 0);

  // A whole message whose frame header's counts disagree with its size is not a frame.
  udp::FrameView view;
  std::vector<unsigned char> frame(120 + 8, 0);
  uint32_t shapes = 3;
  std::memcpy(frame.data() + 84, &shapes, 4);
  CHECK_FALSE(udp::read_frame(frame, view));
  shapes = 2;
  std::memcpy(frame.data() + 84, &shapes, 4);
  CHECK(udp::read_frame(frame, view));
}

TEST_CASE("a UDP stream schema names every shape and its id changes with its content, not its flags") {
  udp_stream::StreamSchema s;
  s.rig_hash = 99;
  s.rig_name = "ict";
  s.shape_names = {"jawOpen", "browInnerUp_L", std::string(80, 'n')};
  s.arkit_names = arkit_names_of(s.shape_names);
  s.vertex_count = 6706;
  s.frame_rate_hz = 240;
  std::vector<char> m;
  const uint32_t id = udp_stream::encode_schema(s, 0, m);
  REQUIRE(m.size() == 104 + 3 * 128);
  udp::SchemaView view;
  REQUIRE(udp::read_schema(as_unsigned(m), view));
  CHECK(view.header.schema_id == id);
  CHECK(view.header.shape_count == 3);
  CHECK(view.header.vertex_count == 6706);
  CHECK(view.header.interval_ms == 1000);
  CHECK(view.header.frame_rate_hz == 240.0);
  CHECK(std::string(view.header.rig_name) == "ict");
  udp::ShapeName names[3];
  std::memcpy(names, view.names, sizeof names);
  CHECK(std::string(names[0].rig) == "jawOpen");
  CHECK(std::string(names[0].arkit) == "JawOpen");
  CHECK(std::string(names[1].arkit).empty());
  CHECK(std::string(names[2].rig) == std::string(63, 'n'));  // truncated, NUL-terminated

  std::vector<char> stopping;
  CHECK(udp_stream::encode_schema(s, udp::kSchemaStopping, stopping) == id);
  CHECK(read_le<uint32_t>(stopping, 12) == udp::kSchemaStopping);
  s.shape_names[0] = "jawOpen2";
  CHECK(udp_stream::encode_schema(s, 0, m) != id);
}
