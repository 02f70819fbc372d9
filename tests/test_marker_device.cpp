// The marker-device protocol (formats/marker_device.hpp): byte-exact info, control and
// frame encodings (the CRC against zlib's crc32, computed outside this code), chunking and
// reassembly, and what a lost chunk, a bad CRC or a lying length does.
#include <cmath>

#include <catch2/catch.hpp>

#include "core/error.hpp"
#include "formats/marker_device.hpp"

using namespace facecap;
using namespace facecap::formats::device;
using Catch::Contains;

namespace {

using Bytes = std::vector<uint8_t>;

DeviceInfo face_device_info() {
  DeviceInfo info;
  info.marker_capacity = 52;
  info.rate_mhz = 120000;
  info.max_rate_mhz = 240000;
  info.units = Units::kMillimetres;
  info.capabilities = kCapabilityRateSettable;
  info.max_chunk_bytes = 64;
  info.clock_hz = 1000000;
  return info;
}

// Frame 0x01020304 at device time 0x1122334455667788 with marker 7 at (1.5, -2.25, 1000)
// and marker 9 occluded; its bytes and CRC were written by Python's struct and zlib.crc32.
DeviceFrame two_marker_frame() {
  DeviceFrame f;
  f.frame_no = 0x01020304;
  f.device_time = 0x1122334455667788;
  f.markers = {{7, 0, {1.5f, -2.25f, 1000.0f}}, {9, kMarkerOccluded, {0, 0, 0}}};
  return f;
}
const Bytes kTwoMarkerBody = {
    0x04, 0x03, 0x02, 0x01, 0x88, 0x77, 0x66, 0x55, 0x44, 0x33, 0x22, 0x11, 0x02, 0x00, 0x00, 0x00, 0x07, 0x00,
    0x00, 0x00, 0x00, 0x00, 0xc0, 0x3f, 0x00, 0x00, 0x10, 0xc0, 0x00, 0x00, 0x7a, 0x44, 0x09, 0x00, 0x01, 0x00,
    0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x78, 0xfb, 0x46, 0xe8};

// 48 markers on a 10 mm grid, ids 0..47.
DeviceFrame face_frame(uint32_t frame_no) {
  DeviceFrame f;
  f.frame_no = frame_no;
  f.device_time = uint64_t(frame_no) * 8333;
  for (uint16_t id = 0; id < 48; ++id)
    f.markers.push_back({id, 0, {float(id % 8) * 10.0f, float(id / 8) * 10.0f, 500.0f + float(frame_no)}});
  return f;
}

DeviceFrame parsed(std::span<const uint8_t> body) {
  DeviceFrame out;
  out.markers.reserve(kMaxMarkers);
  const DeviceParseResult result = parse_frame_body(body, kMaxMarkers, out);
  INFO(describe(result));
  REQUIRE(result.ok());
  return out;
}

}  // namespace

TEST_CASE("the info block is 32 bytes, byte for byte, and reads back") {
  const auto bytes = encode_info(face_device_info());
  const Bytes expected = {0x46, 0x43, 0x4d, 0x44, 0x01, 0x00, 0x34, 0x00, 0xc0, 0xd4, 0x01, 0x00, 0x80, 0xa9, 0x03, 0x00,
                          0x00, 0x01, 0x40, 0x00, 0x40, 0x42, 0x0f, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00};
  CHECK(Bytes(bytes.begin(), bytes.end()) == expected);
  CHECK(parse_info(bytes, "dev") == face_device_info());
}

