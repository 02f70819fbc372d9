#include "tools/mesh_checks.hpp"

#include <algorithm>
#include <array>
#include <numeric>
#include <vector>

#include <Eigen/Geometry>

namespace facecap::tools {
namespace {

using V3 = Eigen::Vector3d;
using V2 = Eigen::Vector2d;

// Six times the signed volume of (a, b, c, d): > 0 when d is on the side of abc's normal.
double orient3d(const V3& a, const V3& b, const V3& c, const V3& d) { return (b - a).cross(c - a).dot(d - a); }

double orient2d(const V2& a, const V2& b, const V2& c) {
  return (b.x() - a.x()) * (c.y() - a.y()) - (b.y() - a.y()) * (c.x() - a.x());
}

bool same_sign_or_zero(double a, double b, double c) {
  return (a >= 0 && b >= 0 && c >= 0) || (a <= 0 && b <= 0 && c <= 0);
}

// Closed 2D segments pq and rs share a point.
bool segments_intersect_2d(const V2& p, const V2& q, const V2& r, const V2& s) {
  const double d1 = orient2d(r, s, p), d2 = orient2d(r, s, q), d3 = orient2d(p, q, r), d4 = orient2d(p, q, s);
  if (((d1 > 0 && d2 < 0) || (d1 < 0 && d2 > 0)) && ((d3 > 0 && d4 < 0) || (d3 < 0 && d4 > 0))) return true;
  auto on_segment = [](const V2& a, const V2& b, const V2& x) {
    return std::min(a.x(), b.x()) <= x.x() && x.x() <= std::max(a.x(), b.x()) && std::min(a.y(), b.y()) <= x.y() &&
           x.y() <= std::max(a.y(), b.y());
  };
  return (d1 == 0 && on_segment(r, s, p)) || (d2 == 0 && on_segment(r, s, q)) || (d3 == 0 && on_segment(p, q, r)) ||
         (d4 == 0 && on_segment(p, q, s));
}

bool point_in_triangle_2d(const V2& x, const V2& a, const V2& b, const V2& c) {
  return same_sign_or_zero(orient2d(a, b, x), orient2d(b, c, x), orient2d(c, a, x));
}

// Drops the coordinate along the normal's largest component.
std::array<int, 2> projection_axes(const V3& normal) {
  const V3 n = normal.cwiseAbs();
  if (n.x() >= n.y() && n.x() >= n.z()) return {1, 2};
  if (n.y() >= n.z()) return {0, 2};
  return {0, 1};
}

// Closed 2D triangles share a point.
bool triangles_intersect_2d(const std::array<V2, 3>& a, const std::array<V2, 3>& b) {
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      if (segments_intersect_2d(a[i], a[(i + 1) % 3], b[j], b[(j + 1) % 3])) return true;
  return point_in_triangle_2d(a[0], b[0], b[1], b[2]) || point_in_triangle_2d(b[0], a[0], a[1], a[2]);
}

// Closed segment pq and closed triangle abc share a point.
bool segment_meets_triangle(const V3& p, const V3& q, const V3& a, const V3& b, const V3& c) {
  const double sp = orient3d(a, b, c, p), sq = orient3d(a, b, c, q);
  if ((sp > 0 && sq > 0) || (sp < 0 && sq < 0)) return false;
  if (sp == 0 && sq == 0) {  // the segment lies in the triangle's plane
    const auto axes = projection_axes((b - a).cross(c - a));
    auto flat = [&](const V3& v) { return V2(v[axes[0]], v[axes[1]]); };
    const V2 p2 = flat(p), q2 = flat(q), a2 = flat(a), b2 = flat(b), c2 = flat(c);
    return point_in_triangle_2d(p2, a2, b2, c2) || segments_intersect_2d(p2, q2, a2, b2) ||
           segments_intersect_2d(p2, q2, b2, c2) || segments_intersect_2d(p2, q2, c2, a2);
  }
  return same_sign_or_zero(orient3d(p, q, a, b), orient3d(p, q, b, c), orient3d(p, q, c, a));
}

}  // namespace

bool closed_triangles_intersect(const V3& a0, const V3& a1, const V3& a2, const V3& b0, const V3& b1, const V3& b2) {
  const double da0 = orient3d(b0, b1, b2, a0), da1 = orient3d(b0, b1, b2, a1), da2 = orient3d(b0, b1, b2, a2);
  if ((da0 > 0 && da1 > 0 && da2 > 0) || (da0 < 0 && da1 < 0 && da2 < 0)) return false;
  const double db0 = orient3d(a0, a1, a2, b0), db1 = orient3d(a0, a1, a2, b1), db2 = orient3d(a0, a1, a2, b2);
  if ((db0 > 0 && db1 > 0 && db2 > 0) || (db0 < 0 && db1 < 0 && db2 < 0)) return false;
  if (da0 == 0 && da1 == 0 && da2 == 0) {  // coplanar
    const V3 n = (b1 - b0).cross(b2 - b0);
    const auto axes = projection_axes(n.squaredNorm() > 0 ? n : V3((a1 - a0).cross(a2 - a0)));
    auto flat = [&](const V3& v) { return V2(v[axes[0]], v[axes[1]]); };
    return triangles_intersect_2d({flat(a0), flat(a1), flat(a2)}, {flat(b0), flat(b1), flat(b2)});
  }
  // Otherwise the intersection, if any, ends on an edge of one triangle inside the other.
  return segment_meets_triangle(a0, a1, b0, b1, b2) || segment_meets_triangle(a1, a2, b0, b1, b2) ||
         segment_meets_triangle(a2, a0, b0, b1, b2) || segment_meets_triangle(b0, b1, a0, a1, a2) ||
         segment_meets_triangle(b1, b2, a0, a1, a2) || segment_meets_triangle(b2, b0, a0, a1, a2);
}

std::vector<std::pair<int, int>> intersecting_triangle_pairs(const Eigen::Matrix3Xi& triangles,
                                                             const Eigen::Matrix3Xd& positions) {
  std::vector<std::pair<int, int>> out;
  const Eigen::Index T = triangles.cols();
  if (T < 2) return out;
  Eigen::Matrix3Xd lo(3, T), hi(3, T);
  for (Eigen::Index t = 0; t < T; ++t) {
    const V3 a = positions.col(triangles(0, t)), b = positions.col(triangles(1, t)), c = positions.col(triangles(2, t));
    lo.col(t) = a.cwiseMin(b).cwiseMin(c);
    hi.col(t) = a.cwiseMax(b).cwiseMax(c);
  }
  int axis = 0;
  (positions.rowwise().maxCoeff() - positions.rowwise().minCoeff()).maxCoeff(&axis);
  std::vector<int> order(static_cast<std::size_t>(T));
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(), [&](int a, int b) { return lo(axis, a) < lo(axis, b); });
  const int other0 = (axis + 1) % 3, other1 = (axis + 2) % 3;
  for (std::size_t a = 0; a < order.size(); ++a) {
    const int i = order[a];
    const Eigen::Vector3i ti = triangles.col(i);
    for (std::size_t b = a + 1; b < order.size() && lo(axis, order[b]) <= hi(axis, i); ++b) {
      const int j = order[b];
      if (lo(other0, j) > hi(other0, i) || hi(other0, j) < lo(other0, i) || lo(other1, j) > hi(other1, i) ||
          hi(other1, j) < lo(other1, i))
        continue;
      const Eigen::Vector3i tj = triangles.col(j);
      bool shared = false;
      for (int p = 0; p < 3 && !shared; ++p)
        for (int q = 0; q < 3; ++q)
          if (ti[p] == tj[q]) { shared = true; break; }
      if (shared) continue;
      if (closed_triangles_intersect(positions.col(ti[0]), positions.col(ti[1]), positions.col(ti[2]),
                                     positions.col(tj[0]), positions.col(tj[1]), positions.col(tj[2])))
        out.emplace_back(std::min(i, j), std::max(i, j));
    }
  }
  std::sort(out.begin(), out.end());
  return out;
}

int64_t count_intersecting_triangle_pairs(const Eigen::Matrix3Xi& triangles, const Eigen::Matrix3Xd& positions) {
  return int64_t(intersecting_triangle_pairs(triangles, positions).size());
}

int64_t count_flipped_triangles_against_rest(const Eigen::Matrix3Xi& triangles, const Eigen::Matrix3Xd& rest_positions,
                                             const Eigen::Matrix3Xd& positions) {
  int64_t count = 0;
  for (Eigen::Index t = 0; t < triangles.cols(); ++t) {
    const int a = triangles(0, t), b = triangles(1, t), c = triangles(2, t);
    const V3 rest = (rest_positions.col(b) - rest_positions.col(a)).cross(rest_positions.col(c) - rest_positions.col(a));
    const V3 now = (positions.col(b) - positions.col(a)).cross(positions.col(c) - positions.col(a));
    if (rest.squaredNorm() == 0 || now.squaredNorm() == 0) continue;
    if (rest.dot(now) < 0) ++count;
  }
  return count;
}

}  // namespace facecap::tools
