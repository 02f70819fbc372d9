#pragma once
// Live Link Face CSV (Epic's iPhone app export): blendshape weights per frame.
//
// Header `Timecode,BlendShapeCount,<61 names>` (BlendShapeCount in either
// capitalisation; columns are read by name, the app's order differs from the packet
// order). Timecode is HH:MM:SS:FF.fff on a 60 fps base (the fraction is of a frame).
// A row `timecode,0` means tracking was lost: it is kept as a frame with tracked=false
// and NaN weights and angles. Weights slightly above 1 (the app writes them) are kept.
#include <array>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "core/frame.hpp"
#include "core/time.hpp"
#include "formats/arkit.hpp"

namespace facecap::formats {

inline constexpr uint16_t kLiveLinkTimecodeRate = 60;

struct FaceFrame {
  Timecode timecode;
  int64_t source_time_ns = 0;  // timecode as time since midnight (days added past a wrap)
  bool tracked = true;
  std::array<float, kArkitShapeCount> weights{};    // kArkitShapes order
  std::array<float, kLiveLinkAngleCount> angles{};  // kLiveLinkAngleNames order, radians
};

struct FaceTake {
  double rate_hz = 0.0;  // from the timecode steps (30 or 60 in practice), 0 with < 2 frames
  std::vector<FaceFrame> frames;
  std::vector<std::string> warnings;

  std::size_t lost_frames() const noexcept;
};

// Parses the CSV text; `name` labels errors ("name:line:column: what"). Throws Error.
FaceTake read_livelinkface(std::string_view text, const std::string& name);
FaceTake read_livelinkface(const std::filesystem::path& path);

// Writes the app's layout (its column order, 10 decimals, lost rows as `timecode,0`).
std::string write_livelinkface(const FaceTake& take);

// "HH:MM:SS:FF.fff" <-> Timecode at kLiveLinkTimecodeRate.
std::optional<Timecode> parse_livelink_timecode(std::string_view text) noexcept;
std::string format_livelink_timecode(const Timecode& timecode);

// The Live Link timecode of a time of day (ns; wraps at 24 h), rounded to the nearest
// thousandth of a 60 fps frame as the CSV writes it, so a frame a hair before a frame
// boundary is that frame (.000), not the one before (.999). Frames of a take up to
// 60 Hz each get their own HH:MM:SS:FF.
Timecode livelink_timecode_at(int64_t time_of_day_ns) noexcept;
// A timecode at any rate as time of day in ns (frames and subframe at tc.rate_hz).
int64_t timecode_time_ns(const Timecode& timecode) noexcept;

// One CSV row from a solved frame: the ARKit weights as `arkit` maps them, head yaw, pitch
// and roll (head_yaw_pitch_roll; eyes 0), the frame's timecode re-based to 60 fps, or its
// source time when it has none. The same values the Live Link output sends.
FaceFrame face_frame_from_solved(const SolvedFrame& solved, const ArkitWeights& arkit);

}  // namespace facecap::formats
