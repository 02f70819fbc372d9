#pragma once
// A solved take as glTF 2.0 (`facecap export take.fcrec out.glb|out.gltf`): the rig's
// neutral mesh and morph targets (names in mesh.extras.targetNames) on one node, "head",
// animated by the take: one key per frame at the frames' times for the morph weights, the
// head's rotation and translation. Lengths in metres, as glTF defines them. Not real-time.
#include <filesystem>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "solver/rig.hpp"

namespace facecap::tools {

struct GltfTake {
  std::vector<std::string> shape_names;  // M
  std::vector<float> times_s;            // per frame, from the first, strictly increasing
  std::vector<float> weights;            // frames x M, frame by frame
  std::vector<Eigen::Quaternionf> head_rotation;   // per frame, head in world
  std::vector<Eigen::Vector3f> head_translation;  // per frame, rig units
  std::vector<std::pair<std::string, std::string>> extras;  // take, actor, timecode, ... (empty values left out)
};

// Writes take onto rig (its neutral and deltas; its shape names must be take.shape_names),
// or with rig == nullptr a file without geometry for an engine that has the rig: the
// mesh is one point with zero-length targets, so the file stays valid glTF (a weights
// channel must target a mesh with as many targets) and keeps the names. metres_per_unit
// scales the rig units. Throws Error naming the file on failure.
void write_gltf_take(const std::filesystem::path& path, const GltfTake& take, const Rig* rig, double metres_per_unit);

}  // namespace facecap::tools
