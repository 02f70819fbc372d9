#include "drivers/marker_set.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <numbers>

#include <fmt/format.h>

#include "core/error.hpp"
#include "solver/marker_layout.hpp"

namespace facecap::drivers {

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

double rig_units_per_mm(const Rig& rig) {
  const double mm = millimetres_per_unit(guess_face_units(bounding_box(rig.neutral))).value_or(0.0);
  return mm > 0.0 ? 1.0 / mm : 0.1;
}

}  // namespace facecap::drivers
