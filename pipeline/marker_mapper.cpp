#include "pipeline/marker_mapper.hpp"

#include <algorithm>
#include <limits>

#include <fmt/format.h>

#include "core/error.hpp"
#include "core/time.hpp"
#include "core/units.hpp"

namespace facecap::pipeline {
namespace {

constexpr int64_t kNeverAccepted = std::numeric_limits<int64_t>::min();
// Before its first acceptance a marker is compared with its rest target (its bound point),
// as if accepted there this long ago: any face reaches, a glitch in the first frame does not.
constexpr int64_t kFirstReachNs = kNsPerSecond;

int find_label(std::span<const std::string> labels, const std::string& label) {
  const auto it = std::find(labels.begin(), labels.end(), label);
  return it == labels.end() ? -1 : int(it - labels.begin());
}

}  // namespace

MarkerMapper::MarkerMapper(const align::Calibration& calibration, std::span<const std::string> frame_labels,
                           std::string_view source_units, MapperOptions options)
    : calibration_(calibration) {
  // Frames in other units than the calibration frame's are scaled into its units.
  const std::optional<double> source_mm = millimetres_per_unit(source_units);
  source_mm_ = source_mm.value_or(calibration_.take_mm_per_unit);
  if (source_mm && calibration_.take_mm_per_unit > 0.0) source_to_take_ = *source_mm / calibration_.take_mm_per_unit;

  for (const auto& m : calibration_.markers) {
    const int slot = find_label(frame_labels, m.label);
    slots_.push_back(slot);
    found_ += slot >= 0;
    stable_.push_back(std::find(calibration_.stable_markers.begin(), calibration_.stable_markers.end(), m.label) !=
                      calibration_.stable_markers.end());
  }
  if (found_ < 3)
    throw Error(fmt::format("only {} of the calibration's {} markers ({}{}) are among the source's {} markers ({}{})",
                            found_, calibration_.markers.size(),
                            calibration_.markers.empty() ? "none" : calibration_.markers.front().label,
                            calibration_.markers.size() > 1 ? ", ..." : "", frame_labels.size(),
                            frame_labels.empty() ? "none" : frame_labels.front(), frame_labels.size() > 1 ? ", ..." : ""));

  // The stable markers' calibration-frame positions, in source units: the head pose is
  // fitted to the frames as they come.
  std::vector<int> stable_slots;
  std::vector<Eigen::Vector3d> reference;
  for (const std::string& label : calibration_.stable_markers) {
    const int slot = find_label(frame_labels, label);
    const Eigen::Vector3d* neutral = calibration_.neutral_of(label);
    if (slot < 0 || !neutral) continue;
    stable_slots.push_back(slot);
    reference.push_back(*neutral / source_to_take_);
  }
  stable_found_ = stable_slots.size();
  stabilising_ = options.stabilise_head && stable_found_ >= 3;
  if (stabilising_) {
    Eigen::Matrix3Xd ref(3, Eigen::Index(reference.size()));
    for (std::size_t i = 0; i < reference.size(); ++i) ref.col(Eigen::Index(i)) = reference[i];
    stabiliser_.emplace(std::move(stable_slots), std::move(ref),
                        align::StabiliserParams{.outlier_floor = options.outlier_floor_mm / source_mm_});
  }
  if (options.max_marker_speed_mm_s > 0.0 && calibration_.rig_mm_per_unit > 0.0)
    max_speed_rig_per_ns_ = options.max_marker_speed_mm_s / calibration_.rig_mm_per_unit / double(kNsPerSecond);
  accepted_targets_.resize(3, marker_count());
  accepted_ns_.resize(slots_.size());
  forget_accepted();
}

void MarkerMapper::forget_accepted() noexcept {
  for (std::size_t k = 0; k < slots_.size(); ++k) accepted_targets_.col(Eigen::Index(k)) = calibration_.markers[k].bound_point;
  std::fill(accepted_ns_.begin(), accepted_ns_.end(), kNeverAccepted);
}

void MarkerMapper::reset() noexcept {
  if (stabiliser_) stabiliser_->reset();
  forget_accepted();
}

MarkerMapper::State MarkerMapper::make_state() const {
  State state{.accepted_targets = accepted_targets_, .accepted_ns = accepted_ns_};
  if (stabiliser_) state.head_pose = stabiliser_->last_pose();
  return state;
}

bool MarkerMapper::save(State& state) const noexcept {
  if (state.accepted_targets.cols() != marker_count() || state.accepted_ns.size() != accepted_ns_.size()) return false;
  state.head_pose = stabiliser_ ? stabiliser_->last_pose() : align::Similarity{};
  state.accepted_targets = accepted_targets_;  // same sizes: no allocation
  state.accepted_ns = accepted_ns_;
  return true;
}

bool MarkerMapper::restore(const State& state) noexcept {
  if (state.accepted_targets.cols() != marker_count() || state.accepted_ns.size() != accepted_ns_.size()) return false;
  if (stabiliser_) stabiliser_->restore_last_pose(state.head_pose);
  accepted_targets_ = state.accepted_targets;
  accepted_ns_ = state.accepted_ns;
  return true;
}

MappedFrame MarkerMapper::make_output() const {
  MappedFrame out;
  out.targets = Eigen::Matrix3Xd::Constant(3, marker_count(), std::numeric_limits<double>::quiet_NaN());
  out.present.assign(slots_.size(), 0);
  return out;
}

void MarkerMapper::process(const MarkerFrame& frame, MappedFrame& out, std::span<uint32_t> marker_flags) noexcept {
  // The head pose in source units: a point fixed to the head is at R reference + t now.
  Eigen::Matrix3d R_head = Eigen::Matrix3d::Identity();
  Eigen::Vector3d t_head = Eigen::Vector3d::Zero();
  if (stabiliser_) {
    stabiliser_->process(frame.markers, pose_, marker_flags);
    R_head = pose_.pose.rotation;
    t_head = pose_.pose.translation;
  }
  const align::Similarity& T = calibration_.take_to_rig;
  const Eigen::Matrix3d R_head_inv = R_head.transpose();
  out.markers_present = 0;
  out.markers_implausible = 0;
  for (std::size_t k = 0; k < slots_.size(); ++k) {
    const int slot = slots_[k];
    // Non-finite coordinates are refused by the plausibility gate below, the one place.
    const bool ok = slot >= 0 && std::size_t(slot) < frame.markers.size() && frame.markers[std::size_t(slot)].present();
    out.present[k] = ok;
    if (!ok) {
      out.targets.col(Eigen::Index(k)).setConstant(std::numeric_limits<double>::quiet_NaN());
      continue;
    }
    const align::MarkerCalibration& m = calibration_.markers[k];
    const Eigen::Vector3d stabilised = source_to_take_ * (R_head_inv * (frame.markers[std::size_t(slot)].position - t_head));
    const Eigen::Vector3d target = m.bound_point + T.apply_vector(stabilised - m.neutral);
    if (!plausible(k, target, frame.source_time_ns)) {
      out.present[k] = 0;
      out.targets.col(Eigen::Index(k)).setConstant(std::numeric_limits<double>::quiet_NaN());
      ++out.markers_implausible;
      if (std::size_t(slot) < marker_flags.size()) marker_flags[std::size_t(slot)] |= kMarkerOutlier;
      continue;
    }
    ++out.markers_present;
    out.targets.col(Eigen::Index(k)) = target;
  }
  // Head pose in rig axes: T o H o T^-1 with H in take units (the scale cancels).
  const Eigen::Matrix3d Rh = T.rotation * R_head * T.rotation.transpose();
  out.head_rotation = Eigen::Quaterniond(Rh);
  out.head_translation = T.translation - Rh * T.translation + T.scale * (T.rotation * (source_to_take_ * t_head));
  out.head_held = stabiliser_ && pose_.held;
  out.stable_inliers = stabiliser_ ? pose_.inliers : 0;
  out.stable_rms_mm = stabiliser_ ? pose_.rms * source_mm_ : 0.0;
}

bool MarkerMapper::plausible(std::size_t k, const Eigen::Vector3d& target, int64_t time_ns) noexcept {
  if (!target.allFinite()) return false;  // NaN or infinite coordinates, or 1e300 overflowing on the way
  if (max_speed_rig_per_ns_ > 0.0) {
    const int64_t since_ns = accepted_ns_[k] == kNeverAccepted ? kFirstReachNs : time_ns - accepted_ns_[k];
    // Written as "not within reach" so that an infinite distance (1e300 - x) is refused too.
    if (since_ns > 0 && !((target - accepted_targets_.col(Eigen::Index(k))).norm() <= max_speed_rig_per_ns_ * double(since_ns)))
      return false;
  }
  accepted_targets_.col(Eigen::Index(k)) = target;
  accepted_ns_[k] = time_ns;
  return true;
}

}  // namespace facecap::pipeline
