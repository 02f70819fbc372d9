#pragma once
// Marker layouts for simulated and synthetic takes: where on the rig markers sit.
#include <vector>

#include "solver/face_solver.hpp"
#include "solver/rig.hpp"

namespace facecap {

// `count` vertices spread evenly over the face (farthest-point sampling from the
// vertex nearest the centre of the front), skipping vertices no shape moves and the
// mesh border. Deterministic. Labels are "M000", "M001", ...
std::vector<MarkerBinding> spread_marker_layout(const Rig& rig, int count);

// Markers on the given vertex indices, labelled "V<index>".
std::vector<MarkerBinding> vertex_marker_layout(const std::vector<int>& vertices);

}  // namespace facecap
