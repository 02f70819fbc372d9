#include "tools/inspect_capture.hpp"

#include <map>

#include <fmt/format.h>

namespace facecap::tools {

using namespace formats::natnet;

namespace {

template <std::size_t N>
nlohmann::json array_of(const std::array<float, N>& values) {
  return nlohmann::json(std::vector<double>(values.begin(), values.end()));
}

nlohmann::json frame_json(const FrameOfData& frame) {
  nlohmann::json markers = nlohmann::json::array();
  for (const LabelledMarker& m : frame.labelled_markers) {
    markers.push_back({{"id", m.id},
                       {"model_id", m.model_id()},
                       {"marker_id", m.marker_id()},
                       {"pos", array_of(m.position)},
                       {"occluded", m.has(LabelledMarkerFlag::kOccluded)}});
  }
  nlohmann::json bodies = nlohmann::json::array();
  for (const RigidBodyData& b : frame.rigid_bodies) {
    bodies.push_back({{"id", b.id}, {"pos", array_of(b.position)}, {"rot", array_of(b.rotation)}});
  }
  nlohmann::json sets = nlohmann::json::array();
  for (const MarkerSetData& s : frame.marker_sets) {
    nlohmann::json positions = nlohmann::json::array();
    for (const Position& p : s.markers) positions.push_back(array_of(p));
    sets.push_back({{"name", s.name}, {"markers", positions}});
  }
  return {{"frame_number", frame.frame_number},
          {"timecode", format_timecode(frame.timecode, frame.timecode_subframe)},
          {"timestamp_s", frame.timestamp_s},
          {"labelled_markers", markers},
          {"rigid_bodies", bodies},
          {"marker_sets", sets}};
}

std::string group_address(const ServerConnection& c) {
  return fmt::format("{}.{}.{}.{}", c.multicast_group[0], c.multicast_group[1], c.multicast_group[2],
                     c.multicast_group[3]);
}

}  // namespace

nlohmann::json capture_json(const NatNetCapture& capture, bool with_frames) {
  nlohmann::json frames = nlohmann::json::array();
  for (const CapturedMessage& m : capture.messages) {
    if (const auto* frame = std::get_if<FrameOfData>(&m.message.body)) frames.push_back(frame_json(*frame));
  }
  nlohmann::json j;
  j["frames"] = frames.size();
  j["natnet_version"] = capture.bitstream.major_minor();
  j["rate_hz"] = frame_rate_hz(capture);
  if (with_frames) j["frame_list"] = std::move(frames);
  return j;
}

void print_capture(const std::filesystem::path& path, const NatNetCapture& capture) {
  std::map<MessageId, std::size_t> kinds;
  const FrameOfData* first = nullptr;
  const FrameOfData* last = nullptr;
  const ModelDefinitions* models = nullptr;
  for (const CapturedMessage& m : capture.messages) {
    ++kinds[m.message.id];
    if (const auto* frame = std::get_if<FrameOfData>(&m.message.body)) {
      if (!first) first = frame;
      last = frame;
    }
    if (const auto* defs = std::get_if<ModelDefinitions>(&m.message.body)) models = defs;  // the latest
  }
  fmt::print("file      {}\n", path.string());
  fmt::print("format    {} capture, link type {}, {} records\n", capture.file_format, capture.link_type,
             capture.records.records);
  fmt::print("natnet    bitstream {} (from {})\n", capture.bitstream.major_minor(),
             kBitstreamSources.name(capture.bitstream_source));
  if (capture.server_info) {
    const ServerInfo& s = *capture.server_info;
    fmt::print("server    {} {}, NatNet {}", s.sender.name.text(), s.sender.app_version.to_string(),
               s.sender.natnet_version.to_string());
    if (s.connection) {
      fmt::print(", data port {}, {}", s.connection->data_port,
                 s.connection->multicast ? "multicast " + group_address(*s.connection) : std::string("unicast"));
    }
    fmt::print("\n");
  }
  fmt::print("messages  {}\n", capture.messages.size());
  for (const auto& [id, count] : kinds) fmt::print("  {:<26} {}\n", kMessageIds.name(id), count);
  fmt::print("frames    {}", kinds[MessageId::kFrameOfData]);
  if (first)
    fmt::print(" (numbers {}..{}, {} labelled markers in the first)", first->frame_number, last->frame_number,
               first->labelled_markers.size());
  fmt::print("\nrate_hz   {:.3f}\n", frame_rate_hz(capture));
  if (models) {
    fmt::print("models    {}\n", models->models.size());
    for (const ModelDescription& d : models->models) {
      fmt::print("  {:<12} {}\n", description_kind(d), description_name(d));
    }
  }
  const auto& r = capture.records;
  fmt::print(
      "skipped   {} records (not IP {}, not UDP {}, truncated {}, malformed {}, unfinished fragments {}), "
      "{} datagrams on other ports, {} not NatNet\n",
      r.skipped(), r.not_ip, r.not_udp, r.truncated, r.malformed, r.unfinished_fragments, capture.other_ports,
      capture.undecodable);
  for (const std::string& e : capture.errors) fmt::print("error     {}\n", e);
  if (capture.undecodable > capture.errors.size()) {
    fmt::print("error     ... and {} more\n", capture.undecodable - capture.errors.size());
  }
  if (capture.damage) fmt::print("warning   the capture ends in a damaged record: {}\n", *capture.damage);
}

}  // namespace facecap::tools
