// facecap inspect: what a marker take, recording (and its solved frames), Live Link Face
// CSV or NatNet capture holds.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numbers>
#include <optional>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "core/error.hpp"
#include "core/printable.hpp"
#include "formats/arkit.hpp"
#include "formats/livelinkface.hpp"
#include "drivers/capture/capture_file.hpp"
#include "formats/natnet_capture.hpp"
#include "formats/recording.hpp"
#include "formats/take.hpp"
#include "tools/commands.hpp"
#include "tools/inspect_capture.hpp"
#include "tools/tool_support.hpp"

namespace facecap::tools {
namespace {

using formats::FaceTake;
using formats::MarkerTake;
using formats::TakeFormat;

// What a recording's solved frames did: per rig shape its weight's spread, and the
// head pose's range.
struct SolvedSummary {
  struct Shape {
    std::string name;
    double min = 0, median = 0, max = 0;
    std::size_t frames_above_half = 0;
  };
  std::size_t frames = 0;
  std::string rig_name, rig_units;
  std::vector<Shape> shapes;
  std::array<std::array<double, 2>, 3> head_angles_deg{};  // yaw, pitch, roll: min, max
  std::array<std::array<double, 2>, 3> head_translation{};  // x, y, z: min, max (rig units)
};

// A file read as whichever kind it is: markers (with a recording's solved frames),
// blendshape weights, or NatNet traffic.
struct LoadedFile {
  std::optional<MarkerTake> markers;
  std::optional<SolvedSummary> solved;
  std::optional<FaceTake> face;
  std::optional<formats::natnet::NatNetCapture> capture;
};

// nullopt for a recording without solved frames. Throws Error on a damaged frame.
std::optional<SolvedSummary> summarise_solved(const std::filesystem::path& path, bool salvage) {
  const formats::RecordingReader reader(path, {.salvage = salvage});
  const std::size_t count = reader.solved_frame_count();
  if (count == 0) return std::nullopt;
  const auto& names = reader.header().shape_names;
  SolvedSummary summary;
  summary.frames = count;
  summary.rig_name = reader.header().rig_name;
  summary.rig_units = reader.header().rig_units;
  std::vector<std::vector<double>> weights(names.size(), std::vector<double>(count));
  const formats::ArkitWeights arkit(names);
  for (auto* range : {&summary.head_angles_deg, &summary.head_translation})
    for (auto& r : *range) r = {std::numeric_limits<double>::infinity(), -std::numeric_limits<double>::infinity()};
  SolvedFrame solved;
  for (std::size_t f = 0; f < count; ++f) {
    read_solved_frame_checked(reader, f, solved);
    for (std::size_t s = 0; s < names.size(); ++s) weights[s][f] = solved.weights[Eigen::Index(s)];
    const auto angles = formats::face_frame_from_solved(solved, arkit).angles;  // the CSV's head angles
    for (int i = 0; i < 3; ++i) {
      auto& a = summary.head_angles_deg[std::size_t(i)];
      const double degrees = angles[std::size_t(i)] * 180.0 / std::numbers::pi;
      a = {std::min(a[0], degrees), std::max(a[1], degrees)};
      auto& t = summary.head_translation[std::size_t(i)];
      t = {std::min(t[0], solved.head_translation[i]), std::max(t[1], solved.head_translation[i])};
    }
  }
  for (std::size_t s = 0; s < names.size(); ++s) {
    auto& w = weights[s];
    SolvedSummary::Shape shape{names[s]};
    shape.frames_above_half = std::size_t(std::count_if(w.begin(), w.end(), [](double x) { return x > 0.5; }));
    shape.min = *std::min_element(w.begin(), w.end());
    shape.max = *std::max_element(w.begin(), w.end());
    shape.median = percentile(w, 50.0);
    summary.shapes.push_back(shape);
  }
  return summary;
}

LoadedFile load(const std::filesystem::path& path, const formats::natnet::CaptureOptions& capture_options,
               bool salvage) {
  LoadedFile loaded;
  const TakeFormat format = formats::detect_file_format(path);
  if (format == TakeFormat::kNatNetCapture) {
    loaded.capture = capture::read_natnet_capture(path, capture_options);
  } else if (format == TakeFormat::kLiveLinkFace) {
    loaded.face = formats::read_livelinkface(path);
  } else {
    loaded.markers = formats::read_take(path, {.salvage_recording = salvage});
    if (loaded.markers->format == TakeFormat::kRecording) loaded.solved = summarise_solved(path, salvage);
  }
  return loaded;
}

struct ReadTimes {
  double min_ms = 0;
  double median_ms = 0;
  int reads = 0;
};

// Reads the file `reads` more times and reports min and median wall time of one read.
ReadTimes time_reads(const std::filesystem::path& path, const formats::natnet::CaptureOptions& capture_options,
                     int reads, bool salvage) {
  std::vector<double> ms;
  for (int i = 0; i < reads; ++i) {
    const auto start = std::chrono::steady_clock::now();
    const LoadedFile loaded = load(path, capture_options, salvage);
    ms.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count());
  }
  std::sort(ms.begin(), ms.end());
  return {ms.front(), ms[ms.size() / 2], reads};
}

nlohmann::json position_or_null(const Marker& m) {
  if (!m.present()) return nullptr;
  return nlohmann::json::array({m.position.x(), m.position.y(), m.position.z()});
}

nlohmann::json markers_json(const std::filesystem::path& path, const MarkerTake& take) {
  const auto gaps = formats::count_gaps(take);
  nlohmann::json j;
  j["file"] = path.string();
  j["format"] = formats::format_name(take.format);
  j["frames"] = take.frames.size();
  j["rate_hz"] = take.rate_hz;
  j["markers"] = take.marker_count();
  j["labels"] = take.labels;
  j["units"] = take.units;
  j["gaps"] = gaps.missing_samples;
  j["gap_runs"] = gaps.gap_runs;
  nlohmann::json first = nlohmann::json::array();
  if (!take.frames.empty()) {
    for (const Marker& m : take.frames.front().markers) first.push_back(position_or_null(m));
  }
  j["first_frame"] = first;
  j["first_frame_number"] = take.first_frame;
  nlohmann::json metadata = nlohmann::json::object();
  for (const auto& [key, value] : take.metadata) metadata[key] = value;
  j["metadata"] = metadata;
  j["warnings"] = take.warnings;
  return j;
}

nlohmann::json solved_json(const SolvedSummary& s) {
  nlohmann::json j;
  j["frames"] = s.frames;
  j["rig"] = s.rig_name;
  j["rig_units"] = s.rig_units;
  nlohmann::json shapes = nlohmann::json::array();
  for (const auto& shape : s.shapes)
    shapes.push_back({{"name", shape.name}, {"min", shape.min}, {"median", shape.median}, {"max", shape.max},
                      {"frames_above_half", shape.frames_above_half}});
  j["shapes"] = shapes;
  const char* angle_names[] = {"yaw_deg", "pitch_deg", "roll_deg"};
  const char* axes[] = {"x", "y", "z"};
  for (int i = 0; i < 3; ++i) {
    j["head"][angle_names[i]] = s.head_angles_deg[std::size_t(i)];
    j["head"]["translation"][axes[i]] = s.head_translation[std::size_t(i)];
  }
  return j;
}

void print_solved(const SolvedSummary& s) {
  fmt::print("\nsolved frames {} (rig {}, {})\n", s.frames, printable(s.rig_name), s.rig_units.empty() ? "units unknown" : s.rig_units);
  const char* angle_names[] = {"yaw", "pitch", "roll"};
  const char* axes[] = {"x", "y", "z"};
  for (int i = 0; i < 3; ++i)
    fmt::print("  head {:<5} {:8.2f} .. {:8.2f} deg    {} {:10.3f} .. {:10.3f}\n", angle_names[i],
               s.head_angles_deg[std::size_t(i)][0], s.head_angles_deg[std::size_t(i)][1], axes[i],
               s.head_translation[std::size_t(i)][0], s.head_translation[std::size_t(i)][1]);
  fmt::print("  {:<24} {:>7} {:>7} {:>7} {:>12}\n", "shape", "min", "median", "max", "frames > 0.5");
  for (const auto& shape : s.shapes)
    fmt::print("  {:<24} {:7.3f} {:7.3f} {:7.3f} {:12}\n", printable(shape.name), shape.min, shape.median, shape.max,
               shape.frames_above_half);
}

nlohmann::json face_json(const std::filesystem::path& path, const FaceTake& take) {
  nlohmann::json j;
  j["file"] = path.string();
  j["format"] = formats::format_name(TakeFormat::kLiveLinkFace);
  j["frames"] = take.frames.size();
  j["rate_hz"] = take.rate_hz;
  j["markers"] = 0;
  j["labels"] = nlohmann::json::array();
  j["units"] = "";
  j["gaps"] = take.lost_frames();  // rows where tracking was lost
  j["first_frame"] = nlohmann::json::array();
  nlohmann::json shapes = nlohmann::json::array();
  for (const auto& s : formats::kArkitShapes) shapes.push_back(s.arkit);
  j["shapes"] = shapes;
  j["lost_frames"] = take.lost_frames();
  if (!take.frames.empty()) {
    const auto& f = take.frames.front();
    j["first_timecode"] = formats::format_livelink_timecode(f.timecode);
    if (f.tracked) {
      nlohmann::json weights = nlohmann::json::object();
      for (std::size_t s = 0; s < formats::kArkitShapeCount; ++s)
        weights[std::string(formats::kArkitShapes[s].arkit)] = f.weights[s];
      j["first_weights"] = weights;
    } else {
      j["first_weights"] = nullptr;
    }
  }
  j["warnings"] = take.warnings;
  return j;
}

void print_markers(const std::filesystem::path& path, const MarkerTake& take) {
  const auto gaps = formats::count_gaps(take);
  fmt::print("file      {}\n", path.string());
  fmt::print("format    {}\n", formats::format_name(take.format));
  fmt::print("frames    {}", take.frames.size());
  if (!take.frames.empty()) fmt::print("  (numbers {}..{})", take.frames.front().frame_no, take.frames.back().frame_no);
  fmt::print("\nrate_hz   {}\nmarkers   {}\nunits     {}\n", take.rate_hz, take.marker_count(), take.units);
  fmt::print("gaps      {} missing samples in {} runs\n", gaps.missing_samples, gaps.gap_runs);
  for (const auto& [key, value] : take.metadata) fmt::print("  {:<22} {}\n", printable(key), printable(value));
  for (const auto& w : take.warnings) fmt::print("warning   {}\n", printable(w));
  if (take.frames.empty()) return;
  fmt::print("\nfirst frame ({}):\n", take.frames.front().frame_no);
  for (std::size_t k = 0; k < take.marker_count(); ++k) {
    const Marker& m = take.frames.front().markers[k];
    if (m.present()) {
      fmt::print("  {:<24} {:12.4f} {:12.4f} {:12.4f}\n", printable(take.labels[k]), m.position.x(), m.position.y(),
                 m.position.z());
    } else {
      fmt::print("  {:<24} missing\n", printable(take.labels[k]));
    }
  }
}

void print_face(const std::filesystem::path& path, const FaceTake& take) {
  fmt::print("file      {}\n", path.string());
  fmt::print("format    {}\n", formats::format_name(TakeFormat::kLiveLinkFace));
  fmt::print("frames    {}\nrate_hz   {}\n", take.frames.size(), take.rate_hz);
  fmt::print("gaps      {} rows where tracking was lost\n", take.lost_frames());
  fmt::print("shapes    {} ARKit weights + {} head/eye angles\n", formats::kArkitShapeCount,
             formats::kLiveLinkAngleCount);
  for (const auto& w : take.warnings) fmt::print("warning   {}\n", printable(w));
  if (take.frames.empty()) return;
  const auto& f = take.frames.front();
  fmt::print("\nfirst frame ({}):\n", formats::format_livelink_timecode(f.timecode));
  if (!f.tracked) {
    fmt::print("  tracking lost\n");
    return;
  }
  for (std::size_t s = 0; s < formats::kArkitShapeCount; ++s) {
    fmt::print("  {:<20} {:8.4f}\n", formats::kArkitShapes[s].arkit, f.weights[s]);
  }
}

}  // namespace

