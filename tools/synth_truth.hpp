#pragma once
// The ground truth `facecap synth` writes beside a take and `facecap eval` reads
// (formats: docs/tools.md):
//   <stem>.truth.json      manifest: rig, units, seed, markers (label -> vertex), files
//   <stem>.truth.csv       per frame: time, head pose, every rig weight
//   <stem>.truth.vertices  built-in rig only: articulated vertices per frame (float32)
// Not real-time; every reader throws Error naming the file and what is wrong.
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <Eigen/Core>

namespace facecap::tools {

inline constexpr int kSynthTruthVersion = 1;

struct SynthTruth {
  std::string rig;            // the --rig the take was made from
  std::string rig_name;
  std::string rig_hash;       // Rig::content_hash() as 16 hex digits
  std::string rig_units;      // "mm", "cm" or "m"
  std::string take_file;      // file name of the take, beside the manifest
  std::string take_units;
  double rate_hz = 0.0;
  uint64_t seed = 0;
  double noise_mm = 0.0;
  double dropout = 0.0;
  bool head_motion = false;
  std::string weights_source;  // "builtin motion" or the CSV path
  std::vector<std::string> marker_labels;  // K
  std::vector<int> marker_vertices;        // K, the vertex each marker sits on
  std::vector<std::string> shape_names;    // M, the weights' order
  // Per frame: weights (M), and the head pose that took rig space to the take's space:
  // p_take = s (R(head_rotation) p_rig + head_translation), s = rig-to-take unit scale,
  // head_rotation a rotation vector (radians), head_translation in rig units.
  std::vector<Eigen::VectorXd> weights;
  std::vector<Eigen::Vector3d> head_rotation, head_translation;
  std::string weights_file;   // file names beside the manifest
  std::string vertices_file;  // empty when there are no truth vertices

  std::size_t frame_count() const { return weights.size(); }
};

// Writes the manifest and the weights CSV (paths from the manifest's directory and
// truth.weights_file). Throws Error.
void write_synth_truth(const std::filesystem::path& manifest, const SynthTruth& truth);
SynthTruth read_synth_truth(const std::filesystem::path& manifest);

// <stem>.truth.vertices: a 32-byte header ("FCTRUTHV", u32 version 1, u32 vertex count N,
// u32 frame count F, u32 bytes per value 4, u64 reserved 0), then F frames of N x,y,z
// float32, all little-endian, in rig units and rig space (no head motion).
class TruthVerticesWriter {
 public:
  TruthVerticesWriter(const std::filesystem::path& path, int64_t vertex_count, int64_t frame_count);
  void append(const Eigen::Matrix3Xd& vertices);
  void close();  // throws unless exactly frame_count frames were appended

 private:
  std::filesystem::path path_;
  std::ofstream out_;
  int64_t vertex_count_, frame_count_, written_ = 0;
  std::vector<float> buffer_;
};

class TruthVerticesReader {
 public:
  explicit TruthVerticesReader(const std::filesystem::path& path);
  int64_t vertex_count() const { return vertex_count_; }
  int64_t frame_count() const { return frame_count_; }
  // Frame f (0-based) into out (3 x N).
  void read(int64_t frame, Eigen::Matrix3Xd& out);

 private:
  std::filesystem::path path_;
  std::ifstream in_;
  int64_t vertex_count_ = 0, frame_count_ = 0;
  std::vector<float> buffer_;
};

}  // namespace facecap::tools
