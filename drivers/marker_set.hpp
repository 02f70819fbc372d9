#pragma once
// Which markers a capture uses and where they sit: face markers bound to the rig surface
// (what the solver pins) and head markers rigid with the skull (what head stabilisation
// fits). The simulated source produces exactly this set; a calibration file can replace
// it for real takes.
#include <string>
#include <vector>

#include <Eigen/Core>

#include "solver/face_solver.hpp"
#include "solver/rig.hpp"

namespace facecap::drivers {

struct HeadMarker {
  std::string label;
  Eigen::Vector3d position = Eigen::Vector3d::Zero();  // rig space, does not move with expressions
};

struct MarkerSet {
  std::vector<MarkerBinding> face;
  std::vector<HeadMarker> head;

  // Face labels, then head labels: the marker order of simulated frames.
  std::vector<std::string> labels() const;
};

// face_markers spread over the face (labels M000...) and head_markers on a rigid
// headband above the brow (labels H0...), placed from the rig's bounding box. Not RT-safe.
MarkerSet default_marker_set(const Rig& rig, int face_markers, int head_markers);

// A binding's point on a posed mesh: the barycentric blend of its triangle's vertices.
// vertices: 3 x N. RT-safe.
inline Eigen::Vector3d binding_point(const MarkerBinding& binding, const Eigen::Matrix3Xd& vertices) noexcept {
  return binding.barycentric[0] * vertices.col(binding.vertices[0]) +
         binding.barycentric[1] * vertices.col(binding.vertices[1]) +
         binding.barycentric[2] * vertices.col(binding.vertices[2]);
}

// Rig units per millimetre from the face's size (0.1 for a rig in cm); 0.1 when unknown.
double rig_units_per_mm(const Rig& rig);


}  // namespace facecap::drivers
