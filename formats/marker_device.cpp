#include "formats/marker_device.hpp"

#include <algorithm>
#include <bit>
#include <cstring>

#include <boost/crc.hpp>
#include <fmt/format.h>

#include "core/error.hpp"

namespace facecap::formats::device {
namespace {

static_assert(std::endian::native == std::endian::little, "the device protocol is read in place: little-endian hosts");

template <typename T>
T load(const uint8_t* at) noexcept {
  T value;
  std::memcpy(&value, at, sizeof(T));
  return value;
}

template <typename T>
void store(uint8_t* at, T value) noexcept {
  std::memcpy(at, &value, sizeof(T));
}

}  // namespace

std::string_view units_name(Units units) noexcept {
  switch (units) {
    case Units::kMillimetres: return "mm";
    case Units::kCentimetres: return "cm";
    case Units::kMetres: return "m";
  }
  return "";
}

// Info block: magic(4) major(1) minor(1) capacity(2) rate_mhz(4) max_rate_mhz(4) units(1)
// capabilities(1) max_chunk_bytes(2) clock_hz(4) reserved(8).
std::array<uint8_t, kInfoBytes> encode_info(const DeviceInfo& info) noexcept {
  std::array<uint8_t, kInfoBytes> out{};
  std::memcpy(out.data(), kInfoMagic.data(), kInfoMagic.size());
  out[4] = info.version_major;
  out[5] = info.version_minor;
  store(&out[6], info.marker_capacity);
  store(&out[8], info.rate_mhz);
  store(&out[12], info.max_rate_mhz);
  out[16] = uint8_t(info.units);
  out[17] = info.capabilities;
  store(&out[18], info.max_chunk_bytes);
  store(&out[20], info.clock_hz);
  return out;
}

DeviceInfo parse_info(std::span<const uint8_t> bytes, const std::string& source) {
  if (bytes.size() < kInfoBytes)
    throw offset_error(source, int64_t(bytes.size()),
                       fmt::format("the info block has {} bytes, {} expected", bytes.size(), kInfoBytes));
  if (std::memcmp(bytes.data(), kInfoMagic.data(), kInfoMagic.size()) != 0)
    throw offset_error(source, 0, "the info block does not start with \"FCMD\": not a facecap marker device");
  DeviceInfo info;
  info.version_major = bytes[4];
  info.version_minor = bytes[5];
  if (info.version_major != kVersionMajor)
    throw offset_error(source, 4, fmt::format("protocol version {}.{}: this facecapd speaks {}.x", info.version_major,
                                              info.version_minor, kVersionMajor));
  info.marker_capacity = load<uint16_t>(&bytes[6]);
  if (info.marker_capacity == 0 || info.marker_capacity > kMaxMarkers)
    throw offset_error(source, 6, fmt::format("marker capacity {} is outside 1 to {}", info.marker_capacity, kMaxMarkers));
  info.rate_mhz = load<uint32_t>(&bytes[8]);
  info.max_rate_mhz = load<uint32_t>(&bytes[12]);
  if (bytes[16] > uint8_t(Units::kMetres))
    throw offset_error(source, 16, fmt::format("units code {} is not 0 (mm), 1 (cm) or 2 (m)", bytes[16]));
  info.units = Units(bytes[16]);
  info.capabilities = bytes[17];
  info.max_chunk_bytes = load<uint16_t>(&bytes[18]);
  if (info.max_chunk_bytes <= kChunkHeaderBytes)
    throw offset_error(source, 18, fmt::format("chunk size {} leaves no room after the {}-byte chunk header",
                                               info.max_chunk_bytes, kChunkHeaderBytes));
  info.clock_hz = load<uint32_t>(&bytes[20]);
  if (info.clock_hz == 0) throw offset_error(source, 20, "the device clock rate is 0 Hz");
  return info;
}

// Control block: command(1) reserved(3) rate_mhz(4).
std::array<uint8_t, kControlBytes> encode_control(const Control& control) noexcept {
  std::array<uint8_t, kControlBytes> out{};
  out[0] = uint8_t(control.command);
  store(&out[4], control.rate_mhz);
  return out;
}

Control parse_control(std::span<const uint8_t> bytes, const std::string& source) {
  if (bytes.size() < kControlBytes)
    throw offset_error(source, int64_t(bytes.size()),
                       fmt::format("the control block has {} bytes, {} expected", bytes.size(), kControlBytes));
  if (bytes[0] > uint8_t(Command::kStart))
    throw offset_error(source, 0, fmt::format("command {} is not 0 (stop) or 1 (start)", bytes[0]));
  return {Command(bytes[0]), load<uint32_t>(&bytes[4])};
}

uint32_t crc32(std::span<const uint8_t> bytes) noexcept {
  boost::crc_32_type crc;
  crc.process_bytes(bytes.data(), bytes.size());
  return crc.checksum();
}

std::string_view device_error_name(DeviceError error) noexcept {
  switch (error) {
    case DeviceError::kNone: return "no error";
    case DeviceError::kBadSync: return "chunk without its sync byte";
    case DeviceError::kChunkOverrun: return "chunk payload past the bytes received";
    case DeviceError::kOutOfSequence: return "chunk out of sequence (a packet was lost)";
    case DeviceError::kFrameTooLarge: return "frame larger than the device's capacity";
    case DeviceError::kShortFrame: return "frame body too short";
    case DeviceError::kBadMarkerCount: return "marker count disagrees with the frame's length or the capacity";
    case DeviceError::kBadCrc: return "bad CRC";
  }
  return "?";
}

std::string describe(const DeviceParseResult& result) {
  return fmt::format("{} at byte {}", device_error_name(result.error), result.offset);
}

// Body: frame_no(4) device_time(8) marker_count(2) flags(2), markers: id(2) flags(2) x y z
// (f32 each), then the CRC-32 of everything before it.
DeviceParseResult parse_frame_body(std::span<const uint8_t> body, std::size_t max_markers, DeviceFrame& out) noexcept {
  if (body.size() < frame_body_bytes(0)) return {DeviceError::kShortFrame, body.size()};
  const std::size_t count = load<uint16_t>(&body[12]);
  if (count > max_markers || body.size() != frame_body_bytes(count)) return {DeviceError::kBadMarkerCount, 12};
  const std::size_t crc_at = body.size() - kCrcBytes;
  if (load<uint32_t>(&body[crc_at]) != crc32(body.first(crc_at))) return {DeviceError::kBadCrc, crc_at};
  out.frame_no = load<uint32_t>(&body[0]);
  out.device_time = load<uint64_t>(&body[4]);
  out.flags = load<uint16_t>(&body[14]);
  out.markers.resize(count);  // within the reserved capacity: no allocation
  const uint8_t* at = &body[kFrameHeaderBytes];
  for (DeviceMarker& m : out.markers) {
    m.id = load<uint16_t>(at);
    m.flags = load<uint16_t>(at + 2);
    for (int c = 0; c < 3; ++c) m.position[std::size_t(c)] = load<float>(at + 4 + 4 * c);
    at += kMarkerBytes;
  }
  return {};
}

std::vector<uint8_t> encode_frame_body(const DeviceFrame& frame) {
  if (frame.markers.size() > kMaxMarkers)
    throw Error(fmt::format("a device frame holds at most {} markers, not {}", kMaxMarkers, frame.markers.size()));
  std::vector<uint8_t> body(frame_body_bytes(frame.markers.size()));
  store(&body[0], frame.frame_no);
  store(&body[4], frame.device_time);
  store(&body[12], uint16_t(frame.markers.size()));
  store(&body[14], frame.flags);
  uint8_t* at = &body[kFrameHeaderBytes];
  for (const DeviceMarker& m : frame.markers) {
    store(at, m.id);
    store(at + 2, m.flags);
    for (int c = 0; c < 3; ++c) store(at + 4 + 4 * c, m.position[std::size_t(c)]);
    at += kMarkerBytes;
  }
  const std::size_t crc_at = body.size() - kCrcBytes;
  store(&body[crc_at], crc32(std::span(body).first(crc_at)));
  return body;
}

std::vector<std::vector<uint8_t>> encode_frame_chunks(const DeviceFrame& frame, std::size_t chunk_bytes) {
  if (chunk_bytes <= kChunkHeaderBytes || chunk_bytes > kChunkHeaderBytes + 0xFFFF)
    throw Error(fmt::format("chunk size {} must be over the {}-byte header and at most {}", chunk_bytes,
                            kChunkHeaderBytes, kChunkHeaderBytes + 0xFFFF));
  const std::vector<uint8_t> body = encode_frame_body(frame);
  const std::size_t per_chunk = chunk_bytes - kChunkHeaderBytes;
  const std::size_t chunks = (body.size() + per_chunk - 1) / per_chunk;
  if (chunks > kMaxChunksPerFrame)
    throw Error(fmt::format("a frame of {} markers needs {} chunks of {} bytes; at most {} are allowed",
                            frame.markers.size(), chunks, chunk_bytes, kMaxChunksPerFrame));
  std::vector<std::vector<uint8_t>> out;
  for (std::size_t i = 0; i < chunks; ++i) {
    const std::size_t begin = i * per_chunk;
    const std::size_t payload = std::min(per_chunk, body.size() - begin);
    std::vector<uint8_t>& chunk = out.emplace_back(kChunkHeaderBytes + payload);
    chunk[0] = kChunkSync;
    chunk[1] = uint8_t((i == 0 ? kChunkFirst : 0) | (i + 1 == chunks ? kChunkLast : 0));
    store(&chunk[2], uint16_t(frame.frame_no & 0xFFFF));
    chunk[4] = uint8_t(i);
    store(&chunk[6], uint16_t(payload));
    std::memcpy(&chunk[kChunkHeaderBytes], &body[begin], payload);
  }
  return out;
}

FrameAssembler::FrameAssembler(std::size_t max_body_bytes) : buffer_(max_body_bytes) {}

// Chunk header: sync(1) flags(1) frame_tag(2) index(1) reserved(1) payload_bytes(2).
FrameAssembler::Result FrameAssembler::push(std::span<const uint8_t> bytes) noexcept {
  auto drop = [&](DeviceError error, std::size_t offset, std::size_t used) {
    reset();
    return Result{Status::kDropped, {error, offset}, used};
  };
  if (bytes.size() < kChunkHeaderBytes || bytes[0] != kChunkSync) return drop(DeviceError::kBadSync, 0, bytes.size());
  const uint8_t flags = bytes[1];
  const auto tag = load<uint16_t>(&bytes[2]);
  const uint8_t index = bytes[4];
  const std::size_t payload = load<uint16_t>(&bytes[6]);
  if (payload > bytes.size() - kChunkHeaderBytes) return drop(DeviceError::kChunkOverrun, 6, bytes.size());
  const std::size_t used = kChunkHeaderBytes + payload;

  bool abandoned = false;
  if (flags & kChunkFirst) {
    if (index != 0) return drop(DeviceError::kOutOfSequence, 4, used);
    abandoned = in_frame_;  // the frame before lost its last chunk
    size_ = 0;
    in_frame_ = true;
    frame_tag_ = tag;
  } else if (!in_frame_ || tag != frame_tag_ || index != next_index_) {
    return drop(DeviceError::kOutOfSequence, in_frame_ && tag != frame_tag_ ? 2 : 4, used);
  }
  if (payload > buffer_.size() - size_) return drop(DeviceError::kFrameTooLarge, 6, used);
  Result result{Status::kPending, {}, used, abandoned};
  std::memcpy(buffer_.data() + size_, bytes.data() + kChunkHeaderBytes, payload);
  size_ += payload;
  next_index_ = uint8_t(index + 1);
  if (flags & kChunkLast) {
    in_frame_ = false;
    result.status = Status::kComplete;
  } else if (next_index_ == 0) {
    return drop(DeviceError::kFrameTooLarge, 4, used);  // 256 chunks and no end
  }
  return result;
}

}  // namespace facecap::formats::device
