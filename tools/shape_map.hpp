#pragma once
// A map from a rig's shape names to ARKit names, for writing a Live Link Face CSV from a
// rig named otherwise (`facecap export --map names.toml`; examples in config/shape-maps/):
//   # rig shape = ARKit name (PascalCase as Live Link writes it, or Apple's camelCase)
//   "Jaw_Open" = "JawOpen"
//   "Blink_L"  = "EyeBlinkLeft"
// Several rig shapes may name one ARKit shape (their mean is written, as for the ICT
// face's split browInnerUp_L and _R). Not real-time code.
#include <array>
#include <filesystem>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "formats/arkit.hpp"

namespace facecap::tools {

struct ShapeMapEntry {
  std::string rig_shape;
  std::size_t arkit_index = 0;  // into formats::kArkitShapes
  int64_t line = -1;            // where the entry is, for errors about it
  int64_t column = -1;
};

struct ShapeMap {
  std::string file;  // names it in errors
  std::vector<ShapeMapEntry> entries;
};

// Parses a map's text; `name` labels errors. Throws Error at file:line:col naming the key
// for a value that is not a string or not an ARKit name (with the closest ARKit name).
ShapeMap parse_shape_map(std::string_view text, const std::string& name);
ShapeMap read_shape_map(const std::filesystem::path& path);

// Per ARKit shape, the rig shapes (indices into rig_shape_names) the map binds to it.
// Throws Error at the entry's file:line:col for a rig shape the rig does not have.
std::array<std::vector<std::size_t>, formats::kArkitShapeCount> bind_shape_map(
    const ShapeMap& map, std::span<const std::string> rig_shape_names);

}  // namespace facecap::tools
