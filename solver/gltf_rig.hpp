#pragma once
// glTF 2.0 rigs: one mesh whose primitives carry named morph targets
// (mesh.extras.targetNames, the convention of Blender and most exporters).
#include <string>

#include "solver/rig.hpp"

namespace facecap {

// Throws Error naming the file and the glTF path (meshes[i].primitives[j]...).
Rig load_gltf_rig(const std::string& path);

// Writes the rig as a .gltf (embedded buffer) or .glb with float positions.
void save_gltf_rig(const Rig& rig, const std::string& path);

}  // namespace facecap
