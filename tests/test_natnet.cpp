// NatNet packets: real Motive 2.1 traffic decoded to the values in its bytes and
// re-encoded byte for byte; independently encoded 4.1/4.2 packets; round trips at every
// bitstream; truncated, oversize and mutated packets refused with an Error.
#include <random>

#include <fmt/format.h>
#include <catch2/catch.hpp>

#include "core/error.hpp"
#include "core/io.hpp"
#include "formats/natnet.hpp"
#include "tests/test_support.hpp"

using namespace facecap;
using namespace facecap::formats::natnet;

namespace {

std::vector<char> from_hex(std::string_view hex) {
  std::vector<char> out;
  for (std::size_t i = 0; i + 1 < hex.size(); i += 2)
    out.push_back(char(std::stoi(std::string(hex.substr(i, 2)), nullptr, 16)));
  return out;
}

template <typename T>
const T& body_as(const Message& message) {
  REQUIRE(std::holds_alternative<T>(message.body));
  return std::get<T>(message.body);
}

// A message must parse or throw facecap::Error; anything else fails the test.
bool parses(std::span<const char> bytes, Version bitstream) {
  try {
    parse_message(bytes, bitstream, "mutant");
    return true;
  } catch (const Error&) {
    return false;
  }
}

// The same packet with its header's payload size set to what the datagram holds.
std::vector<char> with_consistent_size(std::vector<char> bytes) {
  const auto payload = uint16_t(bytes.size() - kHeaderBytes);
  std::memcpy(bytes.data() + 2, &payload, 2);
  return bytes;
}

// Every proper prefix of a packet is refused, and so is every prefix whose header was
// corrected to its length (which reaches the field parsers) unless `valid_prefixes` says
// that length is a complete message.
void require_truncations_refused(const std::vector<char>& bytes, Version bitstream,
                                 const std::vector<std::size_t>& valid_prefixes = {}) {
  for (std::size_t n = 0; n < bytes.size(); ++n) {
    INFO("prefix of " << n << " bytes");
    const std::vector<char> prefix(bytes.begin(), bytes.begin() + long(n));
    CHECK_THROWS_AS(parse_message(prefix, bitstream, "cut"), Error);
    if (n < kHeaderBytes) continue;
    const bool valid = std::find(valid_prefixes.begin(), valid_prefixes.end(), n) != valid_prefixes.end();
    CHECK(parses(with_consistent_size(prefix), bitstream) == valid);
  }
}

// A frame whose every section is filled, with only what `bitstream` carries.
FrameOfData rich_frame(Version bitstream) {
  FrameOfData f;
  f.frame_number = 77;
  f.marker_sets = {{"Face", {{0.1f, 0.2f, 0.3f}, {0.4f, 0.5f, 0.6f}}}, {"all", {}}};
  f.other_markers = {{1.f, 2.f, 3.f}};
  f.rigid_bodies = {{1, {0.5f, 1.5f, -2.f}, {0.f, 0.f, 0.7071068f, 0.7071068f}, 0.0004f, 1},
                    {2, {0.f, 0.f, 0.f}, {0.f, 0.f, 0.f, 1.f}, 0.f, 0}};
  f.skeletons = {{4, {{4 << 16 | 1, {1.f, 1.f, 1.f}, {0.f, 0.f, 0.f, 1.f}, 0.001f, 1}}}, {5, {}}};
  if (bitstream >= kBitstream41) {
    f.assets = {{9,
                 {{10, {0.f, 1.f, 0.f}, {0.f, 0.f, 0.f, 1.f}, 0.002f, 1}},
                 {{11, {0.3f, 0.2f, 0.1f}, 0.012f, 0x04, 0.0003f}}}};
    f.precision_timestamp_s = 1700000000;
    f.precision_timestamp_frac = 42;
  }
  f.labelled_markers = {{1 << 16 | 3, {0.1f, 1.6f, -0.8f}, 0.02f, 0x0b, 0.0002f},
                        {50007, {2.f, 0.f, 1.f}, 0.015f, 0x12, 0.f}};
  f.force_plates = {{1, {{1.f, 2.f}, {3.f, 4.f}, {}}}};
  f.devices = {{2, {{0.5f, 0.25f, 0.125f}}}, {3, {}}};
  f.timecode = 0x0102031e;
  f.timecode_subframe = 1;
  f.timestamp_s = 1234.5678;
  f.camera_mid_exposure = 1'000'000;
  f.camera_data_received = 1'000'500;
  f.transmit = 1'000'900;
  f.params = 0x03;
  return f;
}

// Model definitions of every kind, with only what `bitstream` carries.
ModelDefinitions rich_models(Version bitstream) {
  const bool names = bitstream >= kBitstream40;
  RigidBodyDescription head{
      "Head",
      3,
      -1,
      {0.f, 0.1f, 0.f},
      {0, 0, 0, 1},
      {{{0.01f, 0.02f, 0.03f}, 0, names ? "Head_1" : ""}, {{-0.01f, 0.f, 0.05f}, 7, names ? "Head_2" : ""}}};
  if (bitstream >= kBitstream42) head.rotation = {0.f, 0.3826834f, 0.f, 0.9238795f};
  ForcePlateDescription plate{1, "FP-001", 0.6f, 0.4f, {0.f, 0.f, 0.f}, {}, {}, 2, 1, {"Fx", "Fy", "Fz"}};
  for (std::size_t i = 0; i < plate.calibration.size(); ++i) plate.calibration[i] = float(i) * 0.25f;
  for (std::size_t i = 0; i < plate.corners.size(); ++i) plate.corners[i] = float(i) - 6.f;
  ModelDefinitions defs;
  defs.models = {
      MarkerSetDescription{"Face", {"Brow", "Chin", "Nose"}},
      head,
      SkeletonDescription{
          "Actor", 1, {head, RigidBodyDescription{"Hips", 1 << 16 | 2, -1, {0.f, 1.f, 0.f}, {0, 0, 0, 1}, {}}}},
      plate,
      DeviceDescription{2, "NIDAQ", "SN42", 1, 1, {"ai0", "ai1"}},
      CameraDescription{"Cam 1", {1.f, 2.5f, -1.f}, {0.f, 0.7071068f, 0.f, 0.7071068f}}};
  if (bitstream >= kBitstream41) {
    defs.models.push_back(AssetDescription{"Trained", 1, 5, {head}, {{"Tip", 7, {0.1f, 0.2f, 0.3f}, 0.012f, 0}}});
    defs.models.push_back(UnknownDescription{42, "\x01\x02\x03"});
  }
  return defs;
}

}  // namespace

