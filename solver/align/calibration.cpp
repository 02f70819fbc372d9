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
  const Eigen::Index S = rig.shape_count(), K = Eigen::Index(calibration.markers.size());
  // Each shape's displacement at the bound points, rig mm: 3 x K per shape.
  std::vector<Eigen::Matrix3Xd> displacement(std::size_t(S), Eigen::Matrix3Xd::Zero(3, K));
  std::vector<double> largest(std::size_t(S), 0.0);
  for (Eigen::Index s = 0; s < S; ++s)
    for (Eigen::Index k = 0; k < K; ++k) {
      const auto& b = calibration.markers[std::size_t(k)].binding;
      Eigen::Vector3d d = Eigen::Vector3d::Zero();
      for (int i = 0; i < 3; ++i) d += b.barycentric[i] * rig.deltas.block<3, 1>(3 * b.vertices[std::size_t(i)], s);
      displacement[std::size_t(s)].col(k) = d * calibration.rig_mm_per_unit;
      largest[std::size_t(s)] = std::max(largest[std::size_t(s)], d.norm() * calibration.rig_mm_per_unit);
    }
  std::vector<Eigen::Index> fitted;
  for (Eigen::Index s = 0; s < S; ++s) {
    if (largest[std::size_t(s)] < calibration.observable_shape_mm)
      calibration.unobserved_shapes.push_back({rig.shape_names[std::size_t(s)], largest[std::size_t(s)]});
    else
      fitted.push_back(s);
  }
  std::stable_sort(fitted.begin(), fitted.end(), [&](Eigen::Index a, Eigen::Index b) { return largest[std::size_t(a)] > largest[std::size_t(b)]; });
  std::vector<Eigen::Index> kept;
  for (const Eigen::Index s : fitted) {
    const Eigen::Matrix3Xd& d = displacement[std::size_t(s)];
    bool duplicate = false;
    for (const Eigen::Index t : kept) {
      const Eigen::Matrix3Xd& e = displacement[std::size_t(t)];
      const double a = std::max(0.0, (d.array() * e.array()).sum() / std::max(e.squaredNorm(), 1e-300));
      const double distinct = (d - a * e).colwise().norm().maxCoeff();
      if (distinct < kDistinctShapeMm) {
        calibration.unobserved_shapes.push_back(
            {rig.shape_names[std::size_t(s)], largest[std::size_t(s)], rig.shape_names[std::size_t(t)], distinct});
        duplicate = true;
        break;
      }
    }
    if (!duplicate) kept.push_back(s);
  }
  calibration.distinct_shape_mm = kDistinctShapeMm;
  calibration.observability_known = true;
}

}  // namespace facecap::align
