#include "solver/collide/pair_batch.hpp"

#include <algorithm>
#include <bit>

#include "solver/collide/geometry.hpp"
#include "solver/simd.hpp"

namespace facecap {
namespace {

using Vec3 = Eigen::Vector3d;
using simd::FloatX16;
using simd::MaskX16;

// Per lane a 3-vector: one coordinate per FloatX16.
struct Lanes3 {
  FloatX16 x, y, z;
};
Lanes3 operator+(const Lanes3& a, const Lanes3& b) noexcept { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
Lanes3 operator-(const Lanes3& a, const Lanes3& b) noexcept { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
Lanes3 operator*(const Lanes3& a, const FloatX16& s) noexcept { return {a.x * s, a.y * s, a.z * s}; }
FloatX16 dot(const Lanes3& a, const Lanes3& b) noexcept { return a.x * b.x + a.y * b.y + a.z * b.z; }
Lanes3 cross(const Lanes3& a, const Lanes3& b) noexcept {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
Lanes3 select(const MaskX16& m, const Lanes3& a, const Lanes3& b) noexcept {
  return {m ? a.x : b.x, m ? a.y : b.y, m ? a.z : b.z};
}

// point_triangle_sq per lane (Ericson 5.1.5), every Voronoi region computed and the first
// one that holds chosen. Degenerate triangles give meaningless values: callers leave
// them out.
FloatX16 point_triangle_sq(const Lanes3& p, const Lanes3& a, const Lanes3& b, const Lanes3& c) noexcept {
  const Lanes3 ab = b - a, ac = c - a, ap = p - a, bp = p - b, cp = p - c;
  const FloatX16 d1 = dot(ab, ap), d2 = dot(ac, ap), d3 = dot(ab, bp), d4 = dot(ac, bp), d5 = dot(ab, cp), d6 = dot(ac, cp);
  const FloatX16 va = d3 * d6 - d5 * d4, vb = d5 * d2 - d1 * d6, vc = d1 * d4 - d3 * d2;
  const FloatX16 denom = 1.0f / (va + vb + vc);
  Lanes3 q = a + ab * (vb * denom) + ac * (vc * denom);  // inside
  const FloatX16 e43 = d4 - d3, e56 = d5 - d6;
  q = select((va <= 0.0f) & (e43 >= 0.0f) & (e56 >= 0.0f), b + (c - b) * (e43 / (e43 + e56)), q);
  q = select((vb <= 0.0f) & (d2 >= 0.0f) & (d6 <= 0.0f), a + ac * (d2 / (d2 - d6)), q);
  q = select((d6 >= 0.0f) & (d5 <= d6), c, q);
  q = select((vc <= 0.0f) & (d1 >= 0.0f) & (d3 <= 0.0f), a + ab * (d1 / (d1 - d3)), q);
  q = select((d3 >= 0.0f) & (d4 <= d3), b, q);
  q = select((d1 <= 0.0f) & (d2 <= 0.0f), a, q);
  const Lanes3 d = p - q;
  return dot(d, d);
}

// segment_segment_sq per lane (Ericson 5.1.9): always the distance between two points of
// the segments, so it never falls below the true one by more than rounding.
FloatX16 segment_segment_sq(const Lanes3& p1, const Lanes3& q1, const Lanes3& p2, const Lanes3& q2) noexcept {
  const Lanes3 d1 = q1 - p1, d2 = q2 - p2, r = p1 - p2;
  const FloatX16 a = dot(d1, d1), e = dot(d2, d2), f = dot(d2, r), c = dot(d1, r), b = dot(d1, d2);
  auto clamp01 = [](const FloatX16& x) { return simd::min(simd::max(x, FloatX16{}), FloatX16{} + 1.0f); };
  const FloatX16 denom = a * e - b * b;
  FloatX16 s = (denom > 1e-6f * a * e) ? clamp01((b * f - c * e) / denom) : FloatX16{};
  FloatX16 t = (b * s + f) / e;
  const MaskX16 below = t < 0.0f, above = t > 1.0f;
  s = below ? clamp01(-c / a) : (above ? clamp01((b - c) / a) : s);
  t = clamp01(t);
  const Lanes3 d = (p1 + d1 * s) - (p2 + d2 * t);
  return dot(d, d);
}

// Whether the projections of a and b on `axis` are at least `gap` * |axis| apart.
MaskX16 separated_along(const Lanes3& axis, const Lanes3* a, const Lanes3* b, const FloatX16& gap) noexcept {
  const FloatX16 a0 = dot(axis, a[0]), a1 = dot(axis, a[1]), a2 = dot(axis, a[2]);
  const FloatX16 b0 = dot(axis, b[0]), b1 = dot(axis, b[1]), b2 = dot(axis, b[2]);
  const FloatX16 between = simd::max(simd::min(simd::min(b0, b1), b2) - simd::max(simd::max(a0, a1), a2),
                                     simd::min(simd::min(a0, a1), a2) - simd::max(simd::max(b0, b1), b2));
  return (between > 0.0f) & (between * between >= gap * gap * dot(axis, axis));
}

// Which of `count` (<= 16) pairs are closer than epsilon: triangles_closer_than for each.
// A float pass settles the clear cases with a margin far above its rounding: apart along
// a separating axis (centroids, normals, edge pairs), or closer by a corner's distance to
// the other triangle or an edge's to an edge. The exact test decides the rest (on the
// lips mostly pairs that cross). corner_of(lane, k) gives pair `lane`'s corner k: a's
// three, then b's three.
template <class Corner>
uint32_t closer_than_16(const Corner& corner_of, int count, double epsilon) noexcept {
  if (count <= 0 || !(epsilon > 0.0)) return 0;
  // Corners relative to a's first corner, so that float keeps their detail.
  alignas(64) float corner[5][3][16] = {};
  alignas(64) float extent[16] = {};
  for (int lane = 0; lane < count; ++lane) {
    const Vec3 origin = corner_of(lane, 0);
    double largest = 0.0;
    for (int k = 0; k < 5; ++k) {
      const Vec3 d = corner_of(lane, k + 1) - origin;
      largest = std::max(largest, d.cwiseAbs().maxCoeff());
      for (int c = 0; c < 3; ++c) corner[k][c][lane] = float(d[c]);
    }
    extent[lane] = float(largest);
  }
  auto load = [&](int k) {
    return Lanes3{simd::load<FloatX16>(corner[k][0]), simd::load<FloatX16>(corner[k][1]), simd::load<FloatX16>(corner[k][2])};
  };
  const Lanes3 a[3] = {Lanes3{}, load(0), load(1)}, b[3] = {load(2), load(3), load(4)};
  const FloatX16 scale = simd::load<FloatX16>(extent);
  // Float rounding here stays below 1e-5 of the pair's extent; the margin covers it.
  const float eps = float(epsilon);
  const FloatX16 margin = 1e-3f * eps + 1e-5f * scale;
  const FloatX16 apart_gap = eps + margin, close_distance = simd::max(eps - margin, FloatX16{});
  MaskX16 apart = separated_along((b[0] + b[1] + b[2]) - (a[1] + a[2]), a, b, apart_gap);
  const Lanes3 na = cross(a[1], a[2]), nb = cross(b[1] - b[0], b[2] - b[0]);
  apart |= separated_along(na, a, b, apart_gap) | separated_along(nb, a, b, apart_gap);
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      apart |= separated_along(cross(a[(i + 1) % 3] - a[i], b[(j + 1) % 3] - b[j]), a, b, apart_gap);
  // Corner-to-triangle distances only for well-shaped triangles (sine of the corner
  // angle above 1e-4), where the float closest point lies on the triangle.
  const Lanes3 eb1 = b[1] - b[0], eb2 = b[2] - b[0];
  const MaskX16 shaped = (dot(na, na) > 1e-8f * dot(a[1], a[1]) * dot(a[2], a[2])) &
                         (dot(nb, nb) > 1e-8f * dot(eb1, eb1) * dot(eb2, eb2));
  FloatX16 nearest = point_triangle_sq(a[0], b[0], b[1], b[2]);
  for (int k = 1; k < 3; ++k) nearest = simd::min(nearest, point_triangle_sq(a[k], b[0], b[1], b[2]));
  for (int k = 0; k < 3; ++k) nearest = simd::min(nearest, point_triangle_sq(b[k], a[0], a[1], a[2]));
  FloatX16 nearest_edges = segment_segment_sq(a[0], a[1], b[0], b[1]);
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      nearest_edges = simd::min(nearest_edges, segment_segment_sq(a[i], a[(i + 1) % 3], b[j], b[(j + 1) % 3]));
  const MaskX16 close = (shaped & (nearest < close_distance * close_distance)) |
                        (nearest_edges < close_distance * close_distance);
  const uint32_t used = (1u << count) - 1;
  uint32_t result = simd::lane_bits(close) & used;
  uint32_t undecided = used & ~result & ~simd::lane_bits(apart);
  for (; undecided != 0; undecided &= undecided - 1) {
    const int lane = std::countr_zero(undecided);
    if (triangles_closer_than(corner_of(lane, 0), corner_of(lane, 1), corner_of(lane, 2), corner_of(lane, 3),
                              corner_of(lane, 4), corner_of(lane, 5), epsilon))
      result |= 1u << lane;
  }
  return result;
}

}  // namespace

uint32_t triangles_closer_than(std::span<const TrianglePairCorners> pairs, double epsilon) noexcept {
  auto corner_of = [&](int lane, int k) -> const Vec3& {
    return k < 3 ? pairs[std::size_t(lane)].a[k] : pairs[std::size_t(lane)].b[k - 3];
  };
  return closer_than_16(corner_of, int(std::min<std::size_t>(pairs.size(), kCloserBatch)), epsilon);
}

uint32_t triangles_closer_than(const Eigen::Ref<const Eigen::Matrix3Xd>& positions,
                               std::span<const TrianglePairVertices> pairs, double epsilon) noexcept {
  auto corner_of = [&](int lane, int k) {
    return Vec3(positions.col(k < 3 ? pairs[std::size_t(lane)].a[k] : pairs[std::size_t(lane)].b[k - 3]));
  };
  return closer_than_16(corner_of, int(std::min<std::size_t>(pairs.size(), kCloserBatch)), epsilon);
}

}  // namespace facecap
