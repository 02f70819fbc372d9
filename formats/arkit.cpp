#include "formats/arkit.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>

namespace facecap::formats {

const std::array<ArkitShapeName, kArkitShapeCount> kArkitShapes = {{
    {"EyeBlinkLeft", "eyeBlink_L"},
    {"EyeLookDownLeft", "eyeLookDown_L"},
    {"EyeLookInLeft", "eyeLookIn_L"},
    {"EyeLookOutLeft", "eyeLookOut_L"},
    {"EyeLookUpLeft", "eyeLookUp_L"},
    {"EyeSquintLeft", "eyeSquint_L"},
    {"EyeWideLeft", "eyeWide_L"},
    {"EyeBlinkRight", "eyeBlink_R"},
    {"EyeLookDownRight", "eyeLookDown_R"},
    {"EyeLookInRight", "eyeLookIn_R"},
    {"EyeLookOutRight", "eyeLookOut_R"},
    {"EyeLookUpRight", "eyeLookUp_R"},
    {"EyeSquintRight", "eyeSquint_R"},
    {"EyeWideRight", "eyeWide_R"},
    {"JawForward", "jawForward"},
    {"JawLeft", "jawLeft"},
    {"JawRight", "jawRight"},
    {"JawOpen", "jawOpen"},
    {"MouthClose", "mouthClose"},
    {"MouthFunnel", "mouthFunnel"},
    {"MouthPucker", "mouthPucker"},
    {"MouthLeft", "mouthLeft"},
    {"MouthRight", "mouthRight"},
    {"MouthSmileLeft", "mouthSmile_L"},
    {"MouthSmileRight", "mouthSmile_R"},
    {"MouthFrownLeft", "mouthFrown_L"},
    {"MouthFrownRight", "mouthFrown_R"},
    {"MouthDimpleLeft", "mouthDimple_L"},
    {"MouthDimpleRight", "mouthDimple_R"},
    {"MouthStretchLeft", "mouthStretch_L"},
    {"MouthStretchRight", "mouthStretch_R"},
    {"MouthRollLower", "mouthRollLower"},
    {"MouthRollUpper", "mouthRollUpper"},
    {"MouthShrugLower", "mouthShrugLower"},
    {"MouthShrugUpper", "mouthShrugUpper"},
    {"MouthPressLeft", "mouthPress_L"},
    {"MouthPressRight", "mouthPress_R"},
    {"MouthLowerDownLeft", "mouthLowerDown_L"},
    {"MouthLowerDownRight", "mouthLowerDown_R"},
    {"MouthUpperUpLeft", "mouthUpperUp_L"},
    {"MouthUpperUpRight", "mouthUpperUp_R"},
    {"BrowDownLeft", "browDown_L"},
    {"BrowDownRight", "browDown_R"},
    {"BrowInnerUp", "browInnerUp"},
    {"BrowOuterUpLeft", "browOuterUp_L"},
    {"BrowOuterUpRight", "browOuterUp_R"},
    {"CheekPuff", "cheekPuff"},
    {"CheekSquintLeft", "cheekSquint_L"},
    {"CheekSquintRight", "cheekSquint_R"},
    {"NoseSneerLeft", "noseSneer_L"},
    {"NoseSneerRight", "noseSneer_R"},
    {"TongueOut", "tongueOut"},
}};

namespace {

// ARKit names differ from Apple's camelCase only in the first letter.
bool equal_but_first_case(std::string_view a, std::string_view b) {
  return !a.empty() && a.size() == b.size() && std::tolower(uint8_t(a[0])) == std::tolower(uint8_t(b[0])) &&
         a.substr(1) == b.substr(1);
}

}  // namespace

std::optional<std::size_t> arkit_shape_index(std::string_view arkit_name) noexcept {
  for (std::size_t i = 0; i < kArkitShapes.size(); ++i) {
    if (equal_but_first_case(kArkitShapes[i].arkit, arkit_name)) return i;
  }
  return std::nullopt;
}

std::optional<std::string_view> arkit_to_rig_name(std::string_view arkit_name) noexcept {
  if (auto i = arkit_shape_index(arkit_name)) return kArkitShapes[*i].rig;
  return std::nullopt;
}

std::optional<std::string_view> rig_to_arkit_name(std::string_view rig_name) noexcept {
  for (const auto& shape : kArkitShapes) {
    if (shape.rig == rig_name) return shape.arkit;
  }
  return std::nullopt;
}

std::array<std::vector<std::size_t>, kArkitShapeCount> match_arkit_to_rig(
    std::span<const std::string> rig_shape_names) {
  std::array<std::vector<std::size_t>, kArkitShapeCount> out;
  auto find = [&](std::string_view name) -> std::optional<std::size_t> {
    for (std::size_t i = 0; i < rig_shape_names.size(); ++i) {
      if (rig_shape_names[i] == name) return i;
    }
    return std::nullopt;
  };
  for (std::size_t s = 0; s < kArkitShapeCount; ++s) {
    const std::string rig(kArkitShapes[s].rig);
    if (auto i = find(rig)) {
      out[s].push_back(*i);
      continue;
    }
    for (const char* side : {"_L", "_R"}) {
      if (auto i = find(rig + side)) out[s].push_back(*i);
    }
  }
  return out;
}

std::vector<std::string> arkit_names_of(std::span<const std::string> rig_shape_names) {
  std::vector<std::string> out;
  out.reserve(rig_shape_names.size());
  for (const std::string& name : rig_shape_names) out.emplace_back(rig_to_arkit_name(name).value_or(""));
  return out;
}

ArkitWeights::ArkitWeights(std::span<const std::string> rig_shape_names) : binding_(match_arkit_to_rig(rig_shape_names)) {}

float mean_weight(std::span<const std::size_t> shapes, std::span<const float> rig_weights) noexcept {
  if (shapes.empty()) return 0.0f;
  double sum = 0.0;
  for (const std::size_t s : shapes) sum += s < rig_weights.size() ? double(rig_weights[s]) : 0.0;
  return float(sum / double(shapes.size()));
}

float ArkitWeights::weight(std::size_t arkit_index, std::span<const float> rig_weights) const noexcept {
  return mean_weight(binding_[arkit_index], rig_weights);
}

void ArkitWeights::map(std::span<const float> rig_weights, std::span<float, kArkitShapeCount> out) const noexcept {
  for (std::size_t a = 0; a < kArkitShapeCount; ++a) out[a] = weight(a, rig_weights);
}

std::size_t ArkitWeights::realised() const noexcept {
  std::size_t n = 0;
  for (const auto& shapes : binding_) n += shapes.empty() ? 0 : 1;
  return n;
}

std::array<float, 3> head_yaw_pitch_roll(const Eigen::Quaterniond& head_rotation) noexcept {
  // R = Ry Rx Rz has R(1,2) = -sin(pitch), R(0,2) / R(2,2) = tan(yaw), R(1,0) / R(1,1) = tan(roll).
  const Eigen::Matrix3d r = head_rotation.normalized().toRotationMatrix();
  const double pitch = std::asin(std::clamp(-r(1, 2), -1.0, 1.0));
  return {float(std::atan2(r(0, 2), r(2, 2))), float(pitch), float(std::atan2(r(1, 0), r(1, 1)))};
}

}  // namespace facecap::formats