TEST_CASE("NatNet session packets from Motive 2.1 decode to their bytes' values", "[natnet][shared]") {
  // Expected values from a separate reading of each file with Python's struct module
  // (struct.unpack_from('<HH', ...), '<4B4BQHB4B' for SERVERINFO's tail), run once by hand.
  FACECAP_REQUIRE_SHARED_DATA(dir, "natnet");
  const auto read = [&](const char* file) { return parse_message(read_file_bytes(dir / file), kBitstream30, file); };

  const Message info = read("serverinfo_packet_v3.bin");
  CHECK(info.id == MessageId::kServerInfo);
  const auto& server = body_as<ServerInfo>(info);
  CHECK(server.sender.name.text() == "Motive");
  CHECK(server.sender.app_version == Version{2, 1, 0, 0});
  CHECK(server.sender.natnet_version == Version{3, 0, 0, 0});
  REQUIRE(server.connection);
  CHECK(server.connection->high_res_clock_hz == 3312787);
  CHECK(server.connection->data_port == 1511);
  CHECK(server.connection->multicast);
  CHECK(server.connection->multicast_group == kDefaultMulticastGroup);

  for (const char* file : {"connect_packet_v3.bin", "discovery_packet_v3.bin"}) {
    const Message m = read(file);
    CHECK(m.id == (std::string_view(file).starts_with("connect") ? MessageId::kConnect : MessageId::kDiscovery));
    const auto& connect = body_as<Connect>(m);
    CHECK(connect.sender.name.text() == "NatNetLib");
    CHECK(connect.sender.app_version == Version{3, 0, 0, 0});
    CHECK(connect.sender.natnet_version == Version{3, 0, 0, 0});
    CHECK_FALSE(connect.options);  // a 3.0 client sends none
    CHECK(connect.trailing_bytes.empty());
  }

  CHECK(body_as<EchoRequest>(read("echorequest_packet_v3.bin")).client_time == 278554190);
  const Message echo_message = read("echoresponse_packet_v3.bin");
  const auto& echo = body_as<EchoResponse>(echo_message);
  CHECK(echo.client_time == 278554190);
  CHECK(echo.server_time == 1416498545924);

  const Message request = read("requestmodeldef_packet_v3.bin");
  CHECK(request.id == MessageId::kRequestModelDef);
  CHECK(body_as<RawPayload>(request).bytes.empty());
}

