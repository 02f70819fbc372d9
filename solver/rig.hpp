#pragma once
// A blendshape rig: neutral mesh x0 (N vertices, T triangles) and M shapes stored as
// deltas B = [b_i - x0]. Loaded from OBJ sets, a TOML manifest, glTF morph targets, FBX
// blendshape channels, the binary cache, or generated (the built-in face). Loading is never real-time.
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>

namespace facecap {

struct Rig {
  std::string name;                      // "builtin", directory or file stem
  std::string source;                    // what it was loaded from
  Eigen::Matrix3Xd neutral;              // 3 x N, rig units
  Eigen::Matrix3Xi triangles;            // 3 x T, vertex indices into neutral
  std::vector<std::string> shape_names;  // M, unique
  Eigen::MatrixXd deltas;                // 3N x M; row 3v+k is coordinate k of vertex v
  // Its shapes swing parts about hinges, as a real jaw does (the built-in face, built by
  // rotation), rather than being an artist's linear blend: the solver's kByRig settings
  // follow (SolverParams).
  bool hinged = false;
  // For a rig read from a file that splits vertices at UV and normal seams (FBX through
  // assimp): per vertex of that file's mesh, in its order, the rig vertex it was welded
  // into. Empty when the rig's vertices are the file's.
  std::vector<int> file_vertex_of;

  Eigen::Index vertex_count() const { return neutral.cols(); }
  Eigen::Index triangle_count() const { return triangles.cols(); }
  Eigen::Index shape_count() const { return deltas.cols(); }
  std::optional<Eigen::Index> shape_index(const std::string& name) const;

  // x0 + B w as 3 x N. weights: M.
  Eigen::Matrix3Xd linear_blend(const Eigen::VectorXd& weights) const;
  // Neutral plus one full shape, as 3 x N.
  Eigen::Matrix3Xd shape_positions(Eigen::Index shape) const;

  // Identity of the geometry (vertices, triangles, names, deltas); stable across runs.
  uint64_t content_hash() const;
};

struct BoundingBox {
  Eigen::Vector3d min = Eigen::Vector3d::Zero();
  Eigen::Vector3d max = Eigen::Vector3d::Zero();
  Eigen::Vector3d size() const { return max - min; }
};
BoundingBox bounding_box(const Eigen::Matrix3Xd& points);

// "mm", "cm" or "m" from the size of a human face (about 15-25 cm tall), or "unknown".
std::string guess_face_units(const BoundingBox& box);

// Rig units per millimetre from the face's size (0.1 for a rig in cm); 0.1 when the size
// fits no unit.
double rig_units_per_mm(const Rig& rig);

// Per-shape maximum vertex displacement, in rig units. M.
Eigen::VectorXd max_shape_displacement(const Rig& rig);

struct RigLoadOptions {
  bool use_cache = true;                       // read and write the binary cache
  std::optional<std::filesystem::path> cache_dir;  // default: user_cache_dir()/rigs
};

struct RigLoadReport {
  bool from_cache = false;
  std::filesystem::path cache_file;  // empty when caching is off or failed
  double seconds = 0.0;
};

// A rig manifest (rig.toml):
//   name = "actor"            # optional
//   hinged = true             # optional: its shapes swing about hinges (Rig::hinged)
//   neutral = "neutral.obj"
//   [shapes]
//   jawOpen = "jaw_open.obj"  # one OBJ per shape, in file order
// Paths are relative to the manifest's directory.
struct RigShapeFile {
  std::string name;
  std::filesystem::path path;
};
struct RigManifest {
  std::string name;
  bool hinged = false;
  std::filesystem::path neutral;
  std::vector<RigShapeFile> shapes;
};
// Parses a manifest's text; `manifest` names it in errors and anchors relative paths.
// Throws Error with file:line:col and the key.
RigManifest parse_rig_manifest(std::string_view text, const std::filesystem::path& manifest);

// Loads "builtin", an OBJ directory (ICT layout or with rig.toml), a .toml manifest,
// a .gltf/.glb or an .fbx file. Throws Error naming the file and line on malformed input.
Rig load_rig(const std::string& spec, const RigLoadOptions& options = {},
             RigLoadReport* report = nullptr);

}  // namespace facecap
