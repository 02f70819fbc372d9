#pragma once
// The fold metric (docs/solver.md "Folds"): the triangles a solve folded relative to a
// reference mesh of the same weights, the rig's linear blend x0 + B w. A triangle is
// folded when its normal points against the reference's (flipped), or when an edge it
// shares bends more than a threshold beyond the reference's bend there (a crease the
// shapes do not have: crumpled eyelids, mouth corners). A triangle whose corners are all
// within a tolerance of the reference's is taken as the reference's. Also the largest change of an
// edge's length against the reference (a torn, stretched patch), and the folded count per
// face region. Lifecycle: configure (allocates) -> measure() per frame (real-time safe).
#include <array>
#include <cstdint>
#include <span>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "solver/mesh_topology.hpp"

namespace facecap {
namespace kernels {
struct KernelTable;
}

struct Rig;

// Where on the face a triangle is: the lips and the eyelids are where folds and crossings
// happen (ICT's mouthClose alone flips 416 triangles against the neutral).
enum FaceRegion : uint8_t { kRegionLips, kRegionEyelids, kRegionElsewhere, kFaceRegionCount };
inline constexpr const char* kFaceRegionNames[kFaceRegionCount] = {"lips", "eyelids", "elsewhere"};

// Per triangle (T): lips when a vertex is moved by mouthRollLower or mouthRollUpper,
// eyelids when by eyeBlink_L or eyeBlink_R, at least 30% of that shape's largest vertex
// motion. A rig without those shapes has every triangle elsewhere. Allocates.
std::vector<uint8_t> triangle_regions(const Rig& rig);

// The tolerance facecap measures folds with: a solve this close to the linear blend at
// every corner of a triangle looks like it, whatever the triangle's orientation (ICT's
// lip corners have slivers whose blended area is a fourteenth of their rest area, which
// a micrometre turns over).
inline constexpr double kFoldToleranceMm = 0.01;
// kFoldToleranceMm in the rig's units.
double fold_tolerance(const Rig& rig);

struct FoldReport {
  uint32_t folded = 0;   // triangles flipped or creased against the reference
  uint32_t flipped = 0;  // of those, flipped
  std::array<uint32_t, kFaceRegionCount> folded_by_region{};
  double max_edge_stretch = 0.0;  // rig units: the largest | |e| - |e_ref| | over edges
};

class FoldDetector {
 public:
  // triangles: 3 x T; regions: T (triangle_regions), or empty for all elsewhere. A crease
  // counts when the angle between the normals across an edge exceeds the reference's by
  // more than crease_degrees (SolverParams::fold_crease_degrees; 90: the skin doubles
  // back on itself); tolerance: in the meshes' units (fold_tolerance). kernels: the table
  // whose fold pass measures (null: the widest this CPU runs). Allocates; not real-time.
  void configure(const Eigen::Matrix3Xi& triangles, std::vector<uint8_t> regions, double crease_degrees = 90.0,
                 double tolerance = 0.0, const kernels::KernelTable* kernels = nullptr);
  bool configured() const noexcept { return triangle_count_ > 0; }

  // Measures `solved` against `reference` (both 3 x N), in float (the kernels' fold
  // passes). Zero-area triangles (either mesh) are not counted as flipped. Real-time safe.
  const FoldReport& measure(const Eigen::Matrix3Xd& solved, const Eigen::Matrix3Xd& reference) noexcept;
  // measure() of another solve against the same reference as the last measure(): the
  // reference is not read again (the fold stage's rounds). Real-time safe.
  const FoldReport& measure_again(const Eigen::Matrix3Xd& solved) noexcept;

  // After measure(): per triangle, 1 if folded; the folded triangles, ascending.
  std::span<const uint8_t> folded_flags() const noexcept { return {folded_.data(), std::size_t(triangle_count_)}; }
  std::span<const int> folded_triangles() const noexcept { return {folded_list_.data(), std::size_t(report_.folded)}; }
  const FoldReport& report() const noexcept { return report_; }
  // The triangles sharing an edge with triangle t.
  std::span<const int> neighbours(int t) const noexcept { return adjacency_.neighbours(t); }
  const Eigen::Matrix3Xi& triangles() const noexcept { return triangles_; }

 private:
  // Coordinate-major float copy of a 3 x N mesh (the kernels' layout).
  void copy_positions(const Eigen::Matrix3Xd& mesh, std::vector<float>& out) const noexcept;
  const FoldReport& measure_solved(bool reference_known) noexcept;
  // Triangle t's solved normal, or its reference normal where its corners are all within
  // the tolerance.
  Eigen::Vector3d judged_normal(int t) const noexcept;
  Eigen::Vector3d normal(const std::vector<float>& normals, int t) const noexcept;

  const kernels::KernelTable* kernels_ = nullptr;
  Eigen::Matrix3Xi triangles_;
  Eigen::Index triangle_count_ = 0, padded_count_ = 0, vertex_count_ = 0;
  std::vector<int32_t> corners_;  // 3 x padded_count_, corner-major
  TriangleAdjacency adjacency_{Eigen::Matrix3Xi(3, 0)};
  std::vector<uint8_t> regions_;
  double crease_radians_ = 0.0, tolerance_ = 0.0;
  std::vector<float> solved_, reference_;                  // coordinate-major positions
  std::vector<float> solved_normals_, reference_normals_;  // per triangle, coordinate-major, not normalised
  std::vector<int32_t> flipped_list_, turned_list_;        // the kernel's lists
  std::vector<uint8_t> turned_;                            // per triangle, set only while measuring
  std::vector<uint8_t> folded_;                            // per triangle; cleared by folded_list_
  std::vector<int> folded_list_;
  FoldReport report_;
};

}  // namespace facecap
