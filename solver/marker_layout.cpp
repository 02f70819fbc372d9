#include "solver/marker_layout.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

#include <fmt/format.h>

#include "core/error.hpp"
#include "solver/align/calibration.hpp"
#include "solver/mesh_topology.hpp"

namespace facecap {

namespace {

// Vertices a marker may sit on: not on the mesh's border (an edge used by one triangle: the
// mesh's cut, where real markers never go), and moved by some shape (else it carries no
// information).
std::vector<uint8_t> marker_vertices(const Rig& rig) {
  const Eigen::Index n = rig.vertex_count();
  std::vector<uint8_t> usable(std::size_t(n), 1);
  for (const auto& [a, b] : boundary_edges(rig.triangles)) usable[std::size_t(a)] = usable[std::size_t(b)] = 0;
  for (Eigen::Index v = 0; v < n; ++v) {
    double motion = 0.0;
    for (Eigen::Index s = 0; s < rig.shape_count(); ++s) motion = std::max(motion, rig.deltas.col(s).segment<3>(3 * v).norm());
    if (motion < 1e-6) usable[std::size_t(v)] = 0;
  }
  return usable;
}

// Adds markers at usable vertices, each the farthest from those already in `layout` and the
// `taken` points, until it holds `count`; with no marker yet, it starts at the usable vertex
// nearest the front of the face's centre. Labels "M000", ... in order.
void add_farthest_markers(const Rig& rig, const std::vector<uint8_t>& usable, int count, std::span<const Eigen::Vector3d> taken,
                          std::vector<MarkerBinding>& layout) {
  const Eigen::Index n = rig.vertex_count();
  Eigen::VectorXd distance = Eigen::VectorXd::Constant(n, 1e300);
  auto note_point = [&](const Eigen::Vector3d& point) {
    for (Eigen::Index v = 0; v < n; ++v) distance[v] = std::min(distance[v], (rig.neutral.col(v) - point).squaredNorm());
  };
  auto note = [&](Eigen::Index marker) { note_point(rig.neutral.col(marker)); };
  for (const Eigen::Vector3d& point : taken) note_point(point);
  for (const MarkerBinding& b : layout) note(b.vertices[0]);
  if (layout.empty()) {
    const BoundingBox box = bounding_box(rig.neutral);
    const Eigen::Vector3d front((box.min.x() + box.max.x()) / 2, (box.min.y() + box.max.y()) / 2, box.max.z());
    Eigen::Index first = -1;
    for (Eigen::Index v = 0; v < n; ++v)
      if (usable[std::size_t(v)] &&
          (first < 0 || (rig.neutral.col(v) - front).squaredNorm() < (rig.neutral.col(first) - front).squaredNorm()))
        first = v;
    if (first < 0) throw Error("no vertex of the rig moves with any shape: cannot place markers");
    layout.push_back(MarkerBinding::at_vertex("M000", int(first)));
    note(first);
  }
  while (int(layout.size()) < count) {
    Eigen::Index next = -1;
    for (Eigen::Index v = 0; v < n; ++v)
      if (usable[std::size_t(v)] && distance[v] > 0.0 && (next < 0 || distance[v] > distance[next])) next = v;
    if (next < 0) throw Error(fmt::format("the rig has only {} usable marker vertices, {} asked", layout.size(), count));
    layout.push_back(MarkerBinding::at_vertex(fmt::format("M{:03d}", layout.size()), int(next)));
    note(next);
  }
}

}  // namespace

std::vector<MarkerBinding> spread_marker_layout(const Rig& rig, int count) {
  const Eigen::Index n = rig.vertex_count();
  if (count <= 0 || count > n) throw Error(fmt::format("marker count {} must be between 1 and the rig's {} vertices", count, n));
  std::vector<MarkerBinding> layout;
  add_farthest_markers(rig, marker_vertices(rig), count, {}, layout);
  return layout;
}

std::vector<MarkerBinding> observing_marker_layout(const Rig& rig, int count, double observable_mm,
                                                   std::span<const Eigen::Vector3d> taken) {
  const Eigen::Index n = rig.vertex_count(), shapes = rig.shape_count();
  if (count <= 0 || count > n) throw Error(fmt::format("marker count {} must be between 1 and the rig's {} vertices", count, n));
  const std::vector<uint8_t> usable = marker_vertices(rig);
  const double units_per_mm = rig_units_per_mm(rig);
  const double threshold = observable_mm * units_per_mm, spacing = kObservingMarkerSpacingMm * units_per_mm;
  Eigen::MatrixXd motion(n, shapes);  // rig units at weight 1
  for (Eigen::Index s = 0; s < shapes; ++s)
    for (Eigen::Index v = 0; v < n; ++v) motion(v, s) = usable[std::size_t(v)] ? rig.deltas.col(s).segment<3>(3 * v).norm() : 0.0;
  // A marker observes a shape that moves it by half as much again as the threshold (room for
  // a real calibration's binding error), or, for a shape that moves no vertex that far, by
  // 90% of its largest motion, at least the threshold; a shape below it everywhere is left out.
  Eigen::VectorXd observing(shapes);
  std::vector<uint8_t> covered(std::size_t(shapes), 0);
  for (Eigen::Index s = 0; s < shapes; ++s) {
    observing[s] = std::max(threshold, std::min(1.5 * threshold, 0.9 * motion.col(s).maxCoeff()));
    covered[std::size_t(s)] = motion.col(s).maxCoeff() < observing[s];
  }
  std::vector<MarkerBinding> layout;
  // Two markers stay a spacing apart at rest and half of it at any shape's full weight (a
  // blink brings an upper-lid marker down onto the lower lid: cameras see one blob).
  // Whether vertex v crowds a point at `rest` that shape s moves by other_delta(s).
  auto crowds = [&](Eigen::Index v, const Eigen::Vector3d& rest, auto other_delta) {
    if ((rig.neutral.col(v) - rest).norm() < spacing) return true;
    for (Eigen::Index s = 0; s < shapes; ++s)
      if ((rig.neutral.col(v) + rig.deltas.col(s).segment<3>(3 * v) - rest - other_delta(s)).norm() < 0.5 * spacing)
        return true;
    return false;
  };
  auto apart = [&](Eigen::Index v) {
    const auto rigid = [](Eigen::Index) { return Eigen::Vector3d::Zero(); };
    for (const Eigen::Vector3d& point : taken)
      if (crowds(v, point, rigid)) return false;
    for (const MarkerBinding& b : layout) {
      const Eigen::Index u = b.vertices[0];
      if (crowds(v, rig.neutral.col(u), [&](Eigen::Index s) { return rig.deltas.col(s).segment<3>(3 * u); })) return false;
    }
    return true;
  };
  struct Candidate {
    int observed;
    double moved;
    Eigen::Index vertex;
  };
  std::vector<Candidate> candidates;
  while (int(layout.size()) < count) {
    // The vertex observing the most shapes no marker observes yet (then the one they move
    // most), apart from the markers placed.
    candidates.clear();
    for (Eigen::Index v = 0; v < n; ++v) {
      if (!usable[std::size_t(v)]) continue;
      Candidate c{0, 0.0, v};
      for (Eigen::Index s = 0; s < shapes; ++s)
        if (!covered[std::size_t(s)] && motion(v, s) >= observing[s]) ++c.observed, c.moved += motion(v, s);
      if (c.observed > 0) candidates.push_back(c);
    }
    std::sort(candidates.begin(), candidates.end(), [](const Candidate& a, const Candidate& b) {
      return a.observed != b.observed ? a.observed > b.observed : a.moved != b.moved ? a.moved > b.moved : a.vertex < b.vertex;
    });
    const auto best = std::find_if(candidates.begin(), candidates.end(), [&](const Candidate& c) { return apart(c.vertex); });
    if (best == candidates.end()) break;
    for (Eigen::Index s = 0; s < shapes; ++s)
      if (motion(best->vertex, s) >= observing[s]) covered[std::size_t(s)] = 1;
    layout.push_back(MarkerBinding::at_vertex(fmt::format("M{:03d}", layout.size()), int(best->vertex)));
  }
  add_farthest_markers(rig, usable, count, taken, layout);
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
  // A rigid head rig: points on an arc across the front of the head, alternating between
  // above the brow and temple height (and depth), so that the rigid fit is well
  // conditioned about every axis, not only about the vertical.
  const BoundingBox box = bounding_box(rig.neutral);
  const Eigen::Vector3d size = box.size();
  const double centre_x = 0.5 * (box.min.x() + box.max.x());
  const double centre_z = 0.5 * (box.min.z() + box.max.z());
  std::vector<Eigen::Vector3d> head_points;
  for (int i = 0; i < head_markers; ++i) {
    const double angle = std::numbers::pi * (0.15 + 0.7 * (i + 0.5) / head_markers);
    const bool high = i % 2 == 0;
    const Eigen::Vector3d p(centre_x - 0.55 * size.x() * std::cos(angle),
                            box.max.y() + (high ? 0.1 : -0.3) * size.y(),
                            centre_z + 0.5 * size.z() * std::sin(angle) - (high ? 0.0 : 0.6) * size.z());
    set.head.push_back({fmt::format("H{}", i), p});
    head_points.push_back(p);
  }
  // The face markers keep away from the head rig's too: cameras must see them apart.
  set.face = observing_marker_layout(rig, face_markers, align::kObservableShapeMm, head_points);
  return set;
}

}  // namespace facecap