void add_inspect_command(CLI::App& app, int& exit_code) {
  struct Options {
    std::string file;
    bool json = false;
    bool time = false;
    int repeat = 10;
    bool frames = false;
    bool salvage = false;
    std::string natnet_version;
  };
  auto opts = std::make_shared<Options>();
  auto* cmd = app.add_subcommand(
      "inspect", "Show what a C3D, TRC, Live Link Face CSV, .fcrec recording or pcap/pcapng NatNet capture holds");
  cmd->add_option("file", opts->file, "The file to inspect")->required()->check(CLI::ExistingFile);
  cmd->add_flag("--json", opts->json,
                "Print JSON: format, frames, rate_hz, markers, labels, units, gaps, first_frame (captures: frames, "
                "natnet_version, rate_hz; recordings with solved frames: solved)");
  cmd->add_flag("--time", opts->time, "Also measure how long reading the file takes");
  cmd->add_option("--repeat", opts->repeat, "Reads timed by --time")
      ->check(CLI::Range(1, 10000))
      ->capture_default_str();
  cmd->add_flag("--frames", opts->frames, "Captures: list every frame of data in the JSON (frame_list)");
  cmd->add_flag("--salvage", opts->salvage,
                "Recordings: read the frames of one whose HEAD is damaged and has no intact copy (its fields "
                "taken from the damaged HEAD where it still decodes, else left empty; frames found by scanning)");
  cmd->add_option("--natnet-version", opts->natnet_version,
                  "Captures: the NatNet bitstream when the capture holds no session start [default: 3.0, Motive 2.x]")
      ->check([](const std::string& text) -> std::string {
        const auto version = formats::natnet::parse_version(text);
        if (version && formats::natnet::is_supported_bitstream(*version)) return "";
        return "a NatNet bitstream 3.x or 4.x, like 3.0 or 4.1";
      });
  cmd->callback([opts, &exit_code] {
    const std::filesystem::path path(opts->file);
    formats::natnet::CaptureOptions capture_options;
    if (!opts->natnet_version.empty()) {
      capture_options.default_bitstream = *formats::natnet::parse_version(opts->natnet_version);
    }
    const LoadedFile loaded = load(path, capture_options, opts->salvage);
    if (!loaded.capture && (opts->frames || !opts->natnet_version.empty())) {
      throw file_error(path.string(), "--frames and --natnet-version apply to pcap/pcapng captures only");
    }
    std::optional<ReadTimes> times;
    if (opts->time) times = time_reads(path, capture_options, opts->repeat, opts->salvage);
    if (opts->json) {
      nlohmann::json j = loaded.capture   ? capture_json(*loaded.capture, opts->frames)
                         : loaded.markers ? markers_json(path, *loaded.markers)
                                          : face_json(path, *loaded.face);
      if (loaded.solved) j["solved"] = solved_json(*loaded.solved);
      if (times) j["read_ms"] = {{"min", times->min_ms}, {"median", times->median_ms}, {"reads", times->reads}};
      // NaN has no JSON form; missing positions are already null.
      std::puts(j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace).c_str());
    } else {
      if (loaded.capture)
        print_capture(path, *loaded.capture);
      else if (loaded.markers)
        print_markers(path, *loaded.markers);
      else
        print_face(path, *loaded.face);
      if (loaded.solved) print_solved(*loaded.solved);
      if (times) {
        fmt::print("\nread time min {:.3f} ms, median {:.3f} ms over {} reads ({} bytes)\n", times->min_ms,
                   times->median_ms, times->reads, std::filesystem::file_size(path));
      }
    }
    exit_code = 0;
  });
}

}  // namespace facecap::tools
