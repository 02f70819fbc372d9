#include "solver/collide/lip_region.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <numeric>
#include <string>
#include <string_view>

#include <fmt/format.h>

#include "core/error.hpp"
#include "solver/mesh_topology.hpp"

namespace facecap {
namespace {

using Vec3 = Eigen::Vector3d;

// Automatic lip detection, as fractions of the neutral's bounding-box diagonal or of
// jawOpen's largest displacement (see lip_region_triangles).
constexpr double kLipNeighbourhood = 0.02;
constexpr double kLipJawContrast = 0.5;
constexpr double kLipRegionRadius = 0.03;

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

std::vector<int> all_triangles(Eigen::Index triangle_count) {
  std::vector<int> out(std::size_t(std::max<Eigen::Index>(triangle_count, 0)));
  std::iota(out.begin(), out.end(), 0);
  return out;
}

std::vector<int> masked_triangles(const Eigen::Matrix3Xi& triangles, std::span<const uint8_t> vertex_mask) {
  check_triangle_indices(triangles, Eigen::Index(vertex_mask.size()));
  std::vector<int> out;
  for (Eigen::Index t = 0; t < triangles.cols(); ++t)
    if (vertex_mask[std::size_t(triangles(0, t))] || vertex_mask[std::size_t(triangles(1, t))] ||
        vertex_mask[std::size_t(triangles(2, t))])
      out.push_back(int(t));
  return out;
}

std::vector<int> triangles_near_vertices(const Eigen::Matrix3Xi& triangles, const Eigen::Matrix3Xd& rest_positions,
                                         std::span<const int> seed_vertices, double radius) {
  const Eigen::Index n = rest_positions.cols();
  check_triangle_indices(triangles, n);
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

}  // namespace facecap
