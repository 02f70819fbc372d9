#include "solver/collide.hpp"

#include <algorithm>
#include <array>
#include <bit>
#include <cstring>
#include <cctype>
#include <cmath>
#include <iterator>
#include <limits>
#include <numeric>
#include <string_view>

#if defined(__SSE__)
#include <immintrin.h>  // movemask: lane compare results to bits
#endif

#include <Eigen/Geometry>
#include <fmt/format.h>

#include "core/error.hpp"

namespace facecap {
namespace {

using Vec3 = Eigen::Vector3d;

// ---- Distances between features ---------------------------------------------------

double point_segment_sq(const Vec3& p, const Vec3& a, const Vec3& b) noexcept {
  const Vec3 ab = b - a;
  const double len_sq = ab.squaredNorm();
  const double t = len_sq > 0.0 ? std::clamp((p - a).dot(ab) / len_sq, 0.0, 1.0) : 0.0;
  return (a + t * ab - p).squaredNorm();
}

// Zero (or numerically zero) area: the triangle is handled as its three edges.
bool is_degenerate(const Vec3& a, const Vec3& b, const Vec3& c) noexcept {
  const Vec3 ab = b - a, ac = c - a;
  const double scale = std::max({ab.squaredNorm(), ac.squaredNorm(), (c - b).squaredNorm()});
  return ab.cross(ac).squaredNorm() <= 1e-24 * scale * scale;
}

// Ericson, Real-Time Collision Detection, 5.1.5: Voronoi regions of the triangle.
double point_triangle_sq(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) noexcept {
  if (is_degenerate(a, b, c))
    return std::min({point_segment_sq(p, a, b), point_segment_sq(p, b, c), point_segment_sq(p, c, a)});
  const Vec3 ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0.0 && d2 <= 0.0) return ap.squaredNorm();
  const Vec3 bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0.0 && d4 <= d3) return bp.squaredNorm();
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) return (a + (d1 / (d1 - d3)) * ab - p).squaredNorm();
  const Vec3 cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0.0 && d5 <= d6) return cp.squaredNorm();
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) return (a + (d2 / (d2 - d6)) * ac - p).squaredNorm();
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0)
    return (b + ((d4 - d3) / ((d4 - d3) + (d5 - d6))) * (c - b) - p).squaredNorm();
  const double denom = 1.0 / (va + vb + vc);
  return (a + ab * (vb * denom) + ac * (vc * denom) - p).squaredNorm();
}

// Ericson 5.1.9. Every value returned is the distance between two actual points of the
// segments, so rounding can only overestimate, never underestimate, the distance.
double segment_segment_sq(const Vec3& p1, const Vec3& q1, const Vec3& p2, const Vec3& q2) noexcept {
  const Vec3 d1 = q1 - p1, d2 = q2 - p2, r = p1 - p2;
  const double a = d1.squaredNorm(), e = d2.squaredNorm(), f = d2.dot(r);
  double s = 0.0, t = 0.0;
  if (a <= 0.0 && e <= 0.0) return r.squaredNorm();
  if (a <= 0.0) {
    t = std::clamp(f / e, 0.0, 1.0);
  } else {
    const double c = d1.dot(r);
    if (e <= 0.0) {
      s = std::clamp(-c / a, 0.0, 1.0);
    } else {
      const double b = d1.dot(d2);
      const double denom = a * e - b * b;  // >= 0; 0 when parallel
      s = denom > 1e-14 * a * e ? std::clamp((b * f - c * e) / denom, 0.0, 1.0) : 0.0;
      t = (b * s + f) / e;
      if (t < 0.0) {
        t = 0.0;
        s = std::clamp(-c / a, 0.0, 1.0);
      } else if (t > 1.0) {
        t = 1.0;
        s = std::clamp((b - c) / a, 0.0, 1.0);
      }
    }
  }
  return (p1 + s * d1 - (p2 + t * d2)).squaredNorm();
}

// ---- Intersection ----------------------------------------------------------------

// Whether segment pq meets triangle abc at a point off abc's plane or crossing it. A
// segment lying in the plane returns false: coplanar contact is found by the 2D test.
bool segment_crosses_triangle(const Vec3& p, const Vec3& q, const Vec3& a, const Vec3& b, const Vec3& c) noexcept {
  const Vec3 n = (b - a).cross(c - a);
  const double dp = n.dot(p - a), dq = n.dot(q - a);
  if ((dp > 0.0 && dq > 0.0) || (dp < 0.0 && dq < 0.0)) return false;
  if (dp == 0.0 && dq == 0.0) return false;
  // The line through p, q passes through the closed triangle iff it passes on the same
  // side of (or touches) all three edges.
  const Vec3 d = q - p, pa = a - p, pb = b - p, pc = c - p;
  const double s_ab = d.dot(pa.cross(pb)), s_bc = d.dot(pb.cross(pc)), s_ca = d.dot(pc.cross(pa));
  return (s_ab >= 0.0 && s_bc >= 0.0 && s_ca >= 0.0) || (s_ab <= 0.0 && s_bc <= 0.0 && s_ca <= 0.0);
}

double cross2(double ux, double uy, double vx, double vy) noexcept { return ux * vy - uy * vx; }

// Closed 2D triangles (x, y arrays of 3) overlap: an edge pair crosses or touches, or a
// vertex of one lies in the other.
bool triangles_overlap_2d(const std::array<double, 3>& ax, const std::array<double, 3>& ay,
                          const std::array<double, 3>& bx, const std::array<double, 3>& by) noexcept {
  auto orient = [](double px, double py, double qx, double qy, double rx, double ry) {
    return cross2(qx - px, qy - py, rx - px, ry - py);
  };
  auto on_segment = [](double px, double py, double qx, double qy, double rx, double ry) {
    return std::min(px, qx) <= rx && rx <= std::max(px, qx) && std::min(py, qy) <= ry && ry <= std::max(py, qy);
  };
  for (int i = 0; i < 3; ++i) {
    const int i2 = (i + 1) % 3;
    for (int j = 0; j < 3; ++j) {
      const int j2 = (j + 1) % 3;
      const double o1 = orient(ax[i], ay[i], ax[i2], ay[i2], bx[j], by[j]);
      const double o2 = orient(ax[i], ay[i], ax[i2], ay[i2], bx[j2], by[j2]);
      const double o3 = orient(bx[j], by[j], bx[j2], by[j2], ax[i], ay[i]);
      const double o4 = orient(bx[j], by[j], bx[j2], by[j2], ax[i2], ay[i2]);
      if (((o1 > 0 && o2 < 0) || (o1 < 0 && o2 > 0)) && ((o3 > 0 && o4 < 0) || (o3 < 0 && o4 > 0))) return true;
      if (o1 == 0 && on_segment(ax[i], ay[i], ax[i2], ay[i2], bx[j], by[j])) return true;
      if (o2 == 0 && on_segment(ax[i], ay[i], ax[i2], ay[i2], bx[j2], by[j2])) return true;
      if (o3 == 0 && on_segment(bx[j], by[j], bx[j2], by[j2], ax[i], ay[i])) return true;
      if (o4 == 0 && on_segment(bx[j], by[j], bx[j2], by[j2], ax[i2], ay[i2])) return true;
    }
  }
  auto inside = [&](const std::array<double, 3>& tx, const std::array<double, 3>& ty, double px, double py) {
    const double s0 = orient(tx[0], ty[0], tx[1], ty[1], px, py);
    const double s1 = orient(tx[1], ty[1], tx[2], ty[2], px, py);
    const double s2 = orient(tx[2], ty[2], tx[0], ty[0], px, py);
    return (s0 >= 0 && s1 >= 0 && s2 >= 0) || (s0 <= 0 && s1 <= 0 && s2 <= 0);
  };
  return inside(bx, by, ax[0], ay[0]) || inside(ax, ay, bx[0], by[0]);
}

// Exactly coplanar triangles (every vertex of b on a's plane, as computed): overlap in
// the coordinate plane where a's normal is largest.
bool coplanar_triangles_overlap(const Vec3* a, const Vec3* b, const Vec3& normal_a) noexcept {
  int drop = 0;
  normal_a.cwiseAbs().maxCoeff(&drop);
  const int u = (drop + 1) % 3, v = (drop + 2) % 3;
  std::array<double, 3> ax{}, ay{}, bx{}, by{};
  for (int i = 0; i < 3; ++i) {
    ax[i] = a[i][u];
    ay[i] = a[i][v];
    bx[i] = b[i][u];
    by[i] = b[i][v];
  }
  return triangles_overlap_2d(ax, ay, bx, by);
}

bool intersect_impl(const Vec3* a, const Vec3* b) noexcept {
  // Non-coplanar triangles meet along a segment whose end points lie on edges of one
  // or the other, so some edge crosses (or touches) the other triangle.
  for (int i = 0; i < 3; ++i) {
    if (segment_crosses_triangle(a[i], a[(i + 1) % 3], b[0], b[1], b[2])) return true;
    if (segment_crosses_triangle(b[i], b[(i + 1) % 3], a[0], a[1], a[2])) return true;
  }
  const Vec3 na = (a[1] - a[0]).cross(a[2] - a[0]);
  const Vec3 nb = (b[1] - b[0]).cross(b[2] - b[0]);
  const bool b_on_plane_a = na.dot(b[0] - a[0]) == 0.0 && na.dot(b[1] - a[0]) == 0.0 && na.dot(b[2] - a[0]) == 0.0;
  if (b_on_plane_a && na.squaredNorm() > 0.0) return coplanar_triangles_overlap(a, b, na);
  const bool a_on_plane_b = nb.dot(a[0] - b[0]) == 0.0 && nb.dot(a[1] - b[0]) == 0.0 && nb.dot(a[2] - b[0]) == 0.0;
  if (a_on_plane_b && nb.squaredNorm() > 0.0) return coplanar_triangles_overlap(b, a, nb);
  // Degenerate triangles (segments or points) touching without crossing.
  if (na.squaredNorm() == 0.0 || nb.squaredNorm() == 0.0) {
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j)
        if (segment_segment_sq(a[i], a[(i + 1) % 3], b[j], b[(j + 1) % 3]) == 0.0) return true;
  }
  return false;
}

