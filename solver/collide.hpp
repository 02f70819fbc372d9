#pragma once
// Triangle-triangle proximity for the face solve (DESIGN.md "Collisions"): a bounding
// volume hierarchy of axis-aligned boxes over a candidate set of triangles (the lip
// region or the whole face), built once on the rest mesh and refitted every frame with
// each triangle's box grown by epsilon / 2, finds the triangle pairs closer than
// epsilon that share no vertex. The solver pins those pairs' vertices to the linear
// blend.
//
// Lifecycle: TriangleCollider::configure() (allocates, not real-time) -> make_result()
// (allocates the output once) -> detect() per frame (real-time safe).
//
// Also here: the exact triangle-triangle distance, and the evaluation metrics
// (intersecting pairs over a whole mesh, flipped triangles), which are not real-time.
// Everything is double precision with ordinary floating-point predicates (no exact
// arithmetic): pairs within about 1e-12 of the threshold may be classified either way.
#include <compare>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "solver/rig.hpp"

namespace facecap {

// ---- Triangle geometry (all real-time safe: noexcept, no allocation) -------------

// Euclidean distance between two closed triangles a = (a0, a1, a2) and b = (b0, b1, b2):
// 0 when they touch or cross, otherwise the smallest of the 6 vertex-face and 9
// edge-edge distances. Degenerate (zero-area) triangles are handled as segments/points.
double triangle_distance(const Eigen::Vector3d& a0, const Eigen::Vector3d& a1, const Eigen::Vector3d& a2,
                         const Eigen::Vector3d& b0, const Eigen::Vector3d& b1,
                         const Eigen::Vector3d& b2) noexcept;

// Whether the closed triangles share at least one point (distance exactly 0).
bool triangles_intersect(const Eigen::Vector3d& a0, const Eigen::Vector3d& a1, const Eigen::Vector3d& a2,
                         const Eigen::Vector3d& b0, const Eigen::Vector3d& b1,
                         const Eigen::Vector3d& b2) noexcept;

// triangle_distance(a, b) < epsilon (so always false for epsilon <= 0), with cheap
// separating-axis rejections first.
bool triangles_closer_than(const Eigen::Vector3d& a0, const Eigen::Vector3d& a1, const Eigen::Vector3d& a2,
                           const Eigen::Vector3d& b0, const Eigen::Vector3d& b1, const Eigen::Vector3d& b2,
                           double epsilon) noexcept;

// The corners of two triangles a and b, for the batched test below.
struct TrianglePairCorners {
  Eigen::Vector3d a[3];
  Eigen::Vector3d b[3];
};

inline constexpr int kCloserBatch = 16;

// triangles_closer_than for up to kCloserBatch pairs (more are ignored): bit k is set
// when pair k is closer than epsilon. A float pass over all of them settles the clear
// cases, with margins far above its rounding; the double test decides the rest.
uint32_t triangles_closer_than(std::span<const TrianglePairCorners> pairs, double epsilon) noexcept;

// ---- Candidate triangle sets (configuration time: allocate, may throw) -----------

// 0, 1, ..., triangle_count - 1: the whole face as the candidate set.
std::vector<int> all_triangles(Eigen::Index triangle_count);

// Triangles with at least one vertex flagged in vertex_mask (N flags). Ascending.
std::vector<int> masked_triangles(const Eigen::Matrix3Xi& triangles, std::span<const uint8_t> vertex_mask);

// Triangles with at least one vertex within `radius` (rest positions, rig units) of a
// seed vertex. Ascending. triangles: 3 x T; rest_positions: 3 x N.
std::vector<int> triangles_near_vertices(const Eigen::Matrix3Xi& triangles, const Eigen::Matrix3Xd& rest_positions,
                                         std::span<const int> seed_vertices, double radius);

// N flags: vertices that some shape whose name starts with "mouth" or "jaw" (any case)
// moves by more than min_displacement rig units.
std::vector<uint8_t> mouth_moving_vertices(const Rig& rig, double min_displacement);

// The lips found from the shapes alone (ascending): vertices that some mouth*/jaw* shape
// moves by more than 5% of the largest such displacement AND that lie within 2% of the
// neutral's bounding-box diagonal of a vertex that "jawOpen" moves differently by more
// than half its largest displacement. The two lips face each other across the mouth
// slit, and only there does opening the jaw separate near neighbours. Without a
// "jawOpen" shape: every vertex the mouth*/jaw* shapes move by more than that 5%.
std::vector<int> find_lip_vertices(const Rig& rig);

struct LipRegionOptions {
  // Vertices on the lips (e.g. BuiltinFace::upper_lip_vertices() + lower_lip_vertices()).
  // Empty: find_lip_vertices(rig).
  std::vector<int> lip_vertices;
  // Rig units; triangles with a vertex this close to a lip vertex are candidates.
  // <= 0: 3% of the neutral's bounding-box diagonal (about 8 mm on a face).
  double radius = 0.0;
};

// The lip region's triangles (ascending), the solver's default candidate set: every
// triangle with a vertex within options.radius of a lip vertex (rest positions).
// Not real-time. Throws Error when no lip vertex can be found.
std::vector<int> lip_region_triangles(const Rig& rig, const LipRegionOptions& options = {});

// ---- The per-frame collider ------------------------------------------------------

// Two triangles (indices into the rig's 3 x T triangle matrix), first < second.
struct TrianglePair {
  int32_t first = -1;
  int32_t second = -1;
  friend bool operator==(const TrianglePair&, const TrianglePair&) = default;
  friend auto operator<=>(const TrianglePair&, const TrianglePair&) = default;
};

struct ColliderConfig {
  double epsilon = 0.01;  // rig units: triangle pairs closer than this collide (>= 0)
  int max_pairs = 4096;   // pairs stored per frame; more are counted, not stored (>= 0)
  // Constrained vertices stored per frame; < 0 means every vertex of the candidate
  // triangles, which can never overflow.
  int max_vertices = -1;
  // Leave out pairs already closer than epsilon in the rest pose. Real rigs have such
  // contacts (the ICT neutral's lip corners interpenetrate), and pinning them every
  // frame constrains the mouth for nothing.
  bool ignore_rest_contacts = false;
  // Also leave out pairs where a vertex of one is within this many mesh edges of a
  // vertex of the other (0: only pairs sharing a vertex). Such triangles are neighbours
  // on one sheet of skin, near by construction rather than in contact, and their boxes
  // overlap: leaving them out spares most exact tests (>= 0).
  int neighbour_edges = 0;
};

// One frame's collisions, sized once by TriangleCollider::make_result(); detect() only
// writes into it. The first pair_count pairs and vertex_count vertices are valid.
struct CollisionResult {
  std::vector<TrianglePair> pairs;  // capacity max_pairs; valid prefix sorted ascending
  std::vector<int32_t> vertices;    // capacity max_vertices; valid prefix ascending, unique
  int32_t pair_count = 0;
  int32_t vertex_count = 0;
  int32_t pairs_found = 0;     // colliding pairs this frame, including those not stored
  int32_t vertices_found = 0;  // distinct vertices of all pairs found, including unstored
  // True when pairs or vertices exceeded capacity. The vertices always come from every
  // pair found, stored or not, so pinning stays complete while vertex capacity lasts.
  bool overflowed() const noexcept { return pairs_found > pair_count || vertices_found > vertex_count; }
  std::span<const TrianglePair> valid_pairs() const noexcept { return {pairs.data(), std::size_t(pair_count)}; }
  std::span<const int32_t> valid_vertices() const noexcept { return {vertices.data(), std::size_t(vertex_count)}; }
};

class TriangleCollider {
 public:
  TriangleCollider();
  ~TriangleCollider();
  TriangleCollider(TriangleCollider&&) noexcept;
  TriangleCollider& operator=(TriangleCollider&&) noexcept;

