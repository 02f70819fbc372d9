#include "solver/align/mapper.hpp"

#include <algorithm>
#include <limits>

#include <fmt/format.h>

#include "core/error.hpp"

namespace facecap::align {

namespace {
int find_label(std::span<const std::string> labels, const std::string& label) {
  const auto it = std::find(labels.begin(), labels.end(), label);
  return it == labels.end() ? -1 : int(it - labels.begin());
}
}  // namespace

HeadStabiliser MarkerMapper::make_stabiliser(const Calibration& c, std::span<const std::string> labels, StabiliserParams p) {
  std::vector<int> slots;
  std::vector<Eigen::Vector3d> reference;
  for (const auto& name : c.stable_markers) {
    const int slot = find_label(labels, name);
    const int m = c.find(name);
    if (slot < 0 || m < 0) continue;
    slots.push_back(slot);
    reference.push_back(c.markers[std::size_t(m)].neutral);
  }
  if (slots.size() < 3)
    throw Error(fmt::format("head stabilisation needs 3 stable markers; {} of the calibration's {} are in the take",
                            slots.size(), c.stable_markers.size()));
  Eigen::Matrix3Xd ref(3, Eigen::Index(reference.size()));
  for (std::size_t i = 0; i < reference.size(); ++i) ref.col(Eigen::Index(i)) = reference[i];
  return HeadStabiliser(std::move(slots), std::move(ref), p);
}

MarkerMapper::MarkerMapper(const Calibration& calibration, std::span<const std::string> frame_labels, StabiliserParams params)
    : calibration_(calibration), stabiliser_(make_stabiliser(calibration, frame_labels, params)) {
  int found = 0;
  for (const auto& m : calibration_.markers) {
    const int slot = find_label(frame_labels, m.label);
    slots_.push_back(slot);
    found += slot >= 0;
    stable_.push_back(std::find(calibration_.stable_markers.begin(), calibration_.stable_markers.end(), m.label) !=
                      calibration_.stable_markers.end());
  }
  if (found < 3) throw Error(fmt::format("only {} of the calibration's markers are in the take", found));
}

MappedFrame MarkerMapper::make_output() const {
  MappedFrame out;
  out.targets = Eigen::Matrix3Xd::Constant(3, marker_count(), std::numeric_limits<double>::quiet_NaN());
  out.present.assign(slots_.size(), 0);
  return out;
}

void MarkerMapper::process(const MarkerFrame& frame, MappedFrame& out, std::span<uint32_t> marker_flags) noexcept {
  stabiliser_.process(frame.markers, pose_, marker_flags);
  const Similarity& H = pose_.pose;  // current = R_H reference + t_H (take units)
  const Similarity& T = calibration_.take_to_rig;
  const Eigen::Matrix3d R_H_inv = H.rotation.transpose();
  for (std::size_t k = 0; k < slots_.size(); ++k) {
    const int slot = slots_[k];
    const bool ok = slot >= 0 && std::size_t(slot) < frame.markers.size() && frame.markers[std::size_t(slot)].present() &&
                    frame.markers[std::size_t(slot)].position.allFinite();
    out.present[k] = ok;
    if (!ok) {
      out.targets.col(Eigen::Index(k)).setConstant(std::numeric_limits<double>::quiet_NaN());
      continue;
    }
    const MarkerCalibration& m = calibration_.markers[k];
    const Eigen::Vector3d stabilised = R_H_inv * (frame.markers[std::size_t(slot)].position - H.translation);
    out.targets.col(Eigen::Index(k)) = m.bound_point + T.apply_vector(stabilised - m.neutral);
  }
  // Head pose in rig axes: T o H o T^-1 (the scale cancels).
  const Eigen::Matrix3d Rh = T.rotation * H.rotation * T.rotation.transpose();
  out.head_rotation = Eigen::Quaterniond(Rh);
  out.head_translation = T.translation - Rh * T.translation + T.scale * (T.rotation * H.translation);
  out.head_in_take = H;
  out.head_held = pose_.held;
  out.stable_inliers = pose_.inliers;
  out.stable_rms_mm = pose_.rms * calibration_.take_mm_per_unit;
}

}  // namespace facecap::align
