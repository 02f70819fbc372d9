#include "solver/collide/pair_batch.hpp"

#include <algorithm>
#include <bit>

#include "solver/collide/geometry.hpp"

namespace facecap {
namespace {

using Vec3 = Eigen::Vector3d;

// Which of `count` (<= 16) pairs are closer than epsilon: triangles_closer_than for each.
// The kernels' float pass settles the clear cases (kernels::PairVerdict); the exact test
// decides the rest (on the lips mostly pairs that cross). corner_of(lane, k) gives pair
// `lane`'s corner k: a's three, then b's three.
template <class Corner>
uint32_t closer_than_16(const kernels::KernelTable& table, const Corner& corner_of, int count, double epsilon) noexcept {
  if (count <= 0 || !(epsilon > 0.0)) return 0;
  // Corners relative to a's first corner, so that float keeps their detail.
  kernels::PairLanes lanes{};
  for (int lane = 0; lane < count; ++lane) {
    const Vec3 origin = corner_of(lane, 0);
    double largest = 0.0;
    for (int k = 0; k < 5; ++k) {
      const Vec3 d = corner_of(lane, k + 1) - origin;
      largest = std::max(largest, d.cwiseAbs().maxCoeff());
      for (int c = 0; c < 3; ++c) lanes.corner[k][c][lane] = float(d[c]);
    }
    lanes.extent[lane] = float(largest);
  }
  const kernels::PairVerdict verdict = table.pair_float_pass(lanes, count, float(epsilon));
  uint32_t result = verdict.close;
  uint32_t undecided = ((1u << count) - 1) & ~verdict.close & ~verdict.apart;
  for (; undecided != 0; undecided &= undecided - 1) {
    const int lane = std::countr_zero(undecided);
    if (triangles_closer_than(corner_of(lane, 0), corner_of(lane, 1), corner_of(lane, 2), corner_of(lane, 3),
                              corner_of(lane, 4), corner_of(lane, 5), epsilon))
      result |= 1u << lane;
  }
  return result;
}

}  // namespace

uint32_t triangles_closer_than(const kernels::KernelTable& table, std::span<const TrianglePairCorners> pairs,
                               double epsilon) noexcept {
  auto corner_of = [&](int lane, int k) -> const Vec3& {
    return k < 3 ? pairs[std::size_t(lane)].a[k] : pairs[std::size_t(lane)].b[k - 3];
  };
  return closer_than_16(table, corner_of, int(std::min<std::size_t>(pairs.size(), kCloserBatch)), epsilon);
}

uint32_t triangles_closer_than(const kernels::KernelTable& table, const Eigen::Ref<const Eigen::Matrix3Xd>& positions,
                               std::span<const TrianglePairVertices> pairs, double epsilon) noexcept {
  auto corner_of = [&](int lane, int k) {
    return Vec3(positions.col(k < 3 ? pairs[std::size_t(lane)].a[k] : pairs[std::size_t(lane)].b[k - 3]));
  };
  return closer_than_16(table, corner_of, int(std::min<std::size_t>(pairs.size(), kCloserBatch)), epsilon);
}

}  // namespace facecap