TEST_CASE("NatNet model definitions from Motive 2.1 decode to their bytes' values", "[natnet][shared]") {
  // Expected values: Python struct reading of modeldef_packet_v3.bin (type, cstring name,
  // '<ii3fi' id/parent/offset/count, '<3f' offsets, '<i' labels), run once by hand.
  FACECAP_REQUIRE_SHARED_DATA(path, "natnet/modeldef_packet_v3.bin");
  const Message message = parse_message(read_file_bytes(path), kBitstream30, "modeldef");
  const auto& defs = body_as<ModelDefinitions>(message);
  REQUIRE(defs.models.size() == 3);
  const auto& body = std::get<RigidBodyDescription>(defs.models[0]);
  CHECK(body.name == "RaceQuad");
  CHECK(body.id == 2);
  CHECK(body.parent_id == -1);
  CHECK(body.offset == Position{0.f, 0.f, 0.f});
  REQUIRE(body.markers.size() == 5);
  CHECK(body.markers[0].offset == Position{0.1611589938402176f, 0.03505159914493561f, -0.03218130022287369f});
  CHECK(body.markers[4].offset == Position{-0.05803820118308067f, -0.03194189816713333f, -0.13680699467658997f});
  for (const auto& m : body.markers) {
    CHECK(m.active_label == 0);
    CHECK(m.name.empty());  // names only from bitstream 4.0
  }
  const auto& quad = std::get<MarkerSetDescription>(defs.models[1]);
  CHECK(quad.name == "RaceQuad");
  CHECK(quad.marker_names == std::vector<std::string>{"Marker1", "Marker2", "Marker3", "Marker4", "Marker5"});
  const auto& all = std::get<MarkerSetDescription>(defs.models[2]);
  CHECK(all.name == "all");
  CHECK(all.marker_names.back() == "RaceQuad_5");
  CHECK(description_kind(defs.models[0]) == "rigid body");
  CHECK(description_name(defs.models[2]) == "all");
}

TEST_CASE("NatNet frames from Motive 2.1 decode to their bytes' values", "[natnet][shared]") {
  // Expected values: Python struct reading ('<i' counts, '<i7ffh' rigid bodies, '<i4fhf'
  // labelled markers, '<IIdQQQhi' suffix) of the two frame files, run once by hand; the
  // floats are Python's repr of each float32, so they compare exactly.
  FACECAP_REQUIRE_SHARED_DATA(dir, "natnet");
  const auto frame =
      body_as<FrameOfData>(parse_message(read_file_bytes(dir / "mocapframe_packet_v3.bin"), kBitstream30, "frame"));
  CHECK(frame.frame_number == 162734);
  CHECK(frame.marker_sets.empty());
  REQUIRE(frame.other_markers.size() == 5);
  CHECK(frame.other_markers[0] == Position{0.12721621990203857f, 1.5050275325775146f, -0.8858283758163452f});
  REQUIRE(frame.rigid_bodies.size() == 1);
  const RigidBodyData& body = frame.rigid_bodies[0];
  CHECK(body.id == 2);
  CHECK(body.position == Position{0.17444664239883423f, 1.4471313953399658f, -0.7343040108680725f});
  CHECK(body.rotation ==
        Quaternion{-0.05459423363208771f, 0.509948194026947f, 0.04370357096195221f, -0.8573576807975769f});
  CHECK(body.mean_error == 0.0005152203375473619f);
  CHECK(body.tracking_valid());
  CHECK(frame.skeletons.empty());
  REQUIRE(frame.labelled_markers.size() == 6);
  const LabelledMarker& first = frame.labelled_markers[0];
  CHECK(first.id == 131073);
  CHECK(first.model_id() == 2);
  CHECK(first.marker_id() == 1);
  CHECK(first.position == Position{0.12721621990203857f, 1.5050275325775146f, -0.8858283758163452f});
  CHECK(first.size == 0.021439820528030396f);
  CHECK(first.residual == 0.00020748283714056015f);
  CHECK(first.params == 0x0a);
  CHECK(first.has(LabelledMarkerFlag::kPointCloudSolved));
  CHECK(first.has(LabelledMarkerFlag::kHasModel));
  CHECK_FALSE(first.has(LabelledMarkerFlag::kOccluded));
  const LabelledMarker& loose = frame.labelled_markers[5];  // no asset: a point-cloud id
  CHECK(loose.id == 50007);
  CHECK(loose.model_id() == 0);
  CHECK(loose.marker_id() == 50007);
  CHECK(loose.has(LabelledMarkerFlag::kUnlabelled));
  CHECK_FALSE(loose.has(LabelledMarkerFlag::kHasModel));
  CHECK(loose.position == Position{0.17081165313720703f, 1.5076590776443481f, -0.840234637260437f});
  CHECK(frame.force_plates.empty());
  CHECK(frame.devices.empty());
  CHECK(frame.timecode == 0);
  CHECK(frame.timestamp_s == 1356.1166666666666);
  CHECK(frame.camera_mid_exposure == 1416497730518);
  CHECK(frame.camera_data_received == 1416497745808);
  CHECK(frame.transmit == 1416497748722);
  CHECK(frame.params == 0);

  const auto occluded = body_as<FrameOfData>(
      parse_message(read_file_bytes(dir / "mocapframe_packet_occluded_v3.bin"), kBitstream30, "occluded"));
  CHECK(occluded.frame_number == 269007);
  REQUIRE(occluded.marker_sets.size() == 2);
  CHECK(occluded.marker_sets[0].name == "FakeTree");
  CHECK(occluded.marker_sets[1].name == "all");
  REQUIRE(occluded.marker_sets[0].markers.size() == 5);
  CHECK(occluded.marker_sets[0].markers[1] ==
        Position{-0.13990189135074615f, 0.4736242890357971f, 0.4416866898536682f});
  REQUIRE(occluded.rigid_bodies.size() == 1);
  CHECK(occluded.rigid_bodies[0].id == 7);
  REQUIRE(occluded.labelled_markers.size() == 4);
  const LabelledMarker& hidden = occluded.labelled_markers[0];
  CHECK(hidden.model_id() == 7);
  CHECK(hidden.marker_id() == 2);
  CHECK(hidden.params == 0x0b);
  CHECK(hidden.has(LabelledMarkerFlag::kOccluded));
  CHECK_FALSE(occluded.labelled_markers[1].has(LabelledMarkerFlag::kOccluded));
  CHECK(occluded.timestamp_s == 8966.9);
}

