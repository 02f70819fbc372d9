#pragma once
// FBX rigs, read with assimp (Debian's libassimp-dev): a mesh and its blendshape
// channels. assimp gives one vertex per face corner (it splits at every UV and normal
// seam); the loader welds them back into the artist's vertices.
#include <cstddef>
#include <filesystem>
#include <span>
#include <string>
#include <vector>

#include "solver/rig.hpp"

namespace facecap {

// What an FBX file holds, for `facecap inspect-rig`.
struct FbxContents {
  struct Mesh {
    std::string name;
    std::size_t vertices = 0;  // as assimp delivers them (split at seams)
    std::size_t faces = 0;
    std::size_t channels = 0;  // blendshape channels
  };
  std::vector<Mesh> meshes;
  std::size_t rig_mesh = 0;              // which of meshes became the rig
  std::size_t vertices_before_weld = 0;  // the rig mesh's, as assimp delivers them
  std::size_t vertices_after_weld = 0;
};

// Whether load_rig reads this path as FBX (.fbx, any case).
bool is_fbx_path(const std::filesystem::path& path);

// The rig of the first mesh that has blendshape channels: its vertices in the node's
// coordinates (the file's units, not rescaled), faces fan-triangulated as the OBJ reader
// does, each channel a shape named by the channel. Corners are welded into one vertex
// when they share the position in the neutral and in every shape: the welded vertices
// keep the order of their first corner, and Rig::file_vertex_of maps every corner back.
// Throws Error naming the file and what is wrong (not an FBX assimp reads, no mesh with
// channels, a channel whose vertex count differs, duplicate channel names, NaN).
Rig load_fbx_rig(const std::string& path, FbxContents* contents = nullptr);
// The same from bytes in memory (fuzzing); `name` labels errors.
Rig parse_fbx_rig(std::span<const char> bytes, const std::string& name, FbxContents* contents = nullptr);

}  // namespace facecap
