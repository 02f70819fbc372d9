#pragma once
// Unreal Live Link Face packets, version 6: what Epic's Live Link Face iPhone app sends to
// Unreal over UDP (port 11111), big-endian:
//
//   u8 version (6) | i32 n, n bytes: device id | i32 n, n bytes: subject name |
//   i32 frame number | f32 subframe | i32 fps numerator | i32 fps denominator |
//   u8 value count (61) | 61 x f32
//
// 270 bytes plus the two strings. The values are the 52 ARKit weights in Epic's order
// (kArkitShapes), then head yaw, pitch, roll and each eye's yaw, pitch, roll in radians
// (kLiveLinkAngleNames). Unreal drops a packet whose version is not 6 or whose count is
// not 61. docs/outputs.md has the layout with offsets.
#include <array>
#include <cstddef>
#include <cstdint>
#include <string_view>
#include <vector>

#include "core/time.hpp"
#include "formats/arkit.hpp"

namespace facecap::formats::livelink {

inline constexpr uint8_t kPacketVersion = 6;
inline constexpr std::size_t kValueCount = kArkitShapeCount + kLiveLinkAngleCount;  // 61
// Bytes of a packet besides its device id and subject name.
inline constexpr std::size_t kFixedBytes = 1 + 4 + 4 + 4 + 4 + 4 + 4 + 1 + kValueCount * 4;
static_assert(kFixedBytes == 270);
// The iPhone app sends a UUID ("8-4-4-4-12" hex digits) as its device id; some receivers
// assume that length.
inline constexpr std::size_t kDeviceIdLength = 36;

// One frame's time and values. The time is a frame of the timecode at fps_numerator /
// fps_denominator frames a second (Unreal's FQualifiedFrameTime).
struct LiveLinkFrame {
  int32_t frame_number = 0;
  float subframe = 0.0f;  // 0 to 1, the fraction of a frame
  int32_t fps_numerator = 60;
  int32_t fps_denominator = 1;
  std::array<float, kValueCount> values{};
};

// Bytes of a packet with this device id and subject name.
constexpr std::size_t packet_size(std::string_view device_id, std::string_view subject) noexcept {
  return kFixedBytes + device_id.size() + subject.size();
}

// Replaces `out` with the packet. Not RT-safe when `out` must grow; throws Error when a
// string is longer than a packet can carry (more than 1,024 bytes).
void encode_packet(std::string_view device_id, std::string_view subject, const LiveLinkFrame& frame,
                   std::vector<char>& out);

// A frame's Live Link time: the source timecode as frames since midnight at its rate
// (subframe from the timecode's), or, without a timecode, source_time_ns counted in frames
// of fallback_rate_hz. RT-safe.
void set_frame_time(const Timecode& timecode, int64_t source_time_ns, double fallback_rate_hz,
                    LiveLinkFrame& frame) noexcept;

// A UUID-shaped device id (36 characters, upper-case hex) that is a pure function of
// `seed`: stable for as long as what it is made from. RT-safe.
std::array<char, kDeviceIdLength> device_id_from(std::string_view seed) noexcept;

}  // namespace facecap::formats::livelink
