#pragma once
// Marker layouts for simulated and synthetic takes: where on the rig markers sit.
#include <span>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "solver/face_solver.hpp"
#include "solver/rig.hpp"

namespace facecap {

// `count` vertices spread evenly over the face (farthest-point sampling from the
// vertex nearest the centre of the front), skipping vertices no shape moves and the
// mesh border. Deterministic. Labels are "M000", "M001", ...
std::vector<MarkerBinding> spread_marker_layout(const Rig& rig, int count);

// `count` markers that first observe every shape they can: each at the usable vertex that
// sees the most shapes no marker sees yet (moved by 1.5 x observable_mm at weight 1, the
// calibration's threshold, or by 90% of the most the shape moves a vertex, if that is
// less but above the threshold), kObservingMarkerSpacingMm from the others and from the
// `taken` points (a head rig's) at rest and half that at any shape's full weight; then
// spread as spread_marker_layout does. The built-in face's blinks and brows get markers.
// Deterministic. Labels are "M000", "M001", ...
std::vector<MarkerBinding> observing_marker_layout(const Rig& rig, int count, double observable_mm,
                                                   std::span<const Eigen::Vector3d> taken = {});
// Real markers sit about a centimetre apart at the least.
inline constexpr double kObservingMarkerSpacingMm = 10.0;

// Markers on the given vertex indices, labelled "V<index>".
std::vector<MarkerBinding> vertex_marker_layout(const std::vector<int>& vertices);

// A marker rigid with the skull (a headband, a cap) and not on the face's surface.
struct HeadMarker {
  std::string label;
  Eigen::Vector3d position = Eigen::Vector3d::Zero();  // rig space; does not move with expressions
};

// Which markers a capture has and where they sit in rig space: face markers bound to the
// surface, head markers rigid with the skull. What the simulated source samples.
struct MarkerSet {
  std::vector<MarkerBinding> face;
  std::vector<HeadMarker> head;

  // Face labels, then head labels: the marker order of simulated frames.
  std::vector<std::string> labels() const;
};

// face_markers observing the rig's shapes (observing_marker_layout: labels M000...) and
// head_markers on a rigid headband above the brow (labels H0...), placed from the rig's
// bounding box. head_markers is 0 or at least 3. Not RT-safe; throws Error.
MarkerSet default_marker_set(const Rig& rig, int face_markers, int head_markers);

// A binding's point on a posed mesh: the barycentric blend of its triangle's vertices.
// vertices: 3 x N. RT-safe.
inline Eigen::Vector3d binding_point(const MarkerBinding& binding, const Eigen::Matrix3Xd& vertices) noexcept {
  return binding.barycentric[0] * vertices.col(binding.vertices[0]) +
         binding.barycentric[1] * vertices.col(binding.vertices[1]) +
         binding.barycentric[2] * vertices.col(binding.vertices[2]);
}

}  // namespace facecap
