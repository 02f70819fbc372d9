#include "control/recordings.hpp"

#include <algorithm>
#include <filesystem>

#include <fmt/format.h>

#include "control/stream_sink.hpp"
#include "formats/recording.hpp"

namespace facecap::control {
namespace fs = std::filesystem;
using nlohmann::json;

namespace {

constexpr std::string_view kRecordingExtension = ".fcrec";

// The seconds between a recording's first and last frame of either kind.
double recorded_seconds(const formats::RecordingReader& reader) {
  const auto& index = reader.index();
  if (index.size() < 2) return 0.0;
  const auto [first, last] = std::minmax_element(index.begin(), index.end(), [](const auto& a, const auto& b) {
    return a.source_time_ns < b.source_time_ns;
  });
  return double(last->source_time_ns - first->source_time_ns) * 1e-9;
}

}  // namespace

Reply list_recordings(const std::string& directory) {
  std::error_code ec;
  // The directory is made with the first take: none yet is an empty list.
  if (!fs::exists(directory, ec)) return {200, {{"directory", directory}, {"recordings", json::array()}}};
  std::vector<fs::directory_entry> files;
  for (const auto& entry : fs::directory_iterator(directory, ec)) {
    std::error_code ignored;
    // symlink_status: a link (out of the directory or not) is not a take.
    if (entry.path().extension() == kRecordingExtension &&
        entry.symlink_status(ignored).type() == fs::file_type::regular)
      files.push_back(entry);
  }
  if (ec) return error_reply(500, fmt::format("cannot list the recordings in {}: {}", directory, ec.message()));
  std::sort(files.begin(), files.end(), [](const auto& a, const auto& b) {
    std::error_code ignored;
    return a.last_write_time(ignored) > b.last_write_time(ignored);
  });
  json recordings = json::array();
  for (const fs::directory_entry& entry : files) {
    json item = {{"name", entry.path().filename().string()}, {"file", entry.path().string()}};
    try {
      const formats::RecordingReader reader(entry.path(), {.no_follow = true});
      const formats::RecordingHeader& h = reader.header();
      bool vertices = false;
      if (reader.solved_frame_count() > 0) {
        SolvedFrame frame;
        reader.read_solved_frame(0, frame);
        vertices = frame.vertices.cols() > 0;
      }
      item.update({{"bytes", reader.size_bytes()},
                   {"take", h.take},
                   {"actor", h.actor},
                   {"scene", h.scene},
                   {"shot", h.shot},
                   {"notes", h.notes},
                   {"rig", h.rig_name},
                   {"rate_hz", h.rate_hz},
                   {"created_unix_ns", h.created_unix_ns},
                   {"marker_frames", reader.marker_frame_count()},
                   {"solved_frames", reader.solved_frame_count()},
                   {"seconds", recorded_seconds(reader)},
                   {"vertices", vertices},
                   {"truncated", reader.truncated()}});
    } catch (const std::exception& e) {
      item["error"] = e.what();
    }
    recordings.push_back(std::move(item));
  }
  return {200, {{"directory", directory}, {"recordings", std::move(recordings)}}};
}

Reply recording_frames(const std::string& directory, const ReadRecording& request, const ReplayRig& rig) {
  const fs::path file = fs::path(directory) / request.name;
  std::error_code ec;
  if (fs::symlink_status(file, ec).type() != fs::file_type::regular)
    return error_reply(404, fmt::format("no recording \"{}\" in {}", request.name, directory));
  try {
    const formats::RecordingReader reader(file, {.no_follow = true});  // nor a link swapped in since
    const formats::RecordingHeader& h = reader.header();
    const std::size_t total = reader.solved_frame_count();
    if (request.first >= total)
      return error_reply(416, fmt::format("{} has {} solved frames: frame {} is past its end", request.name, total,
                                          request.first));
    const bool same_rig = h.rig_hash == rig.hash && rig.vertex_count > 0;
    StreamSchema schema{h.rig_name, h.rig_units, h.shape_names, {}, same_rig ? rig.vertex_count : 0, {}};
    if (same_rig) schema.triangles = rig.triangles;
    const uint64_t count = same_rig ? std::clamp<uint64_t>(kMaxRecordingVerticesPerReply / rig.vertex_count, 1, request.count)
                                    : request.count;
    StreamSink::Entry entry;
    std::string vertices_from = "none";
    json frames = json::array();
    for (uint64_t i = request.first, n = 0; i < total && n < count; i += request.step, ++n) {
      reader.read_solved_frame(std::size_t(i), entry.solved);
      if (entry.solved.vertices.cols() == Eigen::Index(schema.vertex_count) && schema.vertex_count > 0) {
        vertices_from = "recorded";
      } else if (same_rig && rig.blend && std::size_t(entry.solved.weights.size()) == h.shape_names.size()) {
        rig.blend(entry.solved.weights, entry.solved.vertices);
        vertices_from = "blend";
      }
      frames.push_back(frame_message(entry, schema, same_rig));
    }
    return {200,
            {{"name", request.name},
             {"rate_hz", h.rate_hz},
             {"solved_frames", total},
             {"vertices_from", vertices_from},
             {"schema", schema_message(schema, h.rate_hz, same_rig)},
             {"frames", std::move(frames)}}};
  } catch (const std::exception& e) {
    return error_reply(422, fmt::format("{}: {}", file.string(), e.what()));
  }
}

}  // namespace facecap::control
