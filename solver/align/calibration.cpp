#include "solver/align/calibration.hpp"

#include <algorithm>

namespace facecap::align {

int Calibration::find(const std::string& label) const {
  for (std::size_t i = 0; i < markers.size(); ++i)
    if (markers[i].label == label) return int(i);
  return -1;
}

int Calibration::find_head(const std::string& label) const {
  for (std::size_t i = 0; i < head_markers.size(); ++i)
    if (head_markers[i].label == label) return int(i);
  return -1;
}

const Eigen::Vector3d* Calibration::neutral_of(const std::string& label) const {
  if (const int m = find(label); m >= 0) return &markers[std::size_t(m)].neutral;
  if (const int h = find_head(label); h >= 0) return &head_markers[std::size_t(h)].neutral;
  return nullptr;
}

std::vector<MarkerBinding> Calibration::bindings() const {
  std::vector<MarkerBinding> out;
  out.reserve(markers.size());
  for (const auto& m : markers) out.push_back(m.binding);
  return out;
}

std::vector<std::string> Calibration::unfitted_shapes() const {
  std::vector<std::string> out;
  for (const auto& u : unobserved_shapes) out.push_back(u.name);
  return out;
}

void find_unobserved_shapes(Calibration& calibration, const Rig& rig) {
  calibration.unobserved_shapes.clear();
  for (Eigen::Index s = 0; s < rig.shape_count(); ++s) {
    double largest = 0.0;
    for (const auto& m : calibration.markers) {
      Eigen::Vector3d d = Eigen::Vector3d::Zero();
      for (int i = 0; i < 3; ++i) d += m.binding.barycentric[i] * rig.deltas.block<3, 1>(3 * m.binding.vertices[std::size_t(i)], s);
      largest = std::max(largest, d.norm());
    }
    const double mm = largest * calibration.rig_mm_per_unit;
    if (mm < calibration.observable_shape_mm)
      calibration.unobserved_shapes.push_back({rig.shape_names[std::size_t(s)], mm});
  }
  calibration.observability_known = true;
}

}  // namespace facecap::align
