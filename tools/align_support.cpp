#include "tools/align_support.hpp"

#include <algorithm>
#include <sstream>

#include <fmt/format.h>

#include "core/error.hpp"
#include "core/units.hpp"

namespace facecap::tools {

double rig_mm_per_unit(const Rig& rig, const std::string& override_units) {
  const std::string units = override_units.empty() ? guess_face_units(bounding_box(rig.neutral)) : override_units;
  const auto mm = millimetres_per_unit(units);
  if (!mm)
    throw Error(fmt::format("cannot tell the units of rig '{}' (guessed '{}'): pass --rig-units mm|cm|m", rig.name, units));
  return *mm;
}

Eigen::Matrix3Xd frame_positions(const MarkerFrame& frame, std::vector<uint8_t>& present) {
  Eigen::Matrix3Xd P(3, Eigen::Index(frame.markers.size()));
  present.assign(frame.markers.size(), 0);
  for (std::size_t k = 0; k < frame.markers.size(); ++k) {
    P.col(Eigen::Index(k)) = frame.markers[k].position;
    present[k] = frame.markers[k].present();
  }
  return P;
}

std::size_t frame_index(const formats::MarkerTake& take, int64_t frame_no, const std::string& take_name) {
  for (std::size_t i = 0; i < take.frames.size(); ++i)
    if (take.frames[i].frame_no == frame_no) return i;
  if (take.frames.empty()) throw file_error(take_name, "the take has no frames");
  throw file_error(take_name, fmt::format("no frame number {} (the take has frames {} to {})", frame_no,
                                          take.frames.front().frame_no, take.frames.back().frame_no));
}

}  // namespace facecap::tools