// Smallest squared distance over the 6 vertex-face and 9 edge-edge feature pairs; stops
// early once below stop_below_sq. Equals the squared triangle distance when they do not
// intersect.
double feature_distance_sq(const Vec3* a, const Vec3* b, double stop_below_sq) noexcept {
  double best = std::numeric_limits<double>::infinity();
  for (int i = 0; i < 3; ++i) {
    best = std::min(best, point_triangle_sq(a[i], b[0], b[1], b[2]));
    best = std::min(best, point_triangle_sq(b[i], a[0], a[1], a[2]));
    if (best < stop_below_sq) return best;
  }
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      best = std::min(best, segment_segment_sq(a[i], a[(i + 1) % 3], b[j], b[(j + 1) % 3]));
      if (best < stop_below_sq) return best;
    }
  }
  return best;
}

// Whether unit-free axis `axis` separates the triangles by at least epsilon: the gap
// between their projections is >= epsilon * |axis|.
bool separated_along(const Vec3& axis, const Vec3* a, const Vec3* b, double epsilon) noexcept {
  const double a0 = axis.dot(a[0]), a1 = axis.dot(a[1]), a2 = axis.dot(a[2]);
  const double b0 = axis.dot(b[0]), b1 = axis.dot(b[1]), b2 = axis.dot(b[2]);
  const double gap = std::max(std::min({b0, b1, b2}) - std::max({a0, a1, a2}),
                              std::min({a0, a1, a2}) - std::max({b0, b1, b2}));
  return gap > 0.0 && gap * gap >= epsilon * epsilon * axis.squaredNorm();
}

// Where triangle `other` lies against the plane through p0 with (unnormalised) normal n:
// separated by at least epsilon, strictly on one side (cannot touch the plane), or neither.
enum class PlaneSide { kFar, kOneSide, kStraddles };
PlaneSide plane_side(const Vec3& n, const Vec3& p0, const Vec3* other, double epsilon) noexcept {
  const double d0 = n.dot(other[0] - p0), d1 = n.dot(other[1] - p0), d2 = n.dot(other[2] - p0);
  const double lo = std::min({d0, d1, d2}), hi = std::max({d0, d1, d2});
  const double gap = lo > 0.0 ? lo : (hi < 0.0 ? -hi : 0.0);
  if (gap <= 0.0) return PlaneSide::kStraddles;
  return gap * gap >= epsilon * epsilon * n.squaredNorm() ? PlaneSide::kFar : PlaneSide::kOneSide;
}

bool closer_than_impl(const Vec3* a, const Vec3* b, double epsilon) noexcept {
  if (!(epsilon > 0.0)) return false;  // no distance is below 0
  // Cheap separating axes first: most candidate pairs are surface neighbours a few
  // edges apart (the centroid axis separates them) or stacked sheets (a normal does).
  const Vec3 centroid_axis = (b[0] + b[1] + b[2]) - (a[0] + a[1] + a[2]);
  if (separated_along(centroid_axis, a, b, epsilon)) return false;
  const PlaneSide b_against_a = plane_side((a[1] - a[0]).cross(a[2] - a[0]), a[0], b, epsilon);
  if (b_against_a == PlaneSide::kFar) return false;
  const PlaneSide a_against_b = plane_side((b[1] - b[0]).cross(b[2] - b[0]), b[0], a, epsilon);
  if (a_against_b == PlaneSide::kFar) return false;
  // Edge-edge directions: when the closest points are inside an edge of each, their
  // cross product is the separating direction, and the gap along it the distance.
  for (int i = 0; i < 3; ++i) {
    const Vec3 edge_a = a[(i + 1) % 3] - a[i];
    for (int j = 0; j < 3; ++j)
      if (separated_along(edge_a.cross(b[(j + 1) % 3] - b[j]), a, b, epsilon)) return false;
  }
  const double eps_sq = epsilon * epsilon;
  if (feature_distance_sq(a, b, eps_sq) < eps_sq) return true;
  // A triangle strictly on one side of the other's plane cannot cross it. (A zero-area
  // triangle has a zero normal and always "straddles", so it gets the full test.)
  if (b_against_a == PlaneSide::kOneSide || a_against_b == PlaneSide::kOneSide) return false;
  return intersect_impl(a, b);
}

// ---- Bounding volume hierarchy ---------------------------------------------------

constexpr int kMaxLeafSize = 16;  // one AVX-512 register of float lanes

// Automatic lip detection, as fractions of the neutral's bounding-box diagonal or of
// jawOpen's largest displacement (see lip_region_triangles).
constexpr double kLipNeighbourhood = 0.02;
constexpr double kLipJawContrast = 0.5;
constexpr double kLipRegionRadius = 0.03;

// Boxes are stored in float, rounded outwards, so that sixteen leaf slots fit one AVX-512
// register; every decision about a pair is still made in double by the exact test.
struct Box {
  float lo[3];
  float hi[3];
};

Box merge(const Box& a, const Box& b) noexcept {
  Box m;
  for (int k = 0; k < 3; ++k) {
    m.lo[k] = std::min(a.lo[k], b.lo[k]);
    m.hi[k] = std::max(a.hi[k], b.hi[k]);
  }
  return m;
}

// A float no larger (smaller) than x: the relative margin exceeds float's rounding
// error (2^-24), the absolute one keeps it so near 0.
float float_below(double x) noexcept { return float(x - (std::abs(x) * 0x1p-22 + 1e-30)); }
float float_above(double x) noexcept { return float(x + (std::abs(x) * 0x1p-22 + 1e-30)); }

bool share_vertex(const std::array<int32_t, 3>& s, const std::array<int32_t, 3>& t) noexcept {
  return (s[0] == t[0]) | (s[0] == t[1]) | (s[0] == t[2]) | (s[1] == t[0]) | (s[1] == t[1]) | (s[1] == t[2]) |
         (s[2] == t[0]) | (s[2] == t[1]) | (s[2] == t[2]);
}

// The boxes of one leaf's slots, one lane per slot. Unused lanes hold empty boxes
// (lo = +inf, hi = -inf) that overlap nothing.
using Lanes = float __attribute__((vector_size(4 * kMaxLeafSize)));
using LaneMask = int32_t __attribute__((vector_size(4 * kMaxLeafSize)));
struct alignas(4 * kMaxLeafSize) LeafBoxes {
  Lanes lo[3];
  Lanes hi[3];
};

uint32_t lane_bits(const LaneMask& m) noexcept {
#if defined(__AVX512F__)
  static_assert(kMaxLeafSize == 16);
  const __m512i lanes = reinterpret_cast<__m512i>(m);
  return uint32_t(_mm512_test_epi32_mask(lanes, lanes));
#else
  uint32_t bits = 0;
  for (int i = 0; i < kMaxLeafSize; ++i) bits |= uint32_t(m[i] != 0) << i;
  return bits;
#endif
}

// ---- Batched closeness: a float pass over 16 pairs at once ---------------------------

