#include "tools/align_support.hpp"

#include <algorithm>
#include <sstream>

#include <fmt/format.h>

#include "core/error.hpp"
#include "core/units.hpp"

namespace facecap::tools {

std::vector<std::string> split_list(const std::string& text) {
  std::vector<std::string> out;
  std::string item;
  std::istringstream in(text);
  while (std::getline(in, item, ',')) {
    const auto b = item.find_first_not_of(" \t"), e = item.find_last_not_of(" \t");
    if (b != std::string::npos) out.push_back(item.substr(b, e - b + 1));
  }
  return out;
}

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

CalibratedSetup make_calibrated_setup(const Rig& rig, const align::Calibration& calibration,
                                      const std::vector<std::string>& take_labels, const SolverParams& params) {
  CalibratedSetup s;
  s.calibration = calibration;
  s.mapper = std::make_unique<align::MarkerMapper>(calibration, take_labels, align::StabiliserParams{
      .outlier_floor = 1.0 / calibration.take_mm_per_unit});  // 1 mm
  s.model = build_solver_model(rig, align::calibration_bindings(calibration), params);
  return s;
}

Eigen::Vector3d bound_position(const MarkerBinding& b, const Eigen::Matrix3Xd& V) {
  return b.barycentric[0] * V.col(b.vertices[0]) + b.barycentric[1] * V.col(b.vertices[1]) +
         b.barycentric[2] * V.col(b.vertices[2]);
}

}  // namespace facecap::tools
