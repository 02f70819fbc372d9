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

}  // namespace facecap::formats
