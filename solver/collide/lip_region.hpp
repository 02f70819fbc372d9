#pragma once
// The triangles the collision stage checks (its candidate set): the lip region, found
// from how the rig's mouth*/jaw* shapes move its vertices, or any set given by a mask,
// a radius around seed vertices or the whole face. Configuration time: these allocate
// and may throw Error; none is real-time.
#include <cstdint>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "solver/rig.hpp"

namespace facecap {

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
// Throws Error when no lip vertex can be found.
std::vector<int> lip_region_triangles(const Rig& rig, const LipRegionOptions& options = {});

}  // namespace facecap