TEST_CASE("Every real Motive 2.1 packet re-encodes byte for byte at bitstream 3.0", "[natnet][shared]") {
  FACECAP_REQUIRE_SHARED_DATA(dir, "natnet");
  for (const char* file :
       {"connect_packet_v3.bin", "discovery_packet_v3.bin", "echorequest_packet_v3.bin", "echoresponse_packet_v3.bin",
        "mocapframe_packet_occluded_v3.bin", "mocapframe_packet_v3.bin", "modeldef_packet_v3.bin",
        "requestmodeldef_packet_v3.bin", "serverinfo_packet_v3.bin"}) {
    INFO(file);
    const auto bytes = read_file_bytes(dir / file);
    CHECK(encode_message(parse_message(bytes, kBitstream30, file), kBitstream30) == bytes);
  }
}

TEST_CASE("A NatNet 4.1 frame encoded independently decodes and re-encodes exactly", "[natnet]") {
  // Written with Python's struct module from the order in the NatNet SDK 4.3
  // PacketClient.cpp (UnpackFrameData): every section count followed by its byte count,
  // assets between skeletons and labelled markers, precision timestamps before the params.
  const auto bytes = from_hex(
      "0700ab01d20400000100000021000000466163650002000000cdcccc3dcdcc4c3e9a99993e000000bf0000a03f000000"
      "40010000000c00000000001041000000410000e0400100000026000000030000000000003f0000c03f000080be000000"
      "0000000000000000000000803f6f12833a0100010000002e0000000100000001000000010001000000803f0000004000"
      "0040400000003f0000003f0000003f0000003f6f12033b0100010000004c000000050000000100000006000000000080"
      "400000a0400000c040000000000000803f0000000000000000a69b443b000001000000070000000000803e0000003f00"
      "00403f4260653c04006f12033a0200000034000000010003000000003e0000c03f000060bf0ad7a33c0a0017b7513951"
      "c3000000002040000000000000803fbc74933c1100000000000100000018000000010000000200000001000000000028"
      "4101000000000050c001000000180000000200000001000000030000000000803f00000040000040400d0c0b0a020000"
      "0000000000000029406f00000000000000de000000000000004d0100000000000000f1536515cd5b07030000000000");
  const Message message = parse_message(bytes, kBitstream41, "frame 4.1");
  const auto& f = body_as<FrameOfData>(message);
  CHECK(f.frame_number == 1234);
  REQUIRE(f.marker_sets.size() == 1);
  CHECK(f.marker_sets[0].name == "Face");
  CHECK(f.marker_sets[0].markers[1] == Position{-0.5f, 1.25f, 2.0f});
  CHECK(f.other_markers == std::vector<Position>{{9.f, 8.f, 7.f}});
  REQUIRE(f.rigid_bodies.size() == 1);
  CHECK(f.rigid_bodies[0].id == 3);
  REQUIRE(f.skeletons.size() == 1);
  CHECK(f.skeletons[0].bones[0].id == 65537);
  CHECK(f.skeletons[0].bones[0].rotation == Quaternion{0.5f, 0.5f, 0.5f, 0.5f});
  REQUIRE(f.assets.size() == 1);
  CHECK(f.assets[0].id == 5);
  CHECK(f.assets[0].rigid_bodies[0].position == Position{4.f, 5.f, 6.f});
  CHECK(f.assets[0].markers[0].id == 7);
  CHECK(f.assets[0].markers[0].has(LabelledMarkerFlag::kModelSolved));
  REQUIRE(f.labelled_markers.size() == 2);
  CHECK(f.labelled_markers[0].model_id() == 3);
  CHECK(f.labelled_markers[0].marker_id() == 1);
  CHECK(f.labelled_markers[1].has(LabelledMarkerFlag::kOccluded));
  CHECK(f.labelled_markers[1].has(LabelledMarkerFlag::kUnlabelled));
  REQUIRE(f.force_plates.size() == 1);
  CHECK(f.force_plates[0].channels == std::vector<std::vector<float>>{{10.5f}, {-3.25f}});
  REQUIRE(f.devices.size() == 1);
  CHECK(f.devices[0].channels == std::vector<std::vector<float>>{{1.f, 2.f, 3.f}});
  CHECK(format_timecode(f.timecode, f.timecode_subframe) == "10:11:12:13.2");
  CHECK(f.timestamp_s == 12.5);
  CHECK(f.camera_mid_exposure == 111);
  CHECK(f.transmit == 333);
  CHECK(f.precision_timestamp_s == 1700000000);
  CHECK(f.precision_timestamp_frac == 123456789);
  CHECK(f.recording());
  CHECK(f.models_changed());
  CHECK(encode_message(message, kBitstream41) == bytes);
  // The 4.1 layout is not the 4.0 one: read as 4.0, the byte counts become counts.
  CHECK_THROWS_AS(parse_message(bytes, kBitstream40, "frame 4.1 as 4.0"), Error);
  require_truncations_refused(bytes, kBitstream41);
}

