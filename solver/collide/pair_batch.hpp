#pragma once
// The closeness test of triangles_closer_than (collide/geometry.hpp) for up to 16 pairs
// at once: one float pass with the pairs in SIMD lanes settles the clear cases, the exact
// double test the rest. The collider tests its candidate pairs this way, and so does the
// collision stage its pairs' linear-blend references. Real-time safe.
#include <cstdint>
#include <span>

#include <Eigen/Core>

#include "solver/kernels/kernels.hpp"

namespace facecap {

// The corners of two triangles a and b, for the batched test below.
struct TrianglePairCorners {
  Eigen::Vector3d a[3];
  Eigen::Vector3d b[3];
};

// The same as vertex indices into a 3 x N positions matrix.
struct TrianglePairVertices {
  int32_t a[3];
  int32_t b[3];
};

inline constexpr int kCloserBatch = kernels::kPairLanes;

// triangles_closer_than for up to kCloserBatch pairs (more are ignored): bit k is set
// when pair k is closer than epsilon. A float pass over all of them settles the clear
// cases, with margins far above its rounding (by the kernels of `table`); the double
// test decides the rest.
uint32_t triangles_closer_than(const kernels::KernelTable& table, std::span<const TrianglePairCorners> pairs,
                               double epsilon) noexcept;
// The same for pairs given by vertex indices into `positions` (3 x N), read where the
// test needs them: the collider tests thousands of candidate pairs a frame, and copying
// their corners first measured 25% slower.
uint32_t triangles_closer_than(const kernels::KernelTable& table, const Eigen::Ref<const Eigen::Matrix3Xd>& positions,
                               std::span<const TrianglePairVertices> pairs, double epsilon) noexcept;

}  // namespace facecap