TEST_CASE("a bad info block is refused naming the byte and the field") {
  auto bytes = encode_info(face_device_info());
  CHECK_THROWS_WITH(parse_info(std::span(bytes).first(31), "usb 1209:0001"),
                    Contains("usb 1209:0001") && Contains("31 bytes, 32 expected"));
  auto bad = bytes;
  bad[0] = 'X';
  CHECK_THROWS_WITH(parse_info(bad, "dev"), Contains("byte 0") && Contains("not a facecap marker device"));
  bad = bytes;
  bad[4] = 2;
  CHECK_THROWS_WITH(parse_info(bad, "dev"), Contains("byte 4") && Contains("protocol version 2.0"));
  bad = bytes;
  bad[6] = bad[7] = 0;
  CHECK_THROWS_WITH(parse_info(bad, "dev"), Contains("byte 6") && Contains("marker capacity 0"));
  bad = bytes;
  bad[16] = 7;
  CHECK_THROWS_WITH(parse_info(bad, "dev"), Contains("byte 16") && Contains("units code 7"));
  bad = bytes;
  bad[18] = 8;
  bad[19] = 0;
  CHECK_THROWS_WITH(parse_info(bad, "dev"), Contains("byte 18") && Contains("chunk size 8"));
}

TEST_CASE("the control block starts and stops streaming at a rate") {
  const auto start = encode_control({Command::kStart, 240000});
  CHECK(Bytes(start.begin(), start.end()) == Bytes{0x01, 0, 0, 0, 0x80, 0xa9, 0x03, 0x00});
  CHECK(parse_control(start, "dev") == Control{Command::kStart, 240000});
  const auto stop = encode_control({Command::kStop, 0});
  CHECK(Bytes(stop.begin(), stop.end()) == Bytes(8, 0));
  CHECK_THROWS_WITH(parse_control(Bytes{5, 0, 0, 0, 0, 0, 0, 0}, "dev"), Contains("byte 0") && Contains("command 5"));
}

TEST_CASE("a frame body is byte-exact with zlib's CRC-32 and reads back") {
  CHECK(encode_frame_body(two_marker_frame()) == kTwoMarkerBody);
  CHECK(crc32(std::span(kTwoMarkerBody).first(48)) == 0xe846fb78u);
  CHECK(parsed(kTwoMarkerBody) == two_marker_frame());
}

TEST_CASE("a bad CRC, a lying marker count and a short body are errors at their byte") {
  DeviceFrame out;
  out.markers.reserve(64);
  Bytes body = kTwoMarkerBody;
  body[20] ^= 0x01;  // one bit of marker 7's x
  DeviceParseResult r = parse_frame_body(body, 64, out);
  CHECK(r.error == DeviceError::kBadCrc);
  CHECK(r.offset == 48);
  CHECK(describe(r) == "bad CRC at byte 48");

  body = kTwoMarkerBody;
  body[12] = 3;  // says three markers, carries two
  r = parse_frame_body(body, 64, out);
  CHECK(r.error == DeviceError::kBadMarkerCount);
  CHECK(r.offset == 12);
  CHECK(parse_frame_body(kTwoMarkerBody, 1, out).error == DeviceError::kBadMarkerCount);  // over the capacity
  CHECK(parse_frame_body(std::span(kTwoMarkerBody).first(19), 64, out).error == DeviceError::kShortFrame);
}

TEST_CASE("a 48-marker frame spans 15 chunks of 64 bytes and reassembles exactly") {
  const DeviceFrame frame = face_frame(70000);
  const auto chunks = encode_frame_chunks(frame, 64);
  REQUIRE(chunks.size() == 15);  // 788 body bytes, 56 per chunk
  CHECK(chunks[0][0] == kChunkSync);
  CHECK(chunks[0][1] == kChunkFirst);
  CHECK(chunks[0][2] == (70000 & 0xFF));
  CHECK(chunks[0][3] == ((70000 >> 8) & 0xFF));
  CHECK(chunks[7][1] == 0);
  CHECK(chunks[7][4] == 7);
  CHECK(chunks[14][1] == kChunkLast);
  CHECK(chunks[14].size() == 8 + 788 - 14 * 56);

  FrameAssembler assembler(frame_body_bytes(64));
  for (std::size_t i = 0; i < chunks.size(); ++i) {
    const auto r = assembler.push(chunks[i]);
    CHECK(r.used == chunks[i].size());
    CHECK(r.status == (i + 1 < chunks.size() ? FrameAssembler::Status::kPending : FrameAssembler::Status::kComplete));
  }
  CHECK(parsed(assembler.body()) == frame);
}

