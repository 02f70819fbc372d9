#pragma once
// What synth, bench and eval share: weight curves driving a rig, units, the ground-truth
// pose, solver selection and order statistics. Nothing here is real-time.
#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include "formats/livelinkface.hpp"
#include "formats/recording.hpp"
#include "solver/face_solver.hpp"
#include "solver/rig.hpp"

namespace facecap::tools {

// Weights over time, one M-vector per frame in the rig's shape order.
struct WeightCurves {
  std::vector<Eigen::VectorXd> frames;
  double rate_hz = 0.0;
  std::string source;                       // "builtin motion" or the CSV's path
  std::vector<std::string> driven_shapes;   // rig shapes the source moves
  std::vector<std::string> unmatched;       // source channels the rig has no shape for
  std::size_t held_frames = 0;              // untracked CSV rows that repeat the last tracked weights
};

// A Live Link Face CSV mapped onto the rig by ARKit name (JawOpen -> jawOpen, split
// shapes to both halves), weights clamped to [0, 1], untracked rows holding the last
// tracked weights, resampled linearly at rate_hz (<= 0: the CSV's own rate). At most
// max_frames frames (< 0: every frame the CSV covers). Throws Error.
WeightCurves livelinkface_curves(const std::filesystem::path& csv, const Rig& rig, double rate_hz, long max_frames);

// BuiltinFace::motion_weights (jaw, blinks, smiles, brows, lips) sampled at rate_hz and
// mapped onto the rig by shape name, max_frames frames. Throws Error when the rig has
// none of the built-in shape names.
WeightCurves builtin_motion_curves(const Rig& rig, double rate_hz, long max_frames);

// The rig's length unit: `override_units` when given, else guess_face_units(). Throws
// Error when neither names mm, cm or m.
std::string rig_units(const Rig& rig, const std::string& override_units);

// Whether this is the built-in face (by content: hashes the rig, so ask once).
bool is_builtin_face(const Rig& rig);

// The pose a weight vector really produces: BuiltinFace::articulated_pose for the
// built-in face (builtin = is_builtin_face(rig)), the linear blend x0 + B w for any
// other rig. 3 x N.
Eigen::Matrix3Xd truth_pose(const Rig& rig, bool builtin, const Eigen::VectorXd& weights);

// Marker points (3 x K) of a pose (3 x N).
Eigen::Matrix3Xd marker_positions(const Eigen::Matrix3Xd& pose, const std::vector<MarkerBinding>& markers);

// "all" (every kSolverMethods row) or a comma-separated list of their names, in the
// order given, each once. Throws Error naming an unknown solver and the allowed names.
std::vector<SolverMethod> select_solvers(const std::string& option);

// The i-th solved frame of a recording, refused (Error naming the file and frame) when
// its weights do not match the header's shapes.
void read_solved_frame_checked(const formats::RecordingReader& reader, std::size_t i, SolvedFrame& out);

// Writes solved weights as a Live Link Face CSV (atomically). Above 60 Hz rows share the
// CSV's 60 fps timecode frames: says so on stderr.
void write_live_link_csv(const std::filesystem::path& path, const formats::FaceTake& face);

// Nearest-rank percentile p (0..100) of values; reorders them. 0 for no values.
double percentile(std::vector<double>& values, double p);

}  // namespace facecap::tools
