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

#include <Eigen/Geometry>

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

// For each rig shape, its ARKit name ("EyeBlinkLeft" for eyeBlink_L), or "" when ARKit has
// no shape of that name (the ICT face's browInnerUp_L is half of BrowInnerUp).
std::vector<std::string> arkit_names_of(std::span<const std::string> rig_shape_names);

// The mean of the weights of `shapes` (indices into rig_weights), 0 for none: one value
// from the rig shapes that realise it. RT-safe.
float mean_weight(std::span<const std::size_t> shapes, std::span<const float> rig_weights) noexcept;

// The 52 ARKit weights of a solved frame: per ARKit shape, the mean of the rig weights
// that realise it (match_arkit_to_rig), 0 for a shape the rig lacks. What facecap solve
// writes to Live Link Face CSV and the Live Link and VMC outputs send.
class ArkitWeights {
 public:
  // Not RT-safe.
  explicit ArkitWeights(std::span<const std::string> rig_shape_names);
  // From an explicit binding: per ARKit shape, the rig shapes that realise it (a name map).
  explicit ArkitWeights(std::array<std::vector<std::size_t>, kArkitShapeCount> binding) : binding_(std::move(binding)) {}
  // out[a] for ARKit shape a (kArkitShapes order) from the rig's weights (rig shape
  // order, as many as the rig has shapes). RT-safe.
  void map(std::span<const float> rig_weights, std::span<float, kArkitShapeCount> out) const noexcept;
  float weight(std::size_t arkit_index, std::span<const float> rig_weights) const noexcept;
  // How many of the 52 the rig realises.
  std::size_t realised() const noexcept;

 private:
  std::array<std::vector<std::size_t>, kArkitShapeCount> binding_;
};

// The head's yaw (about the rig's Y axis, up), pitch (about X) and roll (about Z, the
// direction the face looks), in radians, of R = Ry(yaw) Rx(pitch) Rz(roll): the first
// three of kLiveLinkAngleNames. Pitch is within [-pi/2, pi/2]. RT-safe.
std::array<float, 3> head_yaw_pitch_roll(const Eigen::Quaterniond& head_rotation) noexcept;

}  // namespace facecap::formats
