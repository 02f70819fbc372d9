#include "formats/natnet_markers.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include <fmt/format.h>

#include "core/error.hpp"
#include "core/time.hpp"

namespace facecap::formats::natnet {
namespace {

const MarkerSetDescription* find_marker_set(const ModelDefinitions& definitions, std::string_view name) {
  for (const ModelDescription& model : definitions.models)
    if (const auto* set = std::get_if<MarkerSetDescription>(&model); set && set->name == name) return set;
  return nullptr;
}

// The model whose labelled markers are the set's: a rigid body, skeleton or asset of the
// set's name (Motive describes each with a marker set of the same name).
const ModelDescription* find_owner(const ModelDefinitions& definitions, std::string_view name) {
  for (const ModelDescription& model : definitions.models) {
    const bool owner = std::holds_alternative<RigidBodyDescription>(model) ||
                       std::holds_alternative<SkeletonDescription>(model) ||
                       std::holds_alternative<AssetDescription>(model);
    if (owner && description_name(model) == name) return &model;
  }
  return nullptr;
}

int32_t owner_id(const ModelDescription& model) {
  if (const auto* body = std::get_if<RigidBodyDescription>(&model)) return body->id;
  if (const auto* skeleton = std::get_if<SkeletonDescription>(&model)) return skeleton->id;
  return std::get<AssetDescription>(model).id;
}

// Each name's slot among the first `slots` labels (the first slot of that label not taken
// by an earlier name, so repeated names keep their order), or -1.
std::vector<int> match_slots(const std::vector<std::string>& names, const std::vector<std::string>& labels,
                             std::size_t slots) {
  std::vector<int> out(names.size(), -1);
  std::vector<uint8_t> taken(slots, 0);
  for (std::size_t i = 0; i < names.size(); ++i) {
    for (std::size_t k = 0; k < slots; ++k) {
      if (!taken[k] && labels[k] == names[i]) {
        out[i] = int(k);
        taken[k] = 1;
        break;
      }
    }
  }
  return out;
}

std::string marker_set_names(const ModelDefinitions& definitions) {
  std::vector<std::string> names;
  for (const ModelDescription& model : definitions.models)
    if (const auto* set = std::get_if<MarkerSetDescription>(&model)) names.push_back(fmt::format("'{}'", set->name));
  return names.empty() ? "none" : fmt::format("{}", fmt::join(names, ", "));
}

void set_missing_marker(Marker& marker, uint32_t flags) noexcept {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  marker.id = -1;
  marker.position = Eigen::Vector3d(nan, nan, nan);
  marker.flags = kMarkerMissing | flags;
}

Eigen::Vector3d to_vector(const Position& p) noexcept { return {double(p[0]), double(p[1]), double(p[2])}; }

bool usable(const Position& p) noexcept {
  return std::isfinite(p[0]) && std::isfinite(p[1]) && std::isfinite(p[2]) && !(p[0] == 0 && p[1] == 0 && p[2] == 0);
}

}  // namespace

std::string FrameConverter::unlabelled_label(std::size_t index) { return fmt::format("unlabelled_{}", index + 1); }

FrameConverter::FrameConverter(MarkerSelection selection, const ModelDefinitions& definitions, std::string server)
    : selection_(std::move(selection)), server_(std::move(server)) {
  if (!selection_.marker_set.empty()) {
    const MarkerSetDescription* set = find_marker_set(definitions, selection_.marker_set);
    if (!set) {
      throw Error(fmt::format("NatNet server {} has no marker set '{}' (its marker sets: {})", server_,
                              selection_.marker_set, marker_set_names(definitions)));
    }
    labels_ = set->marker_names;
  }
  set_slots_ = labels_.size();
  for (std::size_t u = 0; u < selection_.unlabelled_slots; ++u) labels_.push_back(unlabelled_label(u));
  if (labels_.empty()) {
    throw Error(fmt::format("NatNet server {}: no marker to take: {}", server_,
                            selection_.marker_set.empty() ? "neither a marker set nor unlabelled points were asked for"
                                                          : fmt::format("marker set '{}' is empty", selection_.marker_set)));
  }
  follow(definitions);
}

std::string FrameConverter::follow(const ModelDefinitions& definitions) {
  set_known_ = false;
  model_id_.reset();
  model_slot_.clear();
  set_index_slot_.clear();
  if (selection_.marker_set.empty()) return {};
  const MarkerSetDescription* set = find_marker_set(definitions, selection_.marker_set);
  if (!set) {
    return fmt::format("marker set '{}' is not in {}'s model definitions now: its {} markers are missing",
                       selection_.marker_set, server_, set_slots_);
  }
  set_known_ = true;
  set_index_slot_ = match_slots(set->marker_names, labels_, set_slots_);

  if (const ModelDescription* owner = find_owner(definitions, selection_.marker_set)) {
    model_id_ = uint16_t(owner_id(*owner));
    if (const auto* asset = std::get_if<AssetDescription>(owner)) {
      // An asset names its markers and gives their ids (perhaps prefixed "<set>_").
      const auto is_slot_label = [&](const std::string& label) {
        return std::find(labels_.begin(), labels_.begin() + std::ptrdiff_t(set_slots_), label) !=
               labels_.begin() + std::ptrdiff_t(set_slots_);
      };
      const std::string prefix = selection_.marker_set + "_";
      std::vector<std::string> names;
      for (const MarkerDescription& m : asset->markers)
        names.push_back(!is_slot_label(m.name) && m.name.starts_with(prefix) ? m.name.substr(prefix.size()) : m.name);
      const std::vector<int> slots = match_slots(names, labels_, set_slots_);
      for (std::size_t j = 0; j < asset->markers.size(); ++j)
        model_slot_.emplace_back(uint16_t(asset->markers[j].id), slots[j]);
    } else {
      // Rigid bodies and skeletons number their markers 1, 2, ... in the set's order.
      for (std::size_t i = 0; i < set_index_slot_.size(); ++i) model_slot_.emplace_back(uint16_t(i + 1), set_index_slot_[i]);
    }
    std::sort(model_slot_.begin(), model_slot_.end());
  }

  std::vector<std::string> unknown, lost;
  std::vector<uint8_t> found(set_slots_, 0);
  for (std::size_t i = 0; i < set_index_slot_.size(); ++i) {
    if (set_index_slot_[i] < 0) unknown.push_back(set->marker_names[i]);
    else found[std::size_t(set_index_slot_[i])] = 1;
  }
  for (std::size_t k = 0; k < set_slots_; ++k)
    if (!found[k]) lost.push_back(labels_[k]);
  std::string note;
  if (!lost.empty())
    note = fmt::format("marker set '{}' no longer has {} of its markers ({}): missing", selection_.marker_set,
                       lost.size(), fmt::join(lost, ", "));
  if (!unknown.empty())
    note += fmt::format("{}marker set '{}' has {} markers it did not have at the start ({}): left out", note.empty() ? "" : "; ",
                        selection_.marker_set, unknown.size(), fmt::join(unknown, ", "));
  return note;
}

void FrameConverter::put_unlabelled(const Position& position, int32_t id, uint32_t& next, ConversionCounts& counts,
                                    MarkerFrame& out) const noexcept {
  if (!usable(position)) return;
  if (next >= selection_.unlabelled_slots) {
    ++counts.unlabelled_dropped;
    return;
  }
  Marker& m = out.markers[set_slots_ + next++];
  m.id = id;
  m.position = to_vector(position);
  m.flags = kMarkerUnlabelled;
  ++counts.unlabelled;
}

ConversionCounts FrameConverter::convert(const FrameOfData& frame, MarkerFrame& out) const noexcept {
  ConversionCounts counts;
  out.frame_no = frame.frame_number;
  out.source_time_ns = std::isfinite(frame.timestamp_s) && std::abs(frame.timestamp_s) < 9e9
                           ? int64_t(std::llround(frame.timestamp_s * double(kNsPerSecond)))
                           : 0;
  out.timecode = facecap::Timecode{};
  if (frame.timecode != 0 || frame.timecode_subframe != 0) {
    const natnet::Timecode t = decode_timecode(frame.timecode, frame.timecode_subframe);
    out.timecode = facecap::Timecode{uint8_t(t.hours), uint8_t(t.minutes), uint8_t(t.seconds), uint8_t(t.frames),
                                     float(t.subframe), selection_.timecode_rate_hz};
  }
  if (out.markers.size() != labels_.size()) return counts;  // not made for these slots: left alone

  for (std::size_t k = 0; k < set_slots_; ++k) set_missing_marker(out.markers[k], 0);
  for (std::size_t u = 0; u < selection_.unlabelled_slots; ++u)
    set_missing_marker(out.markers[set_slots_ + u], kMarkerUnlabelled);

  bool from_labelled = false;
  if (model_id_) {
    for (const LabelledMarker& lm : frame.labelled_markers) {
      if (lm.model_id() != *model_id_) continue;
      from_labelled = true;
      const auto it = std::lower_bound(model_slot_.begin(), model_slot_.end(), std::pair<uint16_t, int>{lm.marker_id(), -1});
      if (it == model_slot_.end() || it->first != lm.marker_id() || it->second < 0) continue;
      Marker& m = out.markers[std::size_t(it->second)];
      m.id = lm.id;
      if (lm.has(LabelledMarkerFlag::kOccluded) || !usable(lm.position)) continue;  // stays missing
      m.position = to_vector(lm.position);
      m.flags = lm.has(LabelledMarkerFlag::kModelSolved) ? kMarkerModelSolved : 0u;
      ++counts.set_markers;
    }
  }
  if (set_known_ && !from_labelled) {
    for (const MarkerSetData& set : frame.marker_sets) {
      if (set.name != selection_.marker_set) continue;
      const std::size_t n = std::min(set.markers.size(), set_index_slot_.size());
      for (std::size_t i = 0; i < n; ++i) {
        if (set_index_slot_[i] < 0 || !usable(set.markers[i])) continue;
        Marker& m = out.markers[std::size_t(set_index_slot_[i])];
        m.position = to_vector(set.markers[i]);
        m.flags = 0;
        ++counts.set_markers;
      }
      break;
    }
  }

  if (selection_.unlabelled_slots > 0 || !selection_.marker_set.empty()) {
    uint32_t next = 0;
    const bool every_marker = selection_.marker_set.empty();
    for (const LabelledMarker& lm : frame.labelled_markers) {
      if ((every_marker || lm.model_id() == 0) && !lm.has(LabelledMarkerFlag::kOccluded))
        put_unlabelled(lm.position, lm.id, next, counts, out);
    }
    if (frame.labelled_markers.empty())
      for (const Position& p : frame.other_markers) put_unlabelled(p, -1, next, counts, out);
  }
  return counts;
}

MarkerTake capture_take(const NatNetCapture& capture, const MarkerSelection& selection, const std::string& name) {
  const ModelDefinitions* first_definitions = nullptr;
  std::size_t frames = 0;
  for (const CapturedMessage& m : capture.messages) {
    if (const auto* definitions = std::get_if<ModelDefinitions>(&m.message.body); definitions && !first_definitions)
      first_definitions = definitions;
    frames += std::holds_alternative<FrameOfData>(m.message.body) ? 1 : 0;
  }
  if (frames == 0) throw Error(fmt::format("{}: the capture holds no NatNet frame of data", name));
  if (!first_definitions && !selection.marker_set.empty()) {
    throw Error(fmt::format("{}: the capture holds no model definitions (NAT_MODELDEF), so marker set '{}' cannot be "
                            "found in it; take its unlabelled points instead", name, selection.marker_set));
  }
  const std::string server = capture.server_info ? std::string(capture.server_info->sender.name.text()) : name;
  FrameConverter converter(selection, first_definitions ? *first_definitions : ModelDefinitions{}, server);

  MarkerTake take;
  take.format = TakeFormat::kNatNetCapture;
  take.labels = converter.labels();
  take.rate_hz = frame_rate_hz(capture);
  take.units = std::string(kPositionUnits);
  take.metadata = {{"capture", capture.file_format},
                   {"bitstream", capture.bitstream.major_minor()},
                   {"server", server},
                   {"marker set", selection.marker_set}};
  if (capture.undecodable > 0)
    take.warnings.push_back(fmt::format("{}: {} datagrams did not parse as NatNet and were left out", name,
                                        capture.undecodable));
  if (capture.damage) take.warnings.push_back(*capture.damage);  // names the file already
  take.frames.reserve(frames);
  const MarkerFrame blank = make_marker_frame(take.labels);
  for (const CapturedMessage& m : capture.messages) {
    if (const auto* definitions = std::get_if<ModelDefinitions>(&m.message.body)) {
      if (definitions != first_definitions)
        if (const std::string note = converter.follow(*definitions); !note.empty())
          take.warnings.push_back(fmt::format("{}: {}", name, note));
      continue;
    }
    const auto* frame = std::get_if<FrameOfData>(&m.message.body);
    if (!frame) continue;
    MarkerFrame& out = take.frames.emplace_back(blank);
    converter.convert(*frame, out);
    out.source_time_ns = m.capture_time_ns;
  }
  take.first_frame = take.frames.front().frame_no;
  finish_take(take, name);
  return take;
}

}  // namespace facecap::formats::natnet
