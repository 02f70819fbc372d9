#pragma once
// glTF 2.0 rigs: one mesh whose primitives carry named morph targets
// (mesh.extras.targetNames, the convention of Blender and most exporters).
#include <filesystem>
#include <span>
#include <string>

#include "solver/rig.hpp"

namespace facecap {

// Throws Error naming the file and the glTF path (meshes[i].primitives[j]...).
Rig load_gltf_rig(const std::string& path);
// The same from bytes in memory (`binary`: GLB, else JSON); `name` labels errors. External
// buffers (uri = "face.bin") are read from base_dir, and refused when it is empty.
// Images are never decoded.
Rig parse_gltf_rig(std::span<const char> bytes, const std::string& name, bool binary,
                   const std::filesystem::path& base_dir = {});

// Writes the rig as a .gltf (embedded buffer) or .glb with float positions.
void save_gltf_rig(const Rig& rig, const std::string& path);

}  // namespace facecap
