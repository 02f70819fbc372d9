#include "daemon/marker_mapper.hpp"

#include <unordered_map>

#include <fmt/format.h>

#include "core/error.hpp"

namespace facecap::daemon {
namespace {

bool slot_present(const MarkerFrame& frame, int slot) noexcept {
  return slot >= 0 && std::size_t(slot) < frame.markers.size() && frame.markers[std::size_t(slot)].present();
}

}  // namespace

MarkerMapper::MarkerMapper(const MarkerCalibration& calibration, const std::vector<std::string>& source_labels,
                           double scale, bool stabilise_head, double outlier_floor)
    : scale_(scale), T_rig_marker_(calibration.T_rig_marker) {
  std::unordered_map<std::string, int> slot_of;
  for (std::size_t i = 0; i < source_labels.size(); ++i) slot_of.emplace(source_labels[i], int(i));
  auto slot = [&](const std::string& label) {
    const auto it = slot_of.find(label);
    return it == slot_of.end() ? -1 : it->second;
  };
  for (const auto& binding : calibration.markers.face) {
    face_slot_.push_back(slot(binding.label));
    matched_face_ += face_slot_.back() >= 0 ? 1 : 0;
  }
  face_offset_ = Eigen::Matrix3Xd::Zero(3, Eigen::Index(face_slot_.size()));
  for (std::size_t k = 0; k < calibration.face_offsets.size(); ++k)
    face_offset_.col(Eigen::Index(k)) = calibration.face_offsets[k];
  if (matched_face_ == 0)
    throw Error(fmt::format("none of the {} face markers of the {} ({}, ...) is among the source's {} markers ({}, ...)",
                            calibration.markers.face.size(), calibration.origin, calibration.markers.face.front().label,
                            source_labels.size(), source_labels.empty() ? "none" : source_labels.front()));
  Eigen::Matrix3Xd head_reference(3, Eigen::Index(calibration.markers.head.size()));
  std::vector<int> head_index;
  for (std::size_t h = 0; h < calibration.markers.head.size(); ++h) {
    head_slot_.push_back(slot(calibration.markers.head[h].label));
    head_reference.col(Eigen::Index(h)) = calibration.markers.head[h].position;
    head_index.push_back(int(h));
  }
  stabilise_ = stabilise_head && head_slot_.size() >= 3;
  if (stabilise_) {
    stabiliser_.emplace(std::move(head_index), std::move(head_reference), align::StabiliserParams{.outlier_floor = outlier_floor});
    head_markers_.resize(head_slot_.size());
  }
}

MappedFrame MarkerMapper::map(const MarkerFrame& frame, Eigen::Matrix3Xd& targets, std::span<uint8_t> present) noexcept {
  MappedFrame out;
  for (const int s : head_slot_) out.head_markers_present += slot_present(frame, s) ? 1 : 0;
  if (stabilise_) {
    for (std::size_t h = 0; h < head_slot_.size(); ++h) {
      const int s = head_slot_[h];
      const bool here = slot_present(frame, s);
      head_markers_[h].flags = here ? 0u : uint32_t(kMarkerMissing);
      if (here) head_markers_[h].position = T_rig_marker_ * (scale_ * frame.markers[std::size_t(s)].position);
    }
    out.head_pose_held = stabiliser_->process(head_markers_, head_pose_);
    out.T_world_head.linear() = head_pose_.pose.rotation;
    out.T_world_head.translation() = head_pose_.pose.translation;
  }
  // Face markers into head space: T_head_world * T_rig_marker * scale * p - offset.
  const Eigen::Isometry3d T_head_marker = out.T_world_head.inverse() * T_rig_marker_;
  for (std::size_t k = 0; k < face_slot_.size(); ++k) {
    const int s = face_slot_[k];
    const bool here = slot_present(frame, s);
    present[k] = here ? 1 : 0;
    if (!here) continue;
    targets.col(Eigen::Index(k)) =
        T_head_marker * (scale_ * frame.markers[std::size_t(s)].position) - face_offset_.col(Eigen::Index(k));
    ++out.face_markers_present;
  }
  return out;
}

}  // namespace facecap::daemon
