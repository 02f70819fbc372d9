#pragma once
// The 52 ARKit face blendshapes, and the map between their names and rig shape names
// (ICT FaceKit style: `JawOpen` <-> `jawOpen`, `EyeBlinkLeft` <-> `eyeBlink_L`).
#include <array>
#include <cstddef>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace facecap::formats {

inline constexpr std::size_t kArkitShapeCount = 52;

struct ArkitShapeName {
  std::string_view arkit;  // PascalCase, as Live Link Face writes it
  std::string_view rig;    // the rig's shape (ICT FaceKit file name without .obj)
};

// In Epic's Live Link order (the order of the 61 values in a Live Link Face packet).
extern const std::array<ArkitShapeName, kArkitShapeCount> kArkitShapes;

// The nine angles (radians) that follow the weights in Live Link Face data.
inline constexpr std::size_t kLiveLinkAngleCount = 9;
inline constexpr std::array<std::string_view, kLiveLinkAngleCount> kLiveLinkAngleNames = {
    "HeadYaw",     "HeadPitch",   "HeadRoll",      "LeftEyeYaw",  "LeftEyePitch",
    "LeftEyeRoll", "RightEyeYaw", "RightEyePitch", "RightEyeRoll"};

// Index in kArkitShapes of an ARKit name, in Live Link's PascalCase ("JawOpen") or
// Apple's camelCase ("jawOpen" is also the rig name, so both spellings resolve).
std::optional<std::size_t> arkit_shape_index(std::string_view arkit_name) noexcept;

// "EyeBlinkLeft" -> "eyeBlink_L"; nullopt for a name that is not an ARKit shape.
std::optional<std::string_view> arkit_to_rig_name(std::string_view arkit_name) noexcept;
// "eyeBlink_L" -> "EyeBlinkLeft"; nullopt for a rig shape ARKit lacks.
std::optional<std::string_view> rig_to_arkit_name(std::string_view rig_name) noexcept;

// For each ARKit shape, the rig shapes (indices into rig_shape_names) that realise it:
// the shape of the same rig name, else its _L and _R halves (the ICT face splits
// browInnerUp and cheekPuff). Empty when the rig has neither (ICT lacks tongueOut).
std::array<std::vector<std::size_t>, kArkitShapeCount> match_arkit_to_rig(std::span<const std::string> rig_shape_names);

}  // namespace facecap::formats
