#include "solver/marker_layout.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

#include <fmt/format.h>

#include "core/error.hpp"
#include "solver/mesh_topology.hpp"

namespace facecap {

std::vector<MarkerBinding> spread_marker_layout(const Rig& rig, int count) {
  const Eigen::Index n = rig.vertex_count();
  if (count <= 0 || count > n) throw Error(fmt::format("marker count {} must be between 1 and the rig's {} vertices", count, n));
  // Border vertices (on an edge used by one triangle) sit on the mesh's cut and are
  // where real markers never go; vertices no shape moves carry no information.
  std::vector<uint8_t> usable(std::size_t(n), 1);
  {
    for (const auto& [a, b] : boundary_edges(rig.triangles)) usable[std::size_t(a)] = usable[std::size_t(b)] = 0;
    for (Eigen::Index v = 0; v < n; ++v) {
      double motion = 0.0;
      for (Eigen::Index s = 0; s < rig.shape_count(); ++s) motion = std::max(motion, rig.deltas.col(s).segment<3>(3 * v).norm());
      if (motion < 1e-6) usable[std::size_t(v)] = 0;
    }
  }
  // Start at the usable vertex nearest the front of the face's centre.
  const BoundingBox box = bounding_box(rig.neutral);
  const Eigen::Vector3d front((box.min.x() + box.max.x()) / 2, (box.min.y() + box.max.y()) / 2, box.max.z());
  Eigen::Index first = -1;
  double best = 1e300;
  for (Eigen::Index v = 0; v < n; ++v)
    if (usable[std::size_t(v)] && (rig.neutral.col(v) - front).squaredNorm() < best) {
      best = (rig.neutral.col(v) - front).squaredNorm();
      first = v;
    }
  if (first < 0) throw Error("no vertex of the rig moves with any shape: cannot place markers");
  Eigen::VectorXd distance = Eigen::VectorXd::Constant(n, 1e300);
  std::vector<MarkerBinding> layout;
  Eigen::Index next = first;
  for (int m = 0; m < count; ++m) {
    layout.push_back(MarkerBinding::at_vertex(fmt::format("M{:03d}", m), int(next)));
    for (Eigen::Index v = 0; v < n; ++v)
      distance[v] = std::min(distance[v], (rig.neutral.col(v) - rig.neutral.col(next)).squaredNorm());
    double farthest = -1.0;
    for (Eigen::Index v = 0; v < n; ++v)
      if (usable[std::size_t(v)] && distance[v] > farthest) { farthest = distance[v]; next = v; }
    if (farthest <= 0.0) throw Error(fmt::format("the rig has only {} usable marker vertices, {} asked", m + 1, count));
  }
  return layout;
}

std::vector<MarkerBinding> vertex_marker_layout(const std::vector<int>& vertices) {
  std::vector<MarkerBinding> layout;
  for (int v : vertices) layout.push_back(MarkerBinding::at_vertex(fmt::format("V{}", v), v));
  return layout;
}

std::vector<std::string> MarkerSet::labels() const {
  std::vector<std::string> out;
  out.reserve(face.size() + head.size());
  for (const auto& b : face) out.push_back(b.label);
  for (const auto& h : head) out.push_back(h.label);
  return out;
}

MarkerSet default_marker_set(const Rig& rig, int face_markers, int head_markers) {
  if (head_markers != 0 && head_markers < 3)
    throw Error(fmt::format("head stabilisation needs at least 3 head markers, {} asked (0 turns it off)", head_markers));
  MarkerSet set;
  set.face = spread_marker_layout(rig, face_markers);
  // A rigid head rig: points on an arc across the front of the head, alternating between
  // above the brow and temple height (and depth), so that the rigid fit is well
  // conditioned about every axis, not only about the vertical.
  const BoundingBox box = bounding_box(rig.neutral);
  const Eigen::Vector3d size = box.size();
  const double centre_x = 0.5 * (box.min.x() + box.max.x());
  const double centre_z = 0.5 * (box.min.z() + box.max.z());
  for (int i = 0; i < head_markers; ++i) {
    const double angle = std::numbers::pi * (0.15 + 0.7 * (i + 0.5) / head_markers);
    const bool high = i % 2 == 0;
    const Eigen::Vector3d p(centre_x - 0.55 * size.x() * std::cos(angle),
                            box.max.y() + (high ? 0.1 : -0.3) * size.y(),
                            centre_z + 0.5 * size.z() * std::sin(angle) - (high ? 0.0 : 0.6) * size.z());
    set.head.push_back({fmt::format("H{}", i), p});
  }
  return set;
}

}  // namespace facecap
