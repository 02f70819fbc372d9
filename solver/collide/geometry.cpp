#include "solver/collide/geometry.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

#include <Eigen/Geometry>

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

}  // namespace

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

}  // namespace facecap
