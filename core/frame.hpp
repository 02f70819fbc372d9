#pragma once
// The two frames that flow through facecap: raw markers in, solved face out.
// Both are sized once (configure) and then copied into pre-reserved storage, so the
// real-time loop never allocates when it moves them.
#include <array>
#include <cstdint>
#include <cstring>
#include <limits>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "core/time.hpp"

namespace facecap {

// Fixed-size label so that copying a marker never allocates.
struct MarkerLabel {
  static constexpr std::size_t kCapacity = 47;
  std::array<char, kCapacity + 1> text{};

  MarkerLabel() = default;
  MarkerLabel(std::string_view s) { assign(s); }  // NOLINT: implicit from text on purpose
  void assign(std::string_view s) noexcept {
    const std::size_t n = s.size() < kCapacity ? s.size() : kCapacity;
    std::memcpy(text.data(), s.data(), n);
    text[n] = '\0';
    for (std::size_t i = n + 1; i < text.size(); ++i) text[i] = '\0';
  }
  std::string_view view() const noexcept { return std::string_view(text.data()); }
  bool empty() const noexcept { return text[0] == '\0'; }
  bool operator==(const MarkerLabel& o) const noexcept { return view() == o.view(); }
};

enum MarkerFlags : uint32_t {
  kMarkerMissing = 1u << 0,      // occluded or dropped: position is meaningless
  kMarkerUnlabelled = 1u << 1,   // the source gave no identity
  kMarkerRelabelled = 1u << 2,   // identity corrected by the labeller
  kMarkerOutlier = 1u << 3,      // rejected by a robust fit this frame
  kMarkerModelSolved = 1u << 4,  // position filled in by the source's own model solve, not seen
};

struct Marker {
  int32_t id = -1;                              // source id, -1 when none
  MarkerLabel label;                            // source label, may be empty
  Eigen::Vector3d position = Eigen::Vector3d::Zero();  // in the units of its take or source
  uint32_t flags = 0;
  bool present() const noexcept { return (flags & kMarkerMissing) == 0; }
};

struct MarkerFrame {
  int64_t frame_no = 0;
  int64_t source_time_ns = 0;   // the source's own clock (file time, device time)
  int64_t receive_time_ns = 0;  // CLOCK_MONOTONIC when facecap received it
  // CLOCK_MONOTONIC estimate of the cameras' mid-exposure (a NatNet stamp moved onto our
  // clock); 0 when the source does not say.
  int64_t exposure_time_ns = 0;
  Timecode timecode;
  std::vector<Marker> markers;  // reserved at configure time

  std::size_t present_count() const noexcept {
    std::size_t n = 0;
    for (const auto& m : markers) n += m.present() ? 1 : 0;
    return n;
  }
};

// A frame with one marker per label (ids 0, 1, ..., all missing), so that copies of frames
// of that size into it never allocate. Not RT-safe.
MarkerFrame make_marker_frame(const std::vector<std::string>& labels);

// Stages of one solve, in order; timings are reported per stage.
enum class SolveStage : uint8_t {
  kStabilise, kCorrespond, kWeights, kBlend, kRhs, kBacksolve, kCollide, kFilter, kCount
};
inline constexpr std::size_t kSolveStageCount = static_cast<std::size_t>(SolveStage::kCount);
std::string_view solve_stage_name(SolveStage stage) noexcept;

// Why a solved frame may be less than it should be. Set by the solve (the solver's
// SolveResult::status and the marker mapper), counted per bit by the loop, published in
// shared memory (docs/shm-format.md), recorded, and shown in STATUS and the stats file.
enum SolvedFlags : uint32_t {
  kSolvedHeadPoseHeld = 1u << 0,        // too few head markers: the previous head pose reused
  kSolvedTooFewMarkers = 1u << 1,       // too few face markers to solve: the previous face reused
  kSolvedQpIterationCap = 1u << 2,      // Eq. 2's box QP stopped at its iteration cap unconverged
  kSolvedPinsBeyondCapacity = 1u << 3,  // the collision stage needed more pins than collision_max_pins
  kSolvedSingularCorrection = 1u << 4,  // a low-rank pin correction was singular: solved without it
  kSolvedImplausibleMarker = 1u << 5,   // a marker moved implausibly fast (or was not finite): left out of this frame
  kSolvedFolded = 1u << 6,              // triangles folded against the linear blend of the same weights remain
  kSolvedInconsistentMarker = 1u << 7,  // a marker disagreed with its face neighbours (a label swap): left out of this frame
};
inline constexpr std::size_t kSolvedFlagCount = 8;
// "head_pose_held", "too_few_markers", ... for bit 0, 1, ...; "?" beyond. RT-safe.
std::string_view solved_flag_name(std::size_t bit) noexcept;

struct SolvedFrame {
  int64_t frame_no = 0;
  int64_t source_time_ns = 0;
  int64_t receive_time_ns = 0;
  int64_t solve_start_ns = 0;
  int64_t solve_end_ns = 0;
  Timecode timecode;
  Eigen::Quaterniond head_rotation = Eigen::Quaterniond::Identity();  // head in world
  Eigen::Vector3d head_translation = Eigen::Vector3d::Zero();
  Eigen::VectorXf weights;           // M, in rig shape order
  Eigen::Matrix3Xf vertices;         // 3 x N, rig units, head space
  std::array<int64_t, kSolveStageCount> stage_ns{};
  uint32_t collision_constraints = 0;
  uint32_t markers_used = 0;      // face markers the solve pinned
  uint32_t markers_expected = 0;  // face markers the calibration binds
  uint32_t flags = 0;
  // The fold metric of this frame's solve against the rig's linear blend of the same
  // weights (SolveResult::folds): folded triangles, the largest edge stretch in rig mm.
  uint32_t folded_triangles = 0;
  float max_edge_stretch_mm = 0.0f;
  // Rounds the fold stage ran before it stopped for the loop's deadline (SolveResult::
  // fold_rounds), -1 when it was not stopped: a re-solve stops there too.
  int32_t fold_deadline_rounds = -1;
  // Operator telemetry per source marker slot (MarkerFrame::markers order): the marker's
  // target in rig space (head frame, rig units) and the fit residual, the distance in mm
  // from the solved surface point it is bound to. NaN for slots missing this frame or not
  // bound to the face (head markers, labels the calibration lacks).
  Eigen::Matrix3Xf marker_targets;
  Eigen::VectorXf marker_residual_mm;

  void resize(Eigen::Index shapes, Eigen::Index vertex_count, Eigen::Index marker_slots = 0) {
    weights.setZero(shapes);
    vertices.setZero(3, vertex_count);
    marker_targets.setConstant(3, marker_slots, std::numeric_limits<float>::quiet_NaN());
    marker_residual_mm.setConstant(marker_slots, std::numeric_limits<float>::quiet_NaN());
  }
};

// Copies `from` into `to`, whose storage was sized beforehand (resize) so that nothing is
// allocated: the weights when the sizes match, the vertices only when `to` has room for
// the same count (a copy made without vertices keeps none). RT-safe.
void copy_solved_frame(const SolvedFrame& from, SolvedFrame& to) noexcept;

}  // namespace facecap