TEST_CASE("NatNet 4.2 model definitions encoded independently decode and re-encode exactly", "[natnet]") {
  // Written with Python's struct module from the NatNet SDK 4.3 PacketClient.cpp
  // (UnpackDescription and friends): each description's type then size, rigid bodies with
  // a rotation (4.2) and marker names (4.0), a force plate's 12x12 calibration matrix
  // (0, 1, 2, ...) and corners (0, 0.5, 1, ...), and a description of unknown type 9.
  const auto bytes = from_hex(
      "0500310408000000000000001300000046616365000200000042726f77004368696e00010000005b0000004865616400"
      "03000000ffffffff00000000cdcccc3d000000000000000000000000000000000000803f020000000ad7233c0ad7a33c"
      "8fc2f53c0ad723bc00000000cdcc4c3d0000000007000000486561645f3100486561645f3200020000003b0000004163"
      "746f72000100000001000000486970730001000100ffffffff000000000000803f000000000000000000000000000000"
      "000000803f0000000003000000a10200000100000046502d303031009a99193fcdcccc3e000000000000000000000000"
      "000000000000803f0000004000004040000080400000a0400000c0400000e04000000041000010410000204100003041"
      "00004041000050410000604100007041000080410000884100009041000098410000a0410000a8410000b0410000b841"
      "0000c0410000c8410000d0410000d8410000e0410000e8410000f0410000f84100000042000004420000084200000c42"
      "00001042000014420000184200001c4200002042000024420000284200002c4200003042000034420000384200003c42"
      "00004042000044420000484200004c4200005042000054420000584200005c4200006042000064420000684200006c42"
      "00007042000074420000784200007c42000080420000824200008442000086420000884200008a4200008c4200008e42"
      "000090420000924200009442000096420000984200009a4200009c4200009e420000a0420000a2420000a4420000a642"
      "0000a8420000aa420000ac420000ae420000b0420000b2420000b4420000b6420000b8420000ba420000bc420000be42"
      "0000c0420000c2420000c4420000c6420000c8420000ca420000cc420000ce420000d0420000d2420000d4420000d642"
      "0000d8420000da420000dc420000de420000e0420000e2420000e4420000e6420000e8420000ea420000ec420000ee42"
      "0000f0420000f2420000f4420000f6420000f8420000fa420000fc420000fe4200000043000001430000024300000343"
      "00000443000005430000064300000743000008430000094300000a4300000b4300000c4300000d4300000e4300000f43"
      "000000000000003f0000803f0000c03f0000004000002040000040400000604000008040000090400000a0400000b040"
      "020000000100000002000000467800467900040000001f000000020000004e4944415100534e34320001000000010000"
      "000100000061693000050000002200000043616d2031000000803f00002040000080bf00000000f304353f00000000f3"
      "04353f060000005f000000547261696e656400010000000500000001000000426f6e650006000000ffffffff00000000"
      "00000000000000000000000000000000000000000000803f00000000010000005469700007000000cdcccc3dcdcc4c3e"
      "9a99993ea69b443c00000900000003000000010203");
  const Message message = parse_message(bytes, kBitstream42, "modeldef 4.2");
  const auto& defs = body_as<ModelDefinitions>(message);
  REQUIRE(defs.models.size() == 8);
  CHECK(std::get<MarkerSetDescription>(defs.models[0]).marker_names == std::vector<std::string>{"Brow", "Chin"});
  const auto& head = std::get<RigidBodyDescription>(defs.models[1]);
  CHECK(head.name == "Head");
  CHECK(head.offset == Position{0.f, 0.1f, 0.f});
  CHECK(head.rotation == Quaternion{0.f, 0.f, 0.f, 1.f});
  REQUIRE(head.markers.size() == 2);
  CHECK(head.markers[1].offset == Position{-0.01f, 0.f, 0.05f});
  CHECK(head.markers[1].active_label == 7);
  CHECK(head.markers[1].name == "Head_2");
  const auto& actor = std::get<SkeletonDescription>(defs.models[2]);
  CHECK(actor.name == "Actor");
  REQUIRE(actor.bones.size() == 1);
  CHECK(actor.bones[0].name == "Hips");
  CHECK(actor.bones[0].id == 65537);
  const auto& plate = std::get<ForcePlateDescription>(defs.models[3]);
  CHECK(plate.serial_number == "FP-001");
  CHECK(plate.width == 0.6f);
  CHECK(plate.calibration[143] == 143.f);
  CHECK(plate.corners[11] == 5.5f);
  CHECK(plate.channel_names == std::vector<std::string>{"Fx", "Fy"});
  const auto& device = std::get<DeviceDescription>(defs.models[4]);
  CHECK(device.name == "NIDAQ");
  CHECK(device.serial_number == "SN42");
  CHECK(device.channel_names == std::vector<std::string>{"ai0"});
  const auto& camera = std::get<CameraDescription>(defs.models[5]);
  CHECK(camera.name == "Cam 1");
  CHECK(camera.orientation[1] == 0.7071067690849304f);
  const auto& asset = std::get<AssetDescription>(defs.models[6]);
  CHECK(asset.name == "Trained");
  CHECK(asset.type == 1);
  CHECK(asset.rigid_bodies[0].name == "Bone");
  CHECK(asset.markers[0].name == "Tip");
  CHECK(asset.markers[0].size == 0.012f);
  const auto& unknown = std::get<UnknownDescription>(defs.models[7]);
  CHECK(unknown.type == 9);
  CHECK(unknown.bytes == "\x01\x02\x03");
  CHECK(encode_message(message, kBitstream42) == bytes);
  require_truncations_refused(bytes, kBitstream42);
  // Before 4.1 an unknown description has no size to step over.
  auto no_unknown = defs;
  CHECK_THROWS_WITH(encode_message({MessageId::kModelDef, defs}, kBitstream40),
                    Catch::Contains("unknown model description type 9"));
  no_unknown.models.pop_back();
  CHECK_NOTHROW(encode_message({MessageId::kModelDef, no_unknown}, kBitstream40));
}