  // Builds the tree over candidate_triangles on the rest mesh (deterministically: the
  // same input always gives the same tree) and sizes every per-frame buffer.
  // triangles: 3 x T vertex indices; rest_positions: 3 x N; candidate_triangles:
  // indices into triangles (duplicates ignored; all_triangles() for the whole face).
  // Not real-time: allocates; throws Error on out-of-range indices or bad limits.
  void configure(const Eigen::Matrix3Xi& triangles, const Eigen::Matrix3Xd& rest_positions,
                 std::span<const int> candidate_triangles, const ColliderConfig& config);

  // A result with capacity for this configuration. Not real-time: allocates.
  CollisionResult make_result() const;

  // Refits the tree to `positions` (3 x N, same vertex order as configure) and writes
  // every candidate pair closer than epsilon that shares no vertex into `out`.
  // Real-time safe: no allocation, locks, logging or exceptions. Pass a Matrix3Xd or a
  // Map of contiguous 3 x N doubles (another expression type would be copied).
  // Returns false, with `out` emptied, if not configured, if the sizes do not match or
  // if a candidate vertex is not finite. It updates the tree in place: one thread at a
  // time per collider.
  bool detect(const Eigen::Ref<const Eigen::Matrix3Xd>& positions, CollisionResult& out) noexcept;