TEST_CASE("chunks packed back to back in one bulk transfer are taken one by one, HID padding skipped") {
  const auto chunks = encode_frame_chunks(face_frame(1), 512);
  REQUIRE(chunks.size() == 2);
  Bytes transfer;
  for (const auto& c : chunks) transfer.insert(transfer.end(), c.begin(), c.end());
  transfer.insert(transfer.end(), 20, 0);  // zero padding, as a fixed-size HID report has
  FrameAssembler assembler(frame_body_bytes(64));
  std::span<const uint8_t> rest(transfer);
  auto r = assembler.push(rest);
  CHECK(r.status == FrameAssembler::Status::kPending);
  rest = rest.subspan(r.used);
  r = assembler.push(rest);
  CHECK(r.status == FrameAssembler::Status::kComplete);
  CHECK(rest.size() - r.used == 20);
  CHECK(parsed(assembler.body()) == face_frame(1));
}

TEST_CASE("a lost chunk drops its frame and the next frame assembles") {
  const auto first = encode_frame_chunks(face_frame(10), 64);
  const auto second = encode_frame_chunks(face_frame(11), 64);
  FrameAssembler assembler(frame_body_bytes(64));
  CHECK(assembler.push(first[0]).status == FrameAssembler::Status::kPending);
  const auto gap = assembler.push(first[2]);  // chunk 1 lost
  CHECK(gap.status == FrameAssembler::Status::kDropped);
  CHECK(gap.error.error == DeviceError::kOutOfSequence);
  for (std::size_t i = 3; i < first.size(); ++i)
    CHECK(assembler.push(first[i]).status == FrameAssembler::Status::kDropped);  // the rest of frame 10
  FrameAssembler::Result r;
  for (const auto& c : second) r = assembler.push(c);
  CHECK(r.status == FrameAssembler::Status::kComplete);
  CHECK(parsed(assembler.body()).frame_no == 11);

  // The last chunk of frame 10 lost: frame 11's first chunk gives frame 10 up.
  for (std::size_t i = 0; i + 1 < first.size(); ++i) assembler.push(first[i]);
  CHECK(assembler.push(second[0]).abandoned);
}

TEST_CASE("a frame bigger than the assembler's capacity, a bad sync byte and a lying payload length are dropped") {
  const auto chunks = encode_frame_chunks(face_frame(3), 64);  // 788 bytes
  FrameAssembler small(frame_body_bytes(10));
  FrameAssembler::Result r;
  for (const auto& c : chunks)
    if ((r = small.push(c)).status != FrameAssembler::Status::kPending) break;
  CHECK(r.status == FrameAssembler::Status::kDropped);
  CHECK(r.error.error == DeviceError::kFrameTooLarge);

  FrameAssembler assembler(frame_body_bytes(64));
  Bytes bad = chunks[0];
  bad[0] = 0x00;
  r = assembler.push(bad);
  CHECK(r.error.error == DeviceError::kBadSync);
  CHECK(r.used == bad.size());
  bad = chunks[0];
  bad[6] = 0xFF;  // payload length 255+ in a 64-byte chunk
  r = assembler.push(bad);
  CHECK(r.error.error == DeviceError::kChunkOverrun);
  CHECK(r.error.offset == 6);
  CHECK(assembler.push(Bytes{kChunkSync, 0, 0}).error.error == DeviceError::kBadSync);
}

TEST_CASE("chunk sizes with no room for payload or too many chunks are refused") {
  CHECK_THROWS_WITH(encode_frame_chunks(face_frame(0), 8), Contains("chunk size 8"));
  DeviceFrame big;
  big.markers.resize(1000);
  CHECK_THROWS_WITH(encode_frame_chunks(big, 16), Contains("at most 256 are allowed"));
}