TEST_CASE("NatNet frames and model definitions round-trip field by field at 3.0, 3.1, 4.0, 4.1 and 4.2", "[natnet]") {
  for (const Version bitstream : {kBitstream30, kBitstream31, kBitstream40, kBitstream41, kBitstream42}) {
    INFO("bitstream " << bitstream.major_minor());
    const Message frame{MessageId::kFrameOfData, rich_frame(bitstream)};
    const auto frame_bytes = encode_message(frame, bitstream);
    CHECK(parse_message(frame_bytes, bitstream, "frame") == frame);
    const Message models{MessageId::kModelDef, rich_models(bitstream)};
    const auto model_bytes = encode_message(models, bitstream);
    CHECK(parse_message(model_bytes, bitstream, "models") == models);
    require_truncations_refused(frame_bytes, bitstream);
    require_truncations_refused(model_bytes, bitstream);
  }
  // Layout sizes as the SDK describes them: 4.1 adds a byte count to each of the 7 older
  // sections, the assets' count and byte count, and 8 bytes of precision timestamp; 3.1 is 3.0.
  FrameOfData no_assets = rich_frame(kBitstream40);
  const auto size_at = [&](Version v) { return encode_message({MessageId::kFrameOfData, no_assets}, v).size(); };
  CHECK(size_at(kBitstream31) == size_at(kBitstream30));
  CHECK(size_at(kBitstream40) == size_at(kBitstream30));
  CHECK(size_at(kBitstream41) == size_at(kBitstream40) + 7 * 4 + (4 + 4) + 8);
}

TEST_CASE("NatNet fields a bitstream lacks are not written", "[natnet]") {
  const FrameOfData frame41 = rich_frame(kBitstream41);
  const auto as30 = body_as<FrameOfData>(
      parse_message(encode_message({MessageId::kFrameOfData, frame41}, kBitstream30), kBitstream30, "downgraded"));
  CHECK(as30.assets.empty());
  CHECK(as30.precision_timestamp_s == 0);
  CHECK(as30.labelled_markers == frame41.labelled_markers);
  CHECK(as30.timestamp_s == frame41.timestamp_s);

  ModelDefinitions models42 = rich_models(kBitstream42);
  models42.models.resize(6);  // no asset, no unknown description
  const auto as30_models = body_as<ModelDefinitions>(
      parse_message(encode_message({MessageId::kModelDef, models42}, kBitstream30), kBitstream30, "downgraded"));
  const auto& head = std::get<RigidBodyDescription>(as30_models.models[1]);
  CHECK(head.rotation == Quaternion{0, 0, 0, 1});
  CHECK(head.markers[0].name.empty());
  CHECK(head.markers[1].active_label == 7);
}

