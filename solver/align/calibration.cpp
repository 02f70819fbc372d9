#include "solver/align/calibration.hpp"

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

}  // namespace facecap::align
