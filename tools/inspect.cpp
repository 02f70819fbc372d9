// facecap inspect: what a marker take, recording, Live Link Face CSV or NatNet capture holds.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <optional>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "core/error.hpp"
#include "formats/livelinkface.hpp"
#include "formats/natnet_capture.hpp"
#include "formats/take.hpp"
#include "tools/commands.hpp"
#include "tools/inspect_capture.hpp"

namespace facecap::tools {
namespace {

using formats::FaceTake;
using formats::MarkerTake;
using formats::TakeFormat;

// A file read as whichever kind it is: markers, blendshape weights, or NatNet traffic.
struct LoadedFile {
  std::optional<MarkerTake> markers;
  std::optional<FaceTake> face;
  std::optional<formats::natnet::NatNetCapture> capture;
};

LoadedFile load(const std::filesystem::path& path, const formats::natnet::CaptureOptions& capture_options) {
  LoadedFile loaded;
  const TakeFormat format = formats::detect_file_format(path);
  if (format == TakeFormat::kNatNetCapture) {
    loaded.capture = formats::natnet::read_natnet_capture(path, capture_options);
  } else if (format == TakeFormat::kLiveLinkFace) {
    loaded.face = formats::read_livelinkface(path);
  } else {
    loaded.markers = formats::read_take(path);
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
                     int reads) {
  std::vector<double> ms;
  for (int i = 0; i < reads; ++i) {
    const auto start = std::chrono::steady_clock::now();
    const LoadedFile loaded = load(path, capture_options);
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
  for (const auto& [key, value] : take.metadata) fmt::print("  {:<22} {}\n", key, value);
  for (const auto& w : take.warnings) fmt::print("warning   {}\n", w);
  if (take.frames.empty()) return;
  fmt::print("\nfirst frame ({}):\n", take.frames.front().frame_no);
  for (std::size_t k = 0; k < take.marker_count(); ++k) {
    const Marker& m = take.frames.front().markers[k];
    if (m.present()) {
      fmt::print("  {:<24} {:12.4f} {:12.4f} {:12.4f}\n", take.labels[k], m.position.x(), m.position.y(),
                 m.position.z());
    } else {
      fmt::print("  {:<24} missing\n", take.labels[k]);
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
  for (const auto& w : take.warnings) fmt::print("warning   {}\n", w);
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
    std::string natnet_version;
  };
  auto opts = std::make_shared<Options>();
  auto* cmd = app.add_subcommand(
      "inspect", "Show what a C3D, TRC, Live Link Face CSV, .fcrec recording or pcap/pcapng NatNet capture holds");
  cmd->add_option("file", opts->file, "The file to inspect")->required()->check(CLI::ExistingFile);
  cmd->add_flag("--json", opts->json,
                "Print JSON: format, frames, rate_hz, markers, labels, units, gaps, first_frame (captures: frames, "
                "natnet_version, rate_hz)");
  cmd->add_flag("--time", opts->time, "Also measure how long reading the file takes");
  cmd->add_option("--repeat", opts->repeat, "Reads timed by --time")
      ->check(CLI::Range(1, 10000))
      ->capture_default_str();
  cmd->add_flag("--frames", opts->frames, "Captures: list every frame of data in the JSON (frame_list)");
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
    const LoadedFile loaded = load(path, capture_options);
    if (!loaded.capture && (opts->frames || !opts->natnet_version.empty())) {
      throw file_error(path.string(), "--frames and --natnet-version apply to pcap/pcapng captures only");
    }
    std::optional<ReadTimes> times;
    if (opts->time) times = time_reads(path, capture_options, opts->repeat);
    if (opts->json) {
      nlohmann::json j = loaded.capture   ? capture_json(*loaded.capture, opts->frames)
                         : loaded.markers ? markers_json(path, *loaded.markers)
                                          : face_json(path, *loaded.face);
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
      if (times) {
        fmt::print("\nread time min {:.3f} ms, median {:.3f} ms over {} reads ({} bytes)\n", times->min_ms,
                   times->median_ms, times->reads, std::filesystem::file_size(path));
      }
    }
    exit_code = 0;
  });
}

}  // namespace facecap::tools