TEST_CASE("NatNet session messages round-trip and the writer's packets are what the SDK sends", "[natnet]") {
  ServerInfo info;
  info.sender = {NameField::from_text("facecap"), {0, 1, 0, 0}, {4, 1, 0, 0}};
  info.connection = ServerConnection{1'000'000'000, 1511, true, kDefaultMulticastGroup};
  Connect connect;
  connect.sender = {NameField::from_text("Ping"), {}, {}};
  connect.options = ConnectOptions{false, {4, 2, 0, 0}};
  connect.trailing_bytes = std::string(2, '\0');  // as NatNetClient.py 4.3 sends it
  const std::vector<Message> messages{
      {MessageId::kServerInfo, info},
      {MessageId::kConnect, connect},
      {MessageId::kKeepAlive, RawPayload{}},
      {MessageId::kRequest, Text{"Bitstream,3.1"}},
      {MessageId::kResponse, RawPayload{std::string("\x00\x00\xf0\x42", 4)}},
      {MessageId::kEchoRequest, EchoRequest{12345}},
      {MessageId::kEchoResponse, EchoResponse{12345, 987654321}},
      {MessageId::kMessageString, Text{"hello"}},
      {MessageId::kUnrecognizedRequest, RawPayload{}},
  };
  for (const Message& m : messages) {
    INFO(kMessageIds.name(m.id));
    CHECK(parse_message(encode_message(m, kBitstream41), kBitstream41, "round trip") == m);
  }
  // Sizes from NatNetTypes.h: sSender_Server is 256 + 4 + 4 + 8 + 2 + 1 + 4 bytes.
  CHECK(encode_message(messages[0], kBitstream41).size() == kHeaderBytes + 279);
  CHECK(encode_message(messages[1], kBitstream41).size() == kHeaderBytes + 271);  // NatNetClient.py's 271
  CHECK(encode_message(messages[2], kBitstream41) == std::vector<char>{10, 0, 0, 0});
  const auto request = encode_message(messages[3], kBitstream41);
  CHECK(std::string(request.begin(), request.end()) == std::string("\x02\x00\x0e\x00"
                                                                   "Bitstream,3.1\0",
                                                                   18));
  const auto& reply = std::get<RawPayload>(messages[4].body);
  CHECK(reply.as_float() == 120.0f);
  CHECK(reply.as_int32() == 0x42f00000);
  CHECK(RawPayload{std::string("OK\0junk", 7)}.as_text() == "OK");
  CHECK_FALSE(RawPayload{"OK"}.as_int32());
}

TEST_CASE("NatNet packets that lie about their sizes are refused with the byte and field", "[natnet]") {
  const Message message{MessageId::kFrameOfData, rich_frame(kBitstream30)};
  const auto bytes = encode_message(message, kBitstream30);

  // The labelled-marker count: frame number, two marker sets, one other marker, two rigid
  // bodies and two skeletons come first.
  const std::size_t labelled_at =
      kHeaderBytes + 4 + (4 + (5 + 4 + 24) + (4 + 4)) + (4 + 12) + (4 + 2 * 38) + (4 + (4 + 4 + 38) + (4 + 4));
  int32_t count;
  std::memcpy(&count, bytes.data() + labelled_at, 4);
  REQUIRE(count == 2);
  for (const int32_t lie : {INT32_MAX, -1, 1000}) {
    auto bad = bytes;
    std::memcpy(bad.data() + labelled_at, &lie, 4);
    CHECK_THROWS_WITH(
        parse_message(bad, kBitstream30, "lying.bin"),
        Catch::StartsWith(fmt::format("lying.bin @ byte {}: labelled marker count {}", labelled_at, lie)));
  }
  // A header declaring more than the datagram holds.
  auto short_datagram = bytes;
  short_datagram.pop_back();
  CHECK_THROWS_WITH(
      parse_message(short_datagram, kBitstream30, "short.bin"),
      Catch::Contains(fmt::format("NAT_FRAMEOFDATA header declares {} payload bytes, the datagram holds {}",
                                  bytes.size() - 4, bytes.size() - 5)));
  // Bytes beyond the declared payload are not part of the message (NatNetClient.py sends
  // a NUL after its empty requests).
  auto padded = encode_message({MessageId::kRequestModelDef, RawPayload{}}, kBitstream30);
  padded.push_back('\0');
  CHECK(parse_message(padded, kBitstream30, "padded").id == MessageId::kRequestModelDef);
  // Bytes left inside the payload mean a wrong bitstream.
  auto long_payload = with_consistent_size([&] {
    auto b = bytes;
    b.push_back(0);
    return b;
  }());
  CHECK_THROWS_WITH(
      parse_message(long_payload, kBitstream30, "long.bin"),
      Catch::Contains("1 bytes left in the NAT_FRAMEOFDATA payload after its last field (read as bitstream 3.0)"));
  CHECK_THROWS_WITH(parse_message(std::vector<char>{char(200), 0, 0, 0}, kBitstream30, "id.bin"),
                    Catch::Contains("id.bin @ byte 0: unknown NatNet message id 200"));
  CHECK_THROWS_WITH(parse_message(bytes, Version{2, 10}, "old.bin"),
                    Catch::Contains("NAT_FRAMEOFDATA: bitstream 2.10 is not supported (3.x and 4.x are)"));
  // A NAT_REQUEST without its NUL.
  CHECK_THROWS_WITH(parse_message(std::vector<char>{2, 0, 2, 0, 'h', 'i'}, kBitstream30, "req.bin"),
                    Catch::Contains("text has no terminating NUL"));
}

TEST_CASE("The NatNet writer refuses what a packet cannot hold", "[natnet]") {
  FrameOfData big;
  big.labelled_markers.resize(3000);  // 26 bytes each, + frame number, 7 counts and the 46-byte suffix
  CHECK_THROWS_WITH(encode_message({MessageId::kFrameOfData, big}, kBitstream30),
                    Catch::Contains("NAT_FRAMEOFDATA payload of 78078 bytes exceeds a packet's 65535"));
  FrameOfData named;
  named.marker_sets.push_back({std::string("a\0b", 3), {}});
  CHECK_THROWS_WITH(encode_message({MessageId::kFrameOfData, named}, kBitstream30), Catch::Contains("contains a NUL"));
  CHECK_THROWS_WITH(encode_message({MessageId::kFrameOfData, Text{"x"}}, kBitstream30),
                    Catch::Contains("NAT_FRAMEOFDATA cannot carry this kind of body"));
  CHECK_THROWS_AS(NameField::from_text(std::string(256, 'x')), Error);
  CHECK(NameField::from_text(std::string(255, 'x')).text().size() == 255);
}

TEST_CASE("Mutated NatNet packets parse or throw Error, never crash", "[natnet][corruption]") {
  std::vector<std::pair<std::vector<char>, Version>> originals;
  for (const Version v : {kBitstream30, kBitstream41, kBitstream42}) {
    originals.push_back({encode_message({MessageId::kFrameOfData, rich_frame(v)}, v), v});
    originals.push_back({encode_message({MessageId::kModelDef, rich_models(v)}, v), v});
  }
  std::mt19937 rng(17);
  std::size_t refused = 0, read = 0;
  for (int i = 0; i < 3000; ++i) {
    const auto& [original, version] = originals[std::size_t(i) % originals.size()];
    auto mutant = original;
    for (int n = int(rng() % 6) + 1; n > 0; --n) mutant[4 + rng() % (mutant.size() - 4)] = char(rng());
    if (rng() % 2)
      mutant = with_consistent_size(
          std::vector<char>(mutant.begin(), mutant.begin() + long(4 + rng() % (mutant.size() - 3))));
    (parses(mutant, version) ? read : refused) += 1;
  }
  CHECK(read + refused == 3000);
  CHECK(refused > 1000);  // the mutations reached the checks
  CHECK(read > 0);        // and some only changed values
}

TEST_CASE("NatNet versions, timecodes and marker ids decode as the SDK samples do", "[natnet]") {
  CHECK(parse_version("3.0") == Version{3, 0, 0, 0});
  CHECK(parse_version("2.1.0.0") == Version{2, 1, 0, 0});
  CHECK(parse_version("4") == Version{4, 0, 0, 0});
  for (const char* bad : {"", "3.", ".1", "3.x", "256.0", "1.2.3.4.5", "3 .0", "-1.0"}) {
    INFO(bad);
    CHECK_FALSE(parse_version(bad));
  }
  CHECK(Version{4, 1, 0, 0}.major_minor() == "4.1");
  CHECK(is_supported_bitstream(kBitstream30));
  CHECK(is_supported_bitstream(Version{4, 3}));
  CHECK_FALSE(is_supported_bitstream(Version{2, 10}));
  // DecodeTimecode in PacketClient.cpp: hours, minutes, seconds, frames from high byte down.
  const Timecode t = decode_timecode(0x17'3b'3a'1d, 3);
  CHECK(t.hours == 23);
  CHECK(t.minutes == 59);
  CHECK(t.seconds == 58);
  CHECK(t.frames == 29);
  CHECK(format_timecode(0x17'3b'3a'1d, 3) == "23:59:58:29.3");
  CHECK(format_timecode(0, 0) == "00:00:00:00.0");
  // DecodeMarkerID: model in the high 16 bits, marker in the low.
  LabelledMarker marker;
  marker.id = int32_t(0xfffe'0005u);
  CHECK(marker.model_id() == 0xfffe);
  CHECK(marker.marker_id() == 5);
}