  bool configured() const noexcept;
  double epsilon() const noexcept;
  Eigen::Index vertex_count() const noexcept;          // N the collider expects
  std::span<const int32_t> candidate_triangles() const noexcept;  // ascending, unique
  std::span<const int32_t> candidate_vertices() const noexcept;   // ascending, unique
  int tree_depth() const noexcept;                     // levels of four-wide nodes, root = 1
  // Pairs left out because they touch at rest (ignore_rest_contacts), sorted.
  std::span<const TrianglePair> rest_contacts() const noexcept;

 private:
  struct State;
  std::unique_ptr<State> state_;
};

// ---- Evaluation metrics (not real-time: allocate) --------------------------------

// The "intersections" metric frame after frame on one mesh: the tree over every
// triangle is built once and refitted per call. Counts pairs of triangles sharing no
// vertex that touch or cross (triangles_intersect); pairs sharing a vertex always touch
// and are not counted. Not real-time: count() does not allocate, but it is not bounded
// and throws Error on misuse.
class IntersectionCounter {
 public:
  IntersectionCounter();
  ~IntersectionCounter();
  IntersectionCounter(IntersectionCounter&&) noexcept;
  IntersectionCounter& operator=(IntersectionCounter&&) noexcept;

  // triangles: 3 x T; rest_positions: 3 x N, where the tree is built. Allocates.
  void configure(const Eigen::Matrix3Xi& triangles, const Eigen::Matrix3Xd& rest_positions);
  // positions: 3 x N.
  int64_t count(const Eigen::Matrix3Xd& positions);
  std::vector<TrianglePair> pairs(const Eigen::Matrix3Xd& positions);  // sorted

 private:
  template <typename Found>
  void for_each(const Eigen::Matrix3Xd& positions, Found&& found);
  struct State;
  std::unique_ptr<State> state_;
};

// One-off IntersectionCounter::count over the whole mesh (builds a tree per call).
// triangles: 3 x T; positions: 3 x N.
int64_t count_intersecting_pairs(const Eigen::Matrix3Xi& triangles, const Eigen::Matrix3Xd& positions);

// The pairs themselves, sorted; the same set count_intersecting_pairs counts.
std::vector<TrianglePair> intersecting_pairs(const Eigen::Matrix3Xi& triangles, const Eigen::Matrix3Xd& positions);

// Intersecting pairs at `positions` that do not intersect at `rest_positions`: the
// metric for rigs whose neutral already self-intersects (ICT: 124 pairs at the lip
// corners).
int64_t count_new_intersecting_pairs(const Eigen::Matrix3Xi& triangles, const Eigen::Matrix3Xd& rest_positions,
                                     const Eigen::Matrix3Xd& positions);

// Triangles whose normal points against their rest normal (dot product < 0).
// Zero-area triangles (rest or current) are not counted.
int64_t count_flipped_triangles(const Eigen::Matrix3Xi& triangles, const Eigen::Matrix3Xd& rest_positions,
                                const Eigen::Matrix3Xd& positions);

}  // namespace facecap
