#include "formats/livelink_packet.hpp"

#include <cmath>

#include <fmt/format.h>

#include "core/error.hpp"
#include "formats/byte_io.hpp"

namespace facecap::formats::livelink {
namespace {

constexpr std::size_t kMaxStringBytes = 1024;

// FNV-1a, 64 bits, from a chosen offset basis.
uint64_t fnv1a(std::string_view text, uint64_t basis) noexcept {
  uint64_t h = basis;
  for (const char c : text) {
    h ^= uint8_t(c);
    h *= 0x100000001b3ull;
  }
  return h;
}

}  // namespace

void encode_packet(std::string_view device_id, std::string_view subject, const LiveLinkFrame& frame,
                   std::vector<char>& out) {
  if (device_id.size() > kMaxStringBytes || subject.size() > kMaxStringBytes)
    throw Error(fmt::format("Live Link: a device id or subject name of {} bytes is longer than {}",
                            std::max(device_id.size(), subject.size()), kMaxStringBytes));
  out.clear();
  out.reserve(packet_size(device_id, subject));
  ByteWriter w(out, ByteOrder::kBig);
  w.u8(kPacketVersion);
  w.i32(int32_t(device_id.size()));
  w.bytes(device_id);
  w.i32(int32_t(subject.size()));
  w.bytes(subject);
  w.i32(frame.frame_number);
  w.f32(frame.subframe);
  w.i32(frame.fps_numerator);
  w.i32(frame.fps_denominator);
  w.u8(uint8_t(kValueCount));
  for (const float v : frame.values) w.f32(v);
}

void set_frame_time(const Timecode& timecode, int64_t source_time_ns, double fallback_rate_hz,
                    LiveLinkFrame& frame) noexcept {
  if (timecode.valid()) {
    const int64_t seconds = int64_t(timecode.hours) * 3600 + int64_t(timecode.minutes) * 60 + timecode.seconds;
    frame.frame_number = int32_t(seconds * timecode.rate_hz + timecode.frames);
    frame.subframe = timecode.subframe;
    frame.fps_numerator = timecode.rate_hz;
    frame.fps_denominator = 1;
    return;
  }
  // A whole rate as n/1, a fractional one (59.94) as n/1000.
  const double rate = fallback_rate_hz > 0.0 ? fallback_rate_hz : 60.0;
  const bool whole = std::abs(rate - std::round(rate)) < 1e-6;
  frame.fps_numerator = whole ? int32_t(std::lround(rate)) : int32_t(std::lround(rate * 1000.0));
  frame.fps_denominator = whole ? 1 : 1000;
  const double frames = double(source_time_ns) / double(kNsPerSecond) * rate;
  const double whole_frames = std::floor(frames);
  frame.frame_number = int32_t(int64_t(whole_frames) % (int64_t(24) * 3600 * int64_t(std::ceil(rate))));
  frame.subframe = float(frames - whole_frames);
}

std::array<char, kDeviceIdLength> device_id_from(std::string_view seed) noexcept {
  const uint64_t high = fnv1a(seed, 0xcbf29ce484222325ull);
  const uint64_t low = fnv1a(seed, 0x84222325cbf29ce4ull);
  uint8_t bytes[16];
  for (int i = 0; i < 8; ++i) {
    bytes[i] = uint8_t(high >> (56 - 8 * i));
    bytes[8 + i] = uint8_t(low >> (56 - 8 * i));
  }
  bytes[6] = uint8_t((bytes[6] & 0x0f) | 0x80);  // version 8: made by its own rule (RFC 9562)
  bytes[8] = uint8_t((bytes[8] & 0x3f) | 0x80);  // the RFC variant
  static constexpr char kHex[] = "0123456789ABCDEF";
  std::array<char, kDeviceIdLength> id{};
  std::size_t at = 0;
  for (int i = 0; i < 16; ++i) {
    if (i == 4 || i == 6 || i == 8 || i == 10) id[at++] = '-';
    id[at++] = kHex[bytes[i] >> 4];
    id[at++] = kHex[bytes[i] & 0x0f];
  }
  return id;
}

}  // namespace facecap::formats::livelink