// Per lane a 3-vector: one coordinate per Lanes.
struct Lanes3 {
  Lanes x, y, z;
};
Lanes3 operator+(const Lanes3& a, const Lanes3& b) noexcept { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
Lanes3 operator-(const Lanes3& a, const Lanes3& b) noexcept { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
Lanes3 operator*(const Lanes3& a, const Lanes& s) noexcept { return {a.x * s, a.y * s, a.z * s}; }
Lanes dot(const Lanes3& a, const Lanes3& b) noexcept { return a.x * b.x + a.y * b.y + a.z * b.z; }
Lanes3 cross(const Lanes3& a, const Lanes3& b) noexcept {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
Lanes3 select(const LaneMask& m, const Lanes3& a, const Lanes3& b) noexcept {
  return {m ? a.x : b.x, m ? a.y : b.y, m ? a.z : b.z};
}
Lanes lanes_min(const Lanes& a, const Lanes& b) noexcept { return a < b ? a : b; }
Lanes lanes_max(const Lanes& a, const Lanes& b) noexcept { return a > b ? a : b; }

// point_triangle_sq per lane (Ericson 5.1.5), every Voronoi region computed and the first
// one that holds chosen. Degenerate triangles give meaningless values: callers leave
// them out.
Lanes point_triangle_sq(const Lanes3& p, const Lanes3& a, const Lanes3& b, const Lanes3& c) noexcept {
  const Lanes3 ab = b - a, ac = c - a, ap = p - a, bp = p - b, cp = p - c;
  const Lanes d1 = dot(ab, ap), d2 = dot(ac, ap), d3 = dot(ab, bp), d4 = dot(ac, bp), d5 = dot(ab, cp), d6 = dot(ac, cp);
  const Lanes va = d3 * d6 - d5 * d4, vb = d5 * d2 - d1 * d6, vc = d1 * d4 - d3 * d2;
  const Lanes denom = 1.0f / (va + vb + vc);
  Lanes3 q = a + ab * (vb * denom) + ac * (vc * denom);  // inside
  const Lanes e43 = d4 - d3, e56 = d5 - d6;
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
Lanes segment_segment_sq(const Lanes3& p1, const Lanes3& q1, const Lanes3& p2, const Lanes3& q2) noexcept {
  const Lanes3 d1 = q1 - p1, d2 = q2 - p2, r = p1 - p2;
  const Lanes a = dot(d1, d1), e = dot(d2, d2), f = dot(d2, r), c = dot(d1, r), b = dot(d1, d2);
  auto clamp01 = [](const Lanes& x) { return lanes_min(lanes_max(x, Lanes{}), Lanes{} + 1.0f); };
  const Lanes denom = a * e - b * b;
  Lanes s = (denom > 1e-6f * a * e) ? clamp01((b * f - c * e) / denom) : Lanes{};
  Lanes t = (b * s + f) / e;
  const LaneMask below = t < 0.0f, above = t > 1.0f;
  s = below ? clamp01(-c / a) : (above ? clamp01((b - c) / a) : s);
  t = clamp01(t);
  const Lanes3 d = (p1 + d1 * s) - (p2 + d2 * t);
  return dot(d, d);
}

// Whether the projections of a and b on `axis` are at least `gap` * |axis| apart.
LaneMask separated_along(const Lanes3& axis, const Lanes3* a, const Lanes3* b, const Lanes& gap) noexcept {
  const Lanes a0 = dot(axis, a[0]), a1 = dot(axis, a[1]), a2 = dot(axis, a[2]);
  const Lanes b0 = dot(axis, b[0]), b1 = dot(axis, b[1]), b2 = dot(axis, b[2]);
  const Lanes between = lanes_max(lanes_min(lanes_min(b0, b1), b2) - lanes_max(lanes_max(a0, a1), a2),
                                  lanes_min(lanes_min(a0, a1), a2) - lanes_max(lanes_max(b0, b1), b2));
  return (between > 0.0f) & (between * between >= gap * gap * dot(axis, axis));
}

// Which of `count` (<= 16) pairs are closer than epsilon: closer_than_impl for each. A
// float pass settles the clear cases with a margin far above its rounding: apart along
// a separating axis (centroids, normals, edge pairs), or closer by a corner's distance
// to the other triangle or an edge's to an edge. The exact test decides the rest (on
// the lips mostly pairs that cross).
// corner(lane, k) gives pair `lane`'s corner k: a's three, then b's three.
template <class Corner>
uint32_t closer_than_16(const Corner& corner_of, int count, double epsilon) noexcept {
  static_assert(kMaxLeafSize == 16);
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
    Lanes3 v;
    std::memcpy(&v.x, corner[k][0], sizeof v.x);
    std::memcpy(&v.y, corner[k][1], sizeof v.y);
    std::memcpy(&v.z, corner[k][2], sizeof v.z);
    return v;
  };
  const Lanes3 a[3] = {Lanes3{}, load(0), load(1)}, b[3] = {load(2), load(3), load(4)};
  Lanes scale;
  std::memcpy(&scale, extent, sizeof scale);
  // Float rounding here stays below 1e-5 of the pair's extent; the margin covers it.
  const float eps = float(epsilon);
  const Lanes margin = 1e-3f * eps + 1e-5f * scale;
  const Lanes apart_gap = eps + margin, close_distance = lanes_max(eps - margin, Lanes{});
  LaneMask apart = separated_along((b[0] + b[1] + b[2]) - (a[1] + a[2]), a, b, apart_gap);
  const Lanes3 na = cross(a[1], a[2]), nb = cross(b[1] - b[0], b[2] - b[0]);
  apart |= separated_along(na, a, b, apart_gap) | separated_along(nb, a, b, apart_gap);
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      apart |= separated_along(cross(a[(i + 1) % 3] - a[i], b[(j + 1) % 3] - b[j]), a, b, apart_gap);
  // Corner-to-triangle distances only for well-shaped triangles (sine of the corner
  // angle above 1e-4), where the float closest point lies on the triangle.
  const Lanes3 eb1 = b[1] - b[0], eb2 = b[2] - b[0];
  const LaneMask shaped = (dot(na, na) > 1e-8f * dot(a[1], a[1]) * dot(a[2], a[2])) &
                          (dot(nb, nb) > 1e-8f * dot(eb1, eb1) * dot(eb2, eb2));
  Lanes nearest = point_triangle_sq(a[0], b[0], b[1], b[2]);
  for (int k = 1; k < 3; ++k) nearest = lanes_min(nearest, point_triangle_sq(a[k], b[0], b[1], b[2]));
  for (int k = 0; k < 3; ++k) nearest = lanes_min(nearest, point_triangle_sq(b[k], a[0], a[1], a[2]));
  Lanes nearest_edges = segment_segment_sq(a[0], a[1], b[0], b[1]);
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      nearest_edges = lanes_min(nearest_edges, segment_segment_sq(a[i], a[(i + 1) % 3], b[j], b[(j + 1) % 3]));
  const LaneMask close = (shaped & (nearest < close_distance * close_distance)) |
                         (nearest_edges < close_distance * close_distance);
  const uint32_t used = (1u << count) - 1;
  uint32_t result = lane_bits(close) & used;
  uint32_t undecided = used & ~result & ~lane_bits(apart);
  for (; undecided != 0; undecided &= undecided - 1) {
    const int lane = std::countr_zero(undecided);
    const Vec3 pa[3] = {corner_of(lane, 0), corner_of(lane, 1), corner_of(lane, 2)};
    const Vec3 pb[3] = {corner_of(lane, 3), corner_of(lane, 4), corner_of(lane, 5)};
    if (closer_than_impl(pa, pb, epsilon)) result |= 1u << lane;
  }
  return result;
}

// Which slots of `leaf` overlap `box`, as bits.
[[gnu::always_inline]] inline uint32_t slots_overlapping(const LeafBoxes& leaf, const Box& box) noexcept {
  const LaneMask m = (leaf.lo[0] <= box.hi[0]) & (leaf.hi[0] >= box.lo[0]) & (leaf.lo[1] <= box.hi[1]) &
                     (leaf.hi[1] >= box.lo[1]) & (leaf.lo[2] <= box.hi[2]) & (leaf.hi[2] >= box.lo[2]);
  return lane_bits(m);
}

// Four child boxes of an inner node, one lane each.
constexpr int kArity = 4;
using Lanes4 = float __attribute__((vector_size(16)));
using LaneMask4 = int32_t __attribute__((vector_size(16)));

uint32_t lane_bits4(LaneMask4 m) noexcept {
#if defined(__SSE__)
  return uint32_t(_mm_movemask_ps(reinterpret_cast<__m128>(m)));
#else
  uint32_t bits = 0;
  for (int i = 0; i < kArity; ++i) bits |= uint32_t(m[i] != 0) << i;
  return bits;
#endif
}

// A reference to a tree element: >= 0 an inner node, < 0 the leaf ~ref.
using Ref = int32_t;
bool is_leaf(Ref r) noexcept { return r < 0; }
int32_t leaf_of(Ref r) noexcept { return ~r; }

struct alignas(16) Node4 {
  Lanes4 lo[3];  // child boxes; unused lanes are empty and overlap nothing
  Lanes4 hi[3];
  Ref child[kArity] = {0, 0, 0, 0};
  int32_t child_count = 0;
};

// Which children of `node` overlap `box`, as bits.
uint32_t children_overlapping(const Node4& node, const Box& box) noexcept {
  const LaneMask4 m = (node.lo[0] <= box.hi[0]) & (node.hi[0] >= box.lo[0]) & (node.lo[1] <= box.hi[1]) &
                      (node.hi[1] >= box.lo[1]) & (node.lo[2] <= box.hi[2]) & (node.hi[2] >= box.lo[2]);
  return lane_bits4(m);
}

Box child_box(const Node4& node, int lane) noexcept {
  return {{node.lo[0][lane], node.lo[1][lane], node.lo[2][lane]}, {node.hi[0][lane], node.hi[1][lane], node.hi[2][lane]}};
}

struct Leaf {
  int32_t first = 0;  // first slot
  int32_t count = 0;  // slots, 1..kMaxLeafSize
};

// A tree of boxes over triangles stored in "slots" (leaf order), up to kMaxLeafSize per
// leaf, four children per inner node. Built once on the rest pose: top-down binary
// splits by the surface area heuristic (every split of the centroid order on each
// axis; ties broken by triangle index, so the tree depends only on its input), then
// collapsed to four-wide nodes so one SIMD compare tests four boxes. Refitting keeps
// the topology and only recomputes boxes.
class Bvh {
 public:
  // triangle_indices: the triangles to hold, in any order; positions: where to build.
  void build(const Eigen::Matrix3Xi& triangles, const Eigen::Matrix3Xd& positions,
             std::span<const int32_t> triangle_indices) {
    const auto count = triangle_indices.size();
    slot_triangle_.assign(triangle_indices.begin(), triangle_indices.end());
    BuildInput input;
    input.centroid.resize(count);
    input.lo.resize(count);
    input.hi.resize(count);
    for (std::size_t i = 0; i < count; ++i) {
      const auto t = slot_triangle_[i];
      const Vec3 p0 = positions.col(triangles(0, t)), p1 = positions.col(triangles(1, t)), p2 = positions.col(triangles(2, t));
      input.centroid[i] = (p0 + p1 + p2) / 3.0;
      input.lo[i] = p0.cwiseMin(p1).cwiseMin(p2);
      input.hi[i] = p0.cwiseMax(p1).cwiseMax(p2);
    }
    input.order.resize(count);
    std::iota(input.order.begin(), input.order.end(), 0);
    std::vector<BuildNode> binary;
    binary.reserve(2 * count + 1);
    leaves_.clear();
    nodes_.clear();
    depth_ = 0;
    if (count > 0) {
      build_binary(input, binary, 0, int32_t(count));
      root_ = collapse(binary, 0, 1);
    }
    // Slots in leaf order, with each triangle's vertices stored beside it.
    std::vector<int32_t> sorted(count);
    for (std::size_t i = 0; i < count; ++i) sorted[i] = slot_triangle_[std::size_t(input.order[i])];
    slot_triangle_ = std::move(sorted);
    slot_vertices_.resize(count);
    for (std::size_t i = 0; i < count; ++i)
      for (int k = 0; k < 3; ++k) slot_vertices_[i][std::size_t(k)] = triangles(k, slot_triangle_[i]);
    const float inf = std::numeric_limits<float>::infinity();
    leaf_boxes_.resize(leaves_.size());
    for (LeafBoxes& leaf : leaf_boxes_)
      for (int k = 0; k < 3; ++k)
        for (int lane = 0; lane < kMaxLeafSize; ++lane) {
          leaf.lo[k][lane] = inf;
          leaf.hi[k][lane] = -inf;
        }
    leaf_box_.assign(leaves_.size(), Box{{inf, inf, inf}, {-inf, -inf, -inf}});
    slot_box_.assign(count, Box{{inf, inf, inf}, {-inf, -inf, -inf}});
    node_box_.assign(nodes_.size(), Box{{inf, inf, inf}, {-inf, -inf, -inf}});
    build_skip_masks({});
    // A popped pair pushes at most 16; at most 15 stay pending per level of the pair
    // recursion, whose levels (the sum of both elements' depths) number below 2 * depth.
    stack_.resize(std::size_t(32 * depth_ + 32));
  }

  // New boxes from positions, each grown by `margin` on every side. Real-time safe.
  void refit(const Eigen::Ref<const Eigen::Matrix3Xd>& positions, double margin) noexcept {
    for (std::size_t l = 0; l < leaves_.size(); ++l) {
      const Leaf& leaf = leaves_[l];
      LeafBoxes& lanes = leaf_boxes_[l];
      for (int32_t lane = 0; lane < leaf.count; ++lane) {
        const auto& v = slot_vertices_[std::size_t(leaf.first + lane)];
        const double* p0 = &positions.coeffRef(0, v[0]);
        const double* p1 = &positions.coeffRef(0, v[1]);
        const double* p2 = &positions.coeffRef(0, v[2]);
        Box& slot = slot_box_[std::size_t(leaf.first + lane)];
        for (int k = 0; k < 3; ++k) {
          slot.lo[k] = lanes.lo[k][lane] = float_below(std::min({p0[k], p1[k], p2[k]}) - margin);
          slot.hi[k] = lanes.hi[k][lane] = float_above(std::max({p0[k], p1[k], p2[k]}) + margin);
        }
      }
      Box& box = leaf_box_[l];
      for (int k = 0; k < 3; ++k) {
        box.lo[k] = lanes.lo[k][0];
        box.hi[k] = lanes.hi[k][0];
        for (int32_t lane = 1; lane < leaf.count; ++lane) {
          box.lo[k] = std::min(box.lo[k], lanes.lo[k][lane]);
          box.hi[k] = std::max(box.hi[k], lanes.hi[k][lane]);
        }
      }
    }
    // Children follow their parent, so a reverse sweep sees children first.
    for (auto n = int32_t(nodes_.size()) - 1; n >= 0; --n) {
      Node4& node = nodes_[std::size_t(n)];
      Box& total = node_box_[std::size_t(n)];
      for (int i = 0; i < node.child_count; ++i) {
        const Ref c = node.child[i];
        const Box& b = is_leaf(c) ? leaf_box_[std::size_t(leaf_of(c))] : node_box_[std::size_t(c)];
        for (int k = 0; k < 3; ++k) {
          node.lo[k][i] = b.lo[k];
          node.hi[k][i] = b.hi[k];
        }
        total = i == 0 ? b : merge(total, b);
      }
    }
  }

  // Calls visit(slot_a, slot_b) for every pair of distinct slots whose boxes overlap,
  // whose triangles share no vertex and that are not skipped, each pair once.
  // Real-time safe when visit is: it allocates nothing itself. Returns false if the
  // traversal stack ran out, which the bound in build() rules out.
  template <typename Visit>
  bool for_each_overlapping_pair(Visit&& visit) {
    if (leaves_.empty()) return true;
    std::size_t top = 0;
    const std::size_t capacity = stack_.size();
    stack_[top++] = {root_, root_};
    while (top > 0) {
      const auto [a, b] = stack_[--top];
      if (top + 16 > capacity) return false;
      if (a == b) {
        if (is_leaf(a)) {
          visit_within_leaf(leaf_of(a), visit);
          continue;
        }
        const Node4& node = nodes_[std::size_t(a)];
        for (int i = 0; i < node.child_count; ++i) {
          stack_[top++] = {node.child[i], node.child[i]};
          uint32_t later = children_overlapping(node, child_box(node, i)) & ~((2u << i) - 1);
          for (; later != 0; later &= later - 1) stack_[top++] = {node.child[i], node.child[std::countr_zero(later)]};
        }
      } else if (is_leaf(a) && is_leaf(b)) {
        visit_between_leaves(leaf_of(a), leaf_of(b), visit);
      } else if (!is_leaf(a) && !is_leaf(b)) {
        const Node4& na = nodes_[std::size_t(a)];
        const Node4& nb = nodes_[std::size_t(b)];
        for (int i = 0; i < na.child_count; ++i) {
          uint32_t hits = children_overlapping(nb, child_box(na, i));
          for (; hits != 0; hits &= hits - 1) stack_[top++] = {na.child[i], nb.child[std::countr_zero(hits)]};
        }
      } else {
        const Ref inner = is_leaf(a) ? b : a, leaf = is_leaf(a) ? a : b;
        const Node4& node = nodes_[std::size_t(inner)];
        uint32_t hits = children_overlapping(node, leaf_box_[std::size_t(leaf_of(leaf))]);
        for (; hits != 0; hits &= hits - 1) stack_[top++] = {node.child[std::countr_zero(hits)], leaf};
      }
    }
    return true;
  }

  // Also skip these triangle pairs from now on (pairs of triangles not in the tree are
  // ignored). Not real-time.
  void skip_pairs(std::span<const TrianglePair> pairs) { build_skip_masks(pairs); }

  std::span<const int32_t> slot_triangles() const noexcept { return slot_triangle_; }
  const std::array<int32_t, 3>& slot_vertices(int32_t slot) const noexcept { return slot_vertices_[std::size_t(slot)]; }
  int depth() const noexcept { return depth_; }

 private:
  // Bit t of row s of a leaf-pair mask stands for slot s of the first leaf and slot t of
  // the second.
  struct PairMask {
    uint16_t row[kMaxLeafSize] = {};
  };
  static_assert(kMaxLeafSize <= 16);
  static constexpr int32_t kSkipGroup = 16;  // skip_leaf_ entries compared at once (one AVX-512 register)

  struct BuildInput {
    std::vector<Vec3> centroid, lo, hi;  // per triangle (index into the input order)
    std::vector<int32_t> order;          // permutation, leaf order once built
  };
  struct BuildNode {
    int32_t left = -1, right = -1;  // children in the binary tree; -1 for a leaf
    int32_t first = 0, count = 0;   // range of `order` below this node
    double area = 0.0;              // half the surface area of its box
  };

  static double half_area(const Vec3& lo, const Vec3& hi) {
    const Vec3 d = hi - lo;
    return d.x() * d.y() + d.y() * d.z() + d.z() * d.x();
  }

  int32_t build_binary(BuildInput& in, std::vector<BuildNode>& out, int32_t begin, int32_t end) {
    const auto index = int32_t(out.size());
    out.emplace_back();
    out[std::size_t(index)].first = begin;
    out[std::size_t(index)].count = end - begin;
    Vec3 lo = in.lo[std::size_t(in.order[std::size_t(begin)])], hi = in.hi[std::size_t(in.order[std::size_t(begin)])];
    for (int32_t i = begin; i < end; ++i) {
      lo = lo.cwiseMin(in.lo[std::size_t(in.order[std::size_t(i)])]);
      hi = hi.cwiseMax(in.hi[std::size_t(in.order[std::size_t(i)])]);
    }
    out[std::size_t(index)].area = half_area(lo, hi);
    if (end - begin <= kMaxLeafSize) return index;
    // Surface area heuristic: sort by centroid on each axis, sweep every split.
    const int32_t n = end - begin;
    std::vector<int32_t> sorted(in.order.begin() + begin, in.order.begin() + end);
    std::vector<double> right_area(static_cast<std::size_t>(n));
    double best_cost = std::numeric_limits<double>::infinity();
    int best_axis = 0;
    int32_t best_split = n / 2;
    auto by_axis = [&](int axis) {
      return [&in, this, axis](int32_t x, int32_t y) {
        const double cx = in.centroid[std::size_t(x)][axis], cy = in.centroid[std::size_t(y)][axis];
        return cx < cy || (cx == cy && slot_triangle_[std::size_t(x)] < slot_triangle_[std::size_t(y)]);
      };
    };
    for (int axis = 0; axis < 3; ++axis) {
      std::sort(sorted.begin(), sorted.end(), by_axis(axis));
      Vec3 r_lo = in.lo[std::size_t(sorted.back())], r_hi = in.hi[std::size_t(sorted.back())];
      for (int32_t i = n - 1; i >= 0; --i) {
        r_lo = r_lo.cwiseMin(in.lo[std::size_t(sorted[std::size_t(i)])]);
        r_hi = r_hi.cwiseMax(in.hi[std::size_t(sorted[std::size_t(i)])]);
        right_area[std::size_t(i)] = half_area(r_lo, r_hi);
      }
      Vec3 l_lo = in.lo[std::size_t(sorted[0])], l_hi = in.hi[std::size_t(sorted[0])];
      for (int32_t split = 1; split < n; ++split) {
        l_lo = l_lo.cwiseMin(in.lo[std::size_t(sorted[std::size_t(split - 1)])]);
        l_hi = l_hi.cwiseMax(in.hi[std::size_t(sorted[std::size_t(split - 1)])]);
        const double cost = half_area(l_lo, l_hi) * split + right_area[std::size_t(split)] * (n - split);
        if (cost < best_cost) {
          best_cost = cost;
          best_axis = axis;
          best_split = split;
        }
      }
    }
    std::sort(in.order.begin() + begin, in.order.begin() + end, by_axis(best_axis));
    const int32_t left = build_binary(in, out, begin, begin + best_split);
    const int32_t right = build_binary(in, out, begin + best_split, end);
    out[std::size_t(index)].left = left;
    out[std::size_t(index)].right = right;
    return index;
  }

  // Turns binary node `index` into a four-wide node (pre-order: children after their
  // parent) by repeatedly opening the largest inner child; returns its reference.
  Ref collapse(const std::vector<BuildNode>& binary, int32_t index, int depth) {
    depth_ = std::max(depth_, depth);
    const BuildNode& b = binary[std::size_t(index)];
    if (b.left < 0) {
      leaves_.push_back({b.first, b.count});
      return ~int32_t(leaves_.size() - 1);
    }
    std::vector<int32_t> children{b.left, b.right};
    while (children.size() < std::size_t(kArity)) {
      int best = -1;
      for (int i = 0; i < int(children.size()); ++i) {
        const BuildNode& c = binary[std::size_t(children[std::size_t(i)])];
        if (c.left >= 0 && (best < 0 || c.area > binary[std::size_t(children[std::size_t(best)])].area)) best = i;
      }
      if (best < 0) break;
      const BuildNode& opened = binary[std::size_t(children[std::size_t(best)])];
      children[std::size_t(best)] = opened.left;
      children.insert(children.begin() + best + 1, opened.right);
    }
    const auto node = int32_t(nodes_.size());
    nodes_.emplace_back();
    const float inf = std::numeric_limits<float>::infinity();
    for (int k = 0; k < 3; ++k)
      for (int lane = 0; lane < kArity; ++lane) {
        nodes_[std::size_t(node)].lo[k][lane] = inf;
        nodes_[std::size_t(node)].hi[k][lane] = -inf;
      }
    nodes_[std::size_t(node)].child_count = int32_t(children.size());
    for (std::size_t i = 0; i < children.size(); ++i) {
      const Ref ref = collapse(binary, children[i], depth + 1);
      nodes_[std::size_t(node)].child[i] = ref;
    }
    return node;
  }

  // For every pair of leaves holding slot pairs to skip (triangles sharing a vertex, a
  // leaf with itself included, and the extra skipped pairs), which slot pairs those
  // are. Most box-overlapping pairs are such neighbours; the masks drop them without
  // looking at their boxes.
  void build_skip_masks(std::span<const TrianglePair> extra_skipped) {
    const auto leaf_count = int32_t(leaves_.size());
    std::vector<int32_t> slot_leaf(slot_triangle_.size());
    for (int32_t l = 0; l < leaf_count; ++l)
      for (int32_t s = 0; s < leaves_[std::size_t(l)].count; ++s) slot_leaf[std::size_t(leaves_[std::size_t(l)].first + s)] = l;
    std::vector<std::pair<int32_t, int32_t>> leaf_pairs;   // (leaf, leaf with pairs to skip), both ways
    std::vector<std::pair<int32_t, int32_t>> vertex_leaf;  // (vertex, leaf)
    for (std::size_t s = 0; s < slot_vertices_.size(); ++s)
      for (int32_t v : slot_vertices_[s]) vertex_leaf.emplace_back(v, slot_leaf[s]);
    std::sort(vertex_leaf.begin(), vertex_leaf.end());
    vertex_leaf.erase(std::unique(vertex_leaf.begin(), vertex_leaf.end()), vertex_leaf.end());
    for (std::size_t i = 0; i < vertex_leaf.size();) {
      std::size_t j = i;
      while (j < vertex_leaf.size() && vertex_leaf[j].first == vertex_leaf[i].first) ++j;
      for (std::size_t p = i; p < j; ++p)
        for (std::size_t q = i; q < j; ++q) leaf_pairs.emplace_back(vertex_leaf[p].second, vertex_leaf[q].second);
      i = j;
    }
    // Triangle -> slot, for the extra pairs (which name triangles).
    std::vector<std::pair<int32_t, int32_t>> triangle_slot(slot_triangle_.size());
    for (std::size_t s = 0; s < slot_triangle_.size(); ++s) triangle_slot[s] = {slot_triangle_[s], int32_t(s)};
    std::sort(triangle_slot.begin(), triangle_slot.end());
    auto slot_of = [&](int32_t triangle) {
      auto it = std::lower_bound(triangle_slot.begin(), triangle_slot.end(), std::pair<int32_t, int32_t>{triangle, INT32_MIN});
      return it != triangle_slot.end() && it->first == triangle ? it->second : -1;
    };
    std::vector<std::pair<int32_t, int32_t>> extra_slots;
    for (const TrianglePair& pair : extra_skipped) {
      const int32_t sa = slot_of(pair.first), sb = slot_of(pair.second);
      if (sa < 0 || sb < 0) continue;
      extra_slots.emplace_back(sa, sb);
      extra_slots.emplace_back(sb, sa);
      leaf_pairs.emplace_back(slot_leaf[std::size_t(sa)], slot_leaf[std::size_t(sb)]);
      leaf_pairs.emplace_back(slot_leaf[std::size_t(sb)], slot_leaf[std::size_t(sa)]);
    }
    std::sort(extra_slots.begin(), extra_slots.end());
    std::sort(leaf_pairs.begin(), leaf_pairs.end());
    leaf_pairs.erase(std::unique(leaf_pairs.begin(), leaf_pairs.end()), leaf_pairs.end());
    // Each leaf's list padded with -1 to whole groups of kSkipGroup, compared at once.
    skip_offset_.assign(std::size_t(leaf_count) + 1, 0);
    skip_leaf_.clear();
    skip_mask_.clear();
    std::size_t next = 0;
    for (int32_t a = 0; a < leaf_count; ++a) {
      skip_offset_[std::size_t(a)] = int32_t(skip_leaf_.size());
      for (; next < leaf_pairs.size() && leaf_pairs[next].first == a; ++next) {
        const int32_t b = leaf_pairs[next].second;
        const Leaf& la = leaves_[std::size_t(a)];
        const Leaf& lb = leaves_[std::size_t(b)];
        PairMask mask;
        for (int32_t s = 0; s < la.count; ++s)
          for (int32_t t = 0; t < lb.count; ++t) {
            const int32_t sa = la.first + s, sb = lb.first + t;
            if (share_vertex(slot_vertices_[std::size_t(sa)], slot_vertices_[std::size_t(sb)]) ||
                std::binary_search(extra_slots.begin(), extra_slots.end(), std::pair<int32_t, int32_t>{sa, sb}))
              mask.row[s] = uint16_t(mask.row[s] | (1u << t));
          }
        skip_leaf_.push_back(b);
        skip_mask_.push_back(mask);
      }
      while (skip_leaf_.size() % kSkipGroup != 0) {
        skip_leaf_.push_back(-1);
        skip_mask_.push_back({});
      }
    }
    skip_offset_[std::size_t(leaf_count)] = int32_t(skip_leaf_.size());
  }

  [[gnu::always_inline]] const PairMask& skip_mask(int32_t leaf_a, int32_t leaf_b) const noexcept {
    static constexpr PairMask kNone{};
    const int32_t end = skip_offset_[std::size_t(leaf_a) + 1];
    for (int32_t k = skip_offset_[std::size_t(leaf_a)]; k < end; k += kSkipGroup) {
#if defined(__AVX512F__)
      const __mmask16 hit = _mm512_cmpeq_epi32_mask(_mm512_loadu_si512(skip_leaf_.data() + k), _mm512_set1_epi32(leaf_b));
      if (hit != 0) return skip_mask_[std::size_t(k + std::countr_zero(unsigned(hit)))];
#else
      for (int32_t i = k; i < k + kSkipGroup; ++i)
        if (skip_leaf_[std::size_t(i)] == leaf_b) return skip_mask_[std::size_t(i)];
#endif
    }
    return kNone;
  }

  template <typename Visit>
  void visit_between_leaves(int32_t la, int32_t lb, Visit& visit) noexcept {
    const Leaf& a = leaves_[std::size_t(la)];
    const Leaf& b = leaves_[std::size_t(lb)];
    const LeafBoxes& boxes_a = leaf_boxes_[std::size_t(la)];
    const LeafBoxes& boxes_b = leaf_boxes_[std::size_t(lb)];
    // Only slots reaching into the other leaf's box can pair up.
    uint32_t a_slots = slots_overlapping(boxes_a, leaf_box_[std::size_t(lb)]);
    const uint32_t b_slots = slots_overlapping(boxes_b, leaf_box_[std::size_t(la)]);
    if (a_slots == 0 || b_slots == 0) return;
    const PairMask& skipped = skip_mask(la, lb);
    for (; a_slots != 0; a_slots &= a_slots - 1) {
      const int s = std::countr_zero(a_slots);
      uint32_t row = slots_overlapping(boxes_b, slot_box_[std::size_t(a.first + s)]) & b_slots & ~uint32_t(skipped.row[s]);
      for (; row != 0; row &= row - 1) visit(a.first + s, b.first + std::countr_zero(row));
    }
  }

  template <typename Visit>
  void visit_within_leaf(int32_t l, Visit& visit) noexcept {
    const Leaf& a = leaves_[std::size_t(l)];
    const LeafBoxes& boxes = leaf_boxes_[std::size_t(l)];
    const PairMask& skipped = skip_mask(l, l);
    for (int s = 0; s + 1 < a.count; ++s) {
      // Slots after s (unused lanes never overlap), not skipped.
      uint32_t row = slots_overlapping(boxes, slot_box_[std::size_t(a.first + s)]) & ~((2u << s) - 1) &
                     ~uint32_t(skipped.row[s]);
      for (; row != 0; row &= row - 1) visit(a.first + s, a.first + std::countr_zero(row));
    }
  }

  std::vector<Node4> nodes_;                          // pre-order: children after their parent
  std::vector<Box> node_box_;                         // per inner node: union of its children
  std::vector<Leaf> leaves_;
  std::vector<LeafBoxes> leaf_boxes_;                 // per leaf: its slots' boxes, refitted
  std::vector<Box> leaf_box_;                         // per leaf: union of its slots
  std::vector<Box> slot_box_;                         // per slot, the same boxes as leaf_boxes_
  Ref root_ = 0;
  std::vector<int32_t> slot_triangle_;                // triangle index per slot
  std::vector<std::array<int32_t, 3>> slot_vertices_;
  std::vector<int32_t> skip_offset_;                  // per leaf: range in skip_leaf_/skip_mask_
  std::vector<int32_t> skip_leaf_;                    // leaves with pairs to skip, ascending per leaf, then -1s
  std::vector<PairMask> skip_mask_;                   // slot pairs to skip
  std::vector<std::pair<Ref, Ref>> stack_;            // traversal scratch, sized at build
  int depth_ = 0;
};

// Pairs of `candidates` with a vertex of one within `edges` mesh edges of a vertex of the
// other, first < second, sorted and unique (pairs sharing a vertex included).
std::vector<TrianglePair> neighbour_pairs(const Eigen::Matrix3Xi& triangles, Eigen::Index vertex_count,
                                          std::span<const int32_t> candidates, int edges) {
  auto adjacent = std::vector<std::vector<int32_t>>(std::size_t(vertex_count));
  auto incident = std::vector<std::vector<int32_t>>(std::size_t(vertex_count));
  for (Eigen::Index t = 0; t < triangles.cols(); ++t)
    for (int k = 0; k < 3; ++k) {
      adjacent[std::size_t(triangles(k, t))].push_back(triangles((k + 1) % 3, t));
      adjacent[std::size_t(triangles((k + 1) % 3, t))].push_back(triangles(k, t));
    }
  for (int32_t t : candidates)
    for (int k = 0; k < 3; ++k) incident[std::size_t(triangles(k, t))].push_back(t);
  std::vector<TrianglePair> out;
  auto reached_by = std::vector<int32_t>(std::size_t(vertex_count), -1);
  std::vector<int32_t> reached, frontier;
  for (int32_t t : candidates) {
    reached.clear();
    for (int k = 0; k < 3; ++k)
      if (reached_by[std::size_t(triangles(k, t))] != t) {
        reached_by[std::size_t(triangles(k, t))] = t;
        reached.push_back(triangles(k, t));
      }
    std::size_t begin = 0;
    for (int depth = 0; depth < edges; ++depth) {
      const std::size_t end = reached.size();
      for (std::size_t i = begin; i < end; ++i)
        for (int32_t u : adjacent[std::size_t(reached[i])])
          if (reached_by[std::size_t(u)] != t) {
            reached_by[std::size_t(u)] = t;
            reached.push_back(u);
          }
      begin = end;
    }
    for (int32_t v : reached)
      for (int32_t u : incident[std::size_t(v)])
        if (u > t) out.push_back({t, u});
  }
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
  return out;
}

void check_triangles(const Eigen::Matrix3Xi& triangles, Eigen::Index vertex_count) {
  if (triangles.size() > 0 && (triangles.minCoeff() < 0 || triangles.maxCoeff() >= vertex_count))
    throw Error(fmt::format("triangle vertex indices must lie in [0, {})", vertex_count));
}

}  // namespace

// ---- Public geometry ---------------------------------------------------------------

double triangle_distance(const Vec3& a0, const Vec3& a1, const Vec3& a2, const Vec3& b0, const Vec3& b1,
                         const Vec3& b2) noexcept {
  const Vec3 a[3] = {a0, a1, a2}, b[3] = {b0, b1, b2};
  if (intersect_impl(a, b)) return 0.0;
  return std::sqrt(feature_distance_sq(a, b, 0.0));
}

bool triangles_intersect(const Vec3& a0, const Vec3& a1, const Vec3& a2, const Vec3& b0, const Vec3& b1,
                         const Vec3& b2) noexcept {
  const Vec3 a[3] = {a0, a1, a2}, b[3] = {b0, b1, b2};
  return intersect_impl(a, b);
}

bool triangles_closer_than(const Vec3& a0, const Vec3& a1, const Vec3& a2, const Vec3& b0, const Vec3& b1,
                           const Vec3& b2, double epsilon) noexcept {
  const Vec3 a[3] = {a0, a1, a2}, b[3] = {b0, b1, b2};
  return closer_than_impl(a, b, epsilon);
}

uint32_t triangles_closer_than(std::span<const TrianglePairCorners> pairs, double epsilon) noexcept {
  auto corner = [&](int lane, int k) -> const Vec3& { return k < 3 ? pairs[std::size_t(lane)].a[k] : pairs[std::size_t(lane)].b[k - 3]; };
  return closer_than_16(corner, int(std::min<std::size_t>(pairs.size(), kCloserBatch)), epsilon);
}

// ---- Candidate sets ----------------------------------------------------------------

std::vector<int> all_triangles(Eigen::Index triangle_count) {
  std::vector<int> out(std::size_t(std::max<Eigen::Index>(triangle_count, 0)));
  std::iota(out.begin(), out.end(), 0);
  return out;
}

std::vector<int> masked_triangles(const Eigen::Matrix3Xi& triangles, std::span<const uint8_t> vertex_mask) {
  check_triangles(triangles, Eigen::Index(vertex_mask.size()));
  std::vector<int> out;
  for (Eigen::Index t = 0; t < triangles.cols(); ++t)
    if (vertex_mask[std::size_t(triangles(0, t))] || vertex_mask[std::size_t(triangles(1, t))] ||
        vertex_mask[std::size_t(triangles(2, t))])
      out.push_back(int(t));
  return out;
}

namespace {

// Vertices bucketed in a uniform grid of cubes `cell` wide: radius queries up to `cell`
// look at 27 cells. Configuration time only.
class VertexGrid {
 public:
  VertexGrid(const Eigen::Matrix3Xd& points, double cell) : points_(points), cell_(cell) {
    entries_.reserve(std::size_t(points.cols()));
    for (Eigen::Index v = 0; v < points.cols(); ++v) entries_.push_back({key(cell_of(points.col(v))), int32_t(v)});
    std::sort(entries_.begin(), entries_.end());
  }

  // Calls visit(u) for every point within `radius` (<= cell) of p.
  template <typename Visit>
  void for_each_within(const Vec3& p, double radius, Visit&& visit) const {
    const Eigen::Vector3<int64_t> c = cell_of(p);
    const double radius_sq = radius * radius;
    for (int64_t dx = -1; dx <= 1; ++dx)
      for (int64_t dy = -1; dy <= 1; ++dy)
        for (int64_t dz = -1; dz <= 1; ++dz) {
          const uint64_t k = key(c + Eigen::Vector3<int64_t>(dx, dy, dz));
          auto it = std::lower_bound(entries_.begin(), entries_.end(), std::pair<uint64_t, int32_t>{k, INT32_MIN});
          for (; it != entries_.end() && it->first == k; ++it)
            if ((points_.col(it->second) - p).squaredNorm() <= radius_sq) visit(it->second);
        }
  }

 private:
  Eigen::Vector3<int64_t> cell_of(const Vec3& p) const {
    return (p / cell_).array().floor().cast<int64_t>();
  }
  static uint64_t key(const Eigen::Vector3<int64_t>& c) {
    // 21 bits per axis: plenty for a face in cells of a few mm.
    auto bits = [](int64_t x) { return uint64_t(x + (int64_t(1) << 20)) & ((uint64_t(1) << 21) - 1); };
    return (bits(c.x()) << 42) | (bits(c.y()) << 21) | bits(c.z());
  }
  const Eigen::Matrix3Xd& points_;
  double cell_;
  std::vector<std::pair<uint64_t, int32_t>> entries_;
};

bool starts_with_ignoring_case(const std::string& s, std::string_view prefix) {
  if (s.size() < prefix.size()) return false;
  for (std::size_t i = 0; i < prefix.size(); ++i)
    if (std::tolower(static_cast<unsigned char>(s[i])) != std::tolower(static_cast<unsigned char>(prefix[i]))) return false;
  return true;
}

bool is_mouth_shape(const std::string& name) {
  return starts_with_ignoring_case(name, "mouth") || starts_with_ignoring_case(name, "jaw");
}

Vec3 shape_delta(const Rig& rig, Eigen::Index shape, Eigen::Index vertex) {
  return rig.deltas.col(shape).segment<3>(3 * vertex);
}

}  // namespace

std::vector<int> triangles_near_vertices(const Eigen::Matrix3Xi& triangles, const Eigen::Matrix3Xd& rest_positions,
                                         std::span<const int> seed_vertices, double radius) {
  const Eigen::Index n = rest_positions.cols();
  check_triangles(triangles, n);
  if (!(radius > 0.0) || !std::isfinite(radius)) throw Error(fmt::format("radius {} must be a distance > 0", radius));
  std::vector<uint8_t> near(std::size_t(n), 0);
  const VertexGrid grid(rest_positions, radius);
  for (int s : seed_vertices) {
    if (s < 0 || s >= n) throw Error(fmt::format("seed vertex {} is not in [0, {})", s, n));
    grid.for_each_within(rest_positions.col(s), radius, [&](int32_t v) { near[std::size_t(v)] = 1; });
  }
  return masked_triangles(triangles, near);
}

std::vector<uint8_t> mouth_moving_vertices(const Rig& rig, double min_displacement) {
  const Eigen::Index n = rig.vertex_count();
  std::vector<uint8_t> mask(std::size_t(n), 0);
  for (Eigen::Index s = 0; s < rig.shape_count(); ++s) {
    if (!is_mouth_shape(rig.shape_names[std::size_t(s)])) continue;
    for (Eigen::Index v = 0; v < n; ++v)
      if (shape_delta(rig, s, v).norm() > min_displacement) mask[std::size_t(v)] = 1;
  }
  return mask;
}

std::vector<int> find_lip_vertices(const Rig& rig) {
  const Eigen::Index n = rig.vertex_count();
  const double diagonal = bounding_box(rig.neutral).size().norm();
  Eigen::Index jaw = -1;
  for (Eigen::Index s = 0; s < rig.shape_count(); ++s)
    if (starts_with_ignoring_case(rig.shape_names[std::size_t(s)], "jawOpen") &&
        rig.shape_names[std::size_t(s)].size() == 7)
      jaw = s;
  double mouth_max = 0.0;
  for (Eigen::Index s = 0; s < rig.shape_count(); ++s)
    if (is_mouth_shape(rig.shape_names[std::size_t(s)]))
      for (Eigen::Index v = 0; v < n; ++v) mouth_max = std::max(mouth_max, shape_delta(rig, s, v).norm());
  std::vector<int> lips;
  if (mouth_max <= 0.0) return lips;
  const std::vector<uint8_t> moving = mouth_moving_vertices(rig, 0.05 * mouth_max);
  if (jaw < 0) {
    for (Eigen::Index v = 0; v < n; ++v)
      if (moving[std::size_t(v)]) lips.push_back(int(v));
    return lips;
  }
  double jaw_max = 0.0;
  for (Eigen::Index v = 0; v < n; ++v) jaw_max = std::max(jaw_max, shape_delta(rig, jaw, v).norm());
  if (jaw_max <= 0.0) return lips;
  // The lips face each other across the mouth slit: near in space, yet the jaw
  // moves one of them much more than the other.
  const double near = kLipNeighbourhood * diagonal;
  const VertexGrid grid(rig.neutral, near);
  for (Eigen::Index v = 0; v < n; ++v) {
    if (!moving[std::size_t(v)]) continue;
    const Vec3 jaw_v = shape_delta(rig, jaw, v);
    bool across_slit = false;
    grid.for_each_within(rig.neutral.col(v), near, [&](int32_t u) {
      if (!across_slit && (shape_delta(rig, jaw, u) - jaw_v).norm() > kLipJawContrast * jaw_max) across_slit = true;
    });
    if (across_slit) lips.push_back(int(v));
  }
  return lips;
}

std::vector<int> lip_region_triangles(const Rig& rig, const LipRegionOptions& options) {
  const double diagonal = bounding_box(rig.neutral).size().norm();
  const double radius = options.radius > 0.0 ? options.radius : kLipRegionRadius * diagonal;
  const std::vector<int> seeds = options.lip_vertices.empty() ? find_lip_vertices(rig) : options.lip_vertices;
  if (seeds.empty())
    throw Error(fmt::format("rig '{}': no lip vertices found (no mouth*/jaw* shape moves any vertex); "
                            "give the lip vertices explicitly", rig.name));
  return triangles_near_vertices(rig.triangles, rig.neutral, seeds, radius);
}

// ---- TriangleCollider ------------------------------------------------------------

struct TriangleCollider::State {
  Bvh tree;
  ColliderConfig config;
  Eigen::Index vertex_count = 0;
  std::vector<int32_t> candidate_triangles;  // ascending
  std::vector<int32_t> candidate_vertices;   // ascending
  std::vector<TrianglePair> rest_contacts;   // sorted; left out when ignore_rest_contacts
  std::vector<uint32_t> vertex_stamp;        // N: frame stamp when a vertex was last collected
  uint32_t stamp = 0;
  int max_vertices = 0;
};

TriangleCollider::TriangleCollider() = default;
TriangleCollider::~TriangleCollider() = default;
TriangleCollider::TriangleCollider(TriangleCollider&&) noexcept = default;
TriangleCollider& TriangleCollider::operator=(TriangleCollider&&) noexcept = default;

void TriangleCollider::configure(const Eigen::Matrix3Xi& triangles, const Eigen::Matrix3Xd& rest_positions,
                                 std::span<const int> candidate_triangles, const ColliderConfig& config) {
  const Eigen::Index n = rest_positions.cols();
  check_triangles(triangles, n);
  if (!(config.epsilon >= 0.0) || !std::isfinite(config.epsilon))
    throw Error(fmt::format("collision epsilon {} must be a finite distance >= 0", config.epsilon));
  if (config.max_pairs < 0) throw Error(fmt::format("collision max_pairs {} must be >= 0", config.max_pairs));
  if (!rest_positions.allFinite()) throw Error("collision rest positions contain NaN or infinity");
  auto state = std::make_unique<State>();
  state->config = config;
  state->vertex_count = n;
  state->candidate_triangles.reserve(candidate_triangles.size());
  for (int t : candidate_triangles) {
    if (t < 0 || t >= triangles.cols())
      throw Error(fmt::format("candidate triangle {} is not in [0, {})", t, triangles.cols()));
    state->candidate_triangles.push_back(t);
  }
  std::sort(state->candidate_triangles.begin(), state->candidate_triangles.end());
  state->candidate_triangles.erase(std::unique(state->candidate_triangles.begin(), state->candidate_triangles.end()),
                                   state->candidate_triangles.end());
  for (int32_t t : state->candidate_triangles)
    for (int k = 0; k < 3; ++k) state->candidate_vertices.push_back(triangles(k, t));
  std::sort(state->candidate_vertices.begin(), state->candidate_vertices.end());
  state->candidate_vertices.erase(std::unique(state->candidate_vertices.begin(), state->candidate_vertices.end()),
                                  state->candidate_vertices.end());
  const auto all_vertices = int(state->candidate_vertices.size());
  state->max_vertices = config.max_vertices < 0 ? all_vertices : std::min(config.max_vertices, all_vertices);
  state->vertex_stamp.assign(std::size_t(n), 0);
  if (config.neighbour_edges < 0) throw Error(fmt::format("collision neighbour_edges {} must be >= 0", config.neighbour_edges));
  state->tree.build(triangles, rest_positions, state->candidate_triangles);
  std::vector<TrianglePair> skipped;
  if (config.neighbour_edges > 0) {
    skipped = neighbour_pairs(triangles, n, state->candidate_triangles, config.neighbour_edges);
    state->tree.skip_pairs(skipped);
  }
  if (config.ignore_rest_contacts) {
    State& s = *state;
    s.tree.refit(rest_positions, 0.5 * config.epsilon);
    s.tree.for_each_overlapping_pair([&](int32_t slot_a, int32_t slot_b) {
      const auto& va = s.tree.slot_vertices(slot_a);
      const auto& vb = s.tree.slot_vertices(slot_b);
      const Vec3 a[3] = {rest_positions.col(va[0]), rest_positions.col(va[1]), rest_positions.col(va[2])};
      const Vec3 b[3] = {rest_positions.col(vb[0]), rest_positions.col(vb[1]), rest_positions.col(vb[2])};
      if (!closer_than_impl(a, b, config.epsilon)) return;
      const int32_t ta = s.tree.slot_triangles()[std::size_t(slot_a)], tb = s.tree.slot_triangles()[std::size_t(slot_b)];
      s.rest_contacts.push_back({std::min(ta, tb), std::max(ta, tb)});
    });
    std::sort(s.rest_contacts.begin(), s.rest_contacts.end());
    skipped.insert(skipped.end(), s.rest_contacts.begin(), s.rest_contacts.end());
    s.tree.skip_pairs(skipped);
  }
  state_ = std::move(state);
}

CollisionResult TriangleCollider::make_result() const {
  CollisionResult out;
  if (!state_) return out;
  out.pairs.resize(std::size_t(state_->config.max_pairs));
  out.vertices.resize(std::size_t(state_->max_vertices));
  return out;
}

bool TriangleCollider::detect(const Eigen::Ref<const Eigen::Matrix3Xd>& positions, CollisionResult& out) noexcept {
  out.pair_count = out.vertex_count = out.pairs_found = out.vertices_found = 0;
  if (!state_ || positions.cols() != state_->vertex_count) return false;
  State& s = *state_;
  // A NaN would poison the boxes above it and hide other pairs: refuse the frame.
  for (int32_t v : s.candidate_vertices)
    if (!positions.col(v).allFinite()) return false;
  const auto pair_capacity = int32_t(std::min<std::size_t>(out.pairs.size(), std::size_t(s.config.max_pairs)));
  const auto vertex_capacity = int32_t(std::min<std::size_t>(out.vertices.size(), std::size_t(s.max_vertices)));
  if (++s.stamp == 0) {  // wrapped: forget every old stamp
    std::fill(s.vertex_stamp.begin(), s.vertex_stamp.end(), 0u);
    s.stamp = 1;
  }
  const double epsilon = s.config.epsilon;
  s.tree.refit(positions, 0.5 * epsilon);  // boxes closer than epsilon overlap
  auto collect_vertex = [&](int32_t v) {
    if (s.vertex_stamp[std::size_t(v)] == s.stamp) return;
    s.vertex_stamp[std::size_t(v)] = s.stamp;
    if (out.vertex_count < vertex_capacity) out.vertices[std::size_t(out.vertex_count++)] = v;
    ++out.vertices_found;
  };
  const auto slot_triangles = s.tree.slot_triangles();
  // Candidates are tested kCloserBatch at a time.
  std::array<int32_t, 2> batch_slots[kCloserBatch];
  int batched = 0;
  auto corner = [&](int lane, int k) {
    return Vec3(positions.col(s.tree.slot_vertices(batch_slots[lane][std::size_t(k / 3)])[std::size_t(k % 3)]));
  };
  auto test_batch = [&] {
    for (uint32_t close = closer_than_16(corner, batched, epsilon); close != 0; close &= close - 1) {
      const auto [slot_a, slot_b] = batch_slots[std::countr_zero(close)];
      const int32_t ta = slot_triangles[std::size_t(slot_a)], tb = slot_triangles[std::size_t(slot_b)];
      if (out.pair_count < pair_capacity) out.pairs[std::size_t(out.pair_count++)] = {std::min(ta, tb), std::max(ta, tb)};
      ++out.pairs_found;
      for (int k = 0; k < 3; ++k) {
        collect_vertex(s.tree.slot_vertices(slot_a)[std::size_t(k)]);
        collect_vertex(s.tree.slot_vertices(slot_b)[std::size_t(k)]);
      }
    }
    batched = 0;
  };
  const bool complete = s.tree.for_each_overlapping_pair([&](int32_t slot_a, int32_t slot_b) {
    batch_slots[batched] = {slot_a, slot_b};
    if (++batched == kCloserBatch) test_batch();
  });
  test_batch();
  // std::sort is in place (introsort): no allocation.
  std::sort(out.pairs.begin(), out.pairs.begin() + out.pair_count);
  std::sort(out.vertices.begin(), out.vertices.begin() + out.vertex_count);
  if (!complete) {
    // Unreachable by construction; report it as an overflow rather than a clean frame.
    out.pairs_found = std::max(out.pairs_found, out.pair_count + 1);
  }
  return true;
}

bool TriangleCollider::configured() const noexcept { return state_ != nullptr; }
double TriangleCollider::epsilon() const noexcept { return state_ ? state_->config.epsilon : 0.0; }
Eigen::Index TriangleCollider::vertex_count() const noexcept { return state_ ? state_->vertex_count : 0; }
std::span<const int32_t> TriangleCollider::candidate_triangles() const noexcept {
  return state_ ? std::span<const int32_t>(state_->candidate_triangles) : std::span<const int32_t>();
}
std::span<const int32_t> TriangleCollider::candidate_vertices() const noexcept {
  return state_ ? std::span<const int32_t>(state_->candidate_vertices) : std::span<const int32_t>();
}
int TriangleCollider::tree_depth() const noexcept { return state_ ? state_->tree.depth() : 0; }
std::span<const TrianglePair> TriangleCollider::rest_contacts() const noexcept {
  return state_ ? std::span<const TrianglePair>(state_->rest_contacts) : std::span<const TrianglePair>();
}

// ---- Metrics ---------------------------------------------------------------------

struct IntersectionCounter::State {
  Bvh tree;
  Eigen::Index vertex_count = 0;
};

IntersectionCounter::IntersectionCounter() = default;
IntersectionCounter::~IntersectionCounter() = default;
IntersectionCounter::IntersectionCounter(IntersectionCounter&&) noexcept = default;
IntersectionCounter& IntersectionCounter::operator=(IntersectionCounter&&) noexcept = default;

void IntersectionCounter::configure(const Eigen::Matrix3Xi& triangles, const Eigen::Matrix3Xd& rest_positions) {
  check_triangles(triangles, rest_positions.cols());
  auto state = std::make_unique<State>();
  state->vertex_count = rest_positions.cols();
  std::vector<int32_t> every(std::size_t(triangles.cols()));
  std::iota(every.begin(), every.end(), 0);
  state->tree.build(triangles, rest_positions, every);
  state_ = std::move(state);
}

template <typename Found>
void IntersectionCounter::for_each(const Eigen::Matrix3Xd& positions, Found&& found) {
  if (!state_) throw Error("intersection counter used before configure()");
  if (positions.cols() != state_->vertex_count)
    throw Error(fmt::format("intersection counter configured for {} vertices, given {}", state_->vertex_count,
                            positions.cols()));
  Bvh& tree = state_->tree;
  tree.refit(positions, 0.0);  // touching boxes still overlap
  const auto slot_triangles = tree.slot_triangles();
  tree.for_each_overlapping_pair([&](int32_t slot_a, int32_t slot_b) {
    const auto& va = tree.slot_vertices(slot_a);
    const auto& vb = tree.slot_vertices(slot_b);
    const Vec3 a[3] = {positions.col(va[0]), positions.col(va[1]), positions.col(va[2])};
    const Vec3 b[3] = {positions.col(vb[0]), positions.col(vb[1]), positions.col(vb[2])};
    if (!intersect_impl(a, b)) return;
    const int32_t ta = slot_triangles[std::size_t(slot_a)], tb = slot_triangles[std::size_t(slot_b)];
    found(TrianglePair{std::min(ta, tb), std::max(ta, tb)});
  });
}

int64_t IntersectionCounter::count(const Eigen::Matrix3Xd& positions) {
  int64_t n = 0;
  for_each(positions, [&](const TrianglePair&) { ++n; });
  return n;
}

std::vector<TrianglePair> IntersectionCounter::pairs(const Eigen::Matrix3Xd& positions) {
  std::vector<TrianglePair> out;
  for_each(positions, [&](const TrianglePair& p) { out.push_back(p); });
  std::sort(out.begin(), out.end());
  return out;
}

std::vector<TrianglePair> intersecting_pairs(const Eigen::Matrix3Xi& triangles, const Eigen::Matrix3Xd& positions) {
  IntersectionCounter counter;
  counter.configure(triangles, positions);
  return counter.pairs(positions);
}

int64_t count_intersecting_pairs(const Eigen::Matrix3Xi& triangles, const Eigen::Matrix3Xd& positions) {
  IntersectionCounter counter;
  counter.configure(triangles, positions);
  return counter.count(positions);
}

int64_t count_new_intersecting_pairs(const Eigen::Matrix3Xi& triangles, const Eigen::Matrix3Xd& rest_positions,
                                     const Eigen::Matrix3Xd& positions) {
  if (rest_positions.cols() != positions.cols())
    throw Error(fmt::format("new intersections: rest has {} vertices, positions {}", rest_positions.cols(),
                            positions.cols()));
  IntersectionCounter counter;
  counter.configure(triangles, rest_positions);
  const auto now = counter.pairs(positions);
  const auto at_rest = counter.pairs(rest_positions);
  std::vector<TrianglePair> fresh;
  std::set_difference(now.begin(), now.end(), at_rest.begin(), at_rest.end(), std::back_inserter(fresh));
  return int64_t(fresh.size());
}

int64_t count_flipped_triangles(const Eigen::Matrix3Xi& triangles, const Eigen::Matrix3Xd& rest_positions,
                                const Eigen::Matrix3Xd& positions) {
  if (rest_positions.cols() != positions.cols())
    throw Error(fmt::format("flipped triangles: rest has {} vertices, positions {}", rest_positions.cols(),
                            positions.cols()));
  check_triangles(triangles, positions.cols());
  int64_t flipped = 0;
  for (Eigen::Index t = 0; t < triangles.cols(); ++t) {
    auto normal = [&](const Eigen::Matrix3Xd& x) {
      const Vec3 p0 = x.col(triangles(0, t));
      return Vec3((x.col(triangles(1, t)) - p0).cross(x.col(triangles(2, t)) - p0));
    };
    if (normal(rest_positions).dot(normal(positions)) < 0.0) ++flipped;
  }
  return flipped;
}

}  // namespace facecap
