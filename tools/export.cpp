// facecap export: a solved take (.fcrec) in the files artists and engines read: glTF 2.0
// animation, PC2 and MDD point caches of the solved mesh, one frame as OBJ, Live Link Face
// CSV (ARKit names, through a name map for other rigs) and a CSV of the rig's own names.
#include <algorithm>
#include <filesystem>
#include <functional>
#include <optional>

#include <fmt/format.h>

#include "core/error.hpp"
#include "core/io.hpp"
#include "core/units.hpp"
#include "formats/arkit.hpp"
#include "formats/livelinkface.hpp"
#include "formats/point_cache.hpp"
#include "formats/recording.hpp"
#include "formats/take.hpp"
#include "pipeline/calibration.hpp"
#include "pipeline/settings.hpp"
#include "pipeline/solve_pipeline.hpp"
#include "solver/obj_mesh.hpp"
#include "tools/commands.hpp"
#include "tools/export.hpp"
#include "tools/export_gltf.hpp"
#include "tools/progress.hpp"
#include "tools/shape_map.hpp"
#include "tools/solve_config.hpp"
#include "tools/tool_support.hpp"

namespace facecap::tools {
namespace {

enum class ExportKind { kGltf, kPc2, kMdd, kObj, kCsv };

std::optional<ExportKind> export_kind(const std::filesystem::path& output) {
  const std::string ext = output.extension().string();
  if (ext == ".glb" || ext == ".gltf") return ExportKind::kGltf;
  if (ext == ".pc2") return ExportKind::kPc2;
  if (ext == ".mdd") return ExportKind::kMdd;
  if (ext == ".obj") return ExportKind::kObj;
  if (ext == ".csv") return ExportKind::kCsv;
  return std::nullopt;
}

struct ExportOptions {
  std::string input, output, rig, map;
  bool weights_only = false, rig_names = false, force = false, progress = false;
  double scale = 1.0;
  std::optional<std::size_t> frame;
};

// `what` names the output in the error for an input that is not a recording ("a glTF").
formats::RecordingReader open_recording(const std::string& input, const char* what) {
  if (formats::detect_file_format(input) != formats::TakeFormat::kRecording)
    throw file_error(input, fmt::format("{} is written from a .fcrec recording's solved frames (facecapd's, or facecap "
                                        "solve -o take.fcrec)", what));
  formats::RecordingReader reader(input);
  if (const std::string damage = reader.damage_summary(); !damage.empty())
    fmt::print(stderr, "facecap: warning: {}: damaged: {}; exporting the frames read\n", input, damage);
  return reader;
}

void require_solved_frames(const formats::RecordingReader& reader) {
  if (reader.solved_frame_count() == 0)
    throw file_error(reader.name(), "the recording has no solved frames (record from facecapd or facecap solve -o x.fcrec)");
}

// The rig the recording was solved on: --rig, checked against the recording's rig hash.
Rig recording_rig(const formats::RecordingReader& reader, const std::string& rig_spec, const char* why) {
  const auto& h = reader.header();
  if (rig_spec.empty())
    throw file_error(reader.name(), fmt::format("{} needs the rig the take was solved on (rig '{}', content hash {:016x}): "
                                                "pass --rig", why, h.rig_name, h.rig_hash));
  Rig rig = load_rig(rig_spec);
  if (h.rig_hash != 0 && rig.content_hash() != h.rig_hash)
    throw file_error(rig_spec, fmt::format("is not the rig {} was solved on: content hash {:016x}, the recording's rig "
                                           "'{}' is {:016x}", reader.name(), rig.content_hash(), h.rig_name, h.rig_hash));
  return rig;
}

// A frame's timecode as Live Link Face writes it (its own, else its time of day), as in
// face_frame_from_solved.
std::string livelink_timecode_of(const SolvedFrame& frame) {
  return formats::format_livelink_timecode(formats::livelink_timecode_at(
      frame.timecode.valid() ? formats::timecode_time_ns(frame.timecode) : frame.source_time_ns));
}

// Seconds from the first frame of the index entries of one kind.
std::vector<double> frame_times_s(const formats::RecordingReader& reader, formats::ChunkKind kind) {
  std::vector<double> out;
  std::optional<int64_t> first;
  for (const auto& entry : reader.index()) {
    if (entry.kind != kind) continue;
    if (!first) first = entry.source_time_ns;
    out.push_back(double(entry.source_time_ns - *first) * 1e-9);
  }
  return out;
}

// Calls start(times, vertex count) and then each(frame) for every solved mesh of the
// recording, in order: the recorded vertices, or when the recording has none, its marker
// frames solved again with the calibration and [solver] settings it stores (facecap
// solve's path, so the weights come out as recorded).
using MeshStart = std::function<void(const std::vector<double>& times_s, Eigen::Index vertex_count)>;
using MeshFrame = std::function<void(std::size_t index, const SolvedFrame& frame)>;
void for_each_solved_mesh(const formats::RecordingReader& reader, const std::string& rig_spec, const MeshStart& start,
                          const MeshFrame& each, bool show_progress) {
  SolvedFrame solved;
  if (reader.solved_frame_count() > 0) {
    read_solved_frame_checked(reader, 0, solved);
    const Eigen::Index vertex_count = solved.vertices.cols();
    if (vertex_count > 0) {
      start(frame_times_s(reader, formats::ChunkKind::kSolvedFrame), vertex_count);
      ProgressBar bar(fmt::format("reading {}", reader.name()), show_progress);
      for (std::size_t i = 0; i < reader.solved_frame_count(); ++i) {
        read_solved_frame_checked(reader, i, solved);
        if (solved.vertices.cols() != vertex_count)
          throw file_error(reader.name(), fmt::format("solved frame {} has {} vertices, the first {}", i,
                                                      solved.vertices.cols(), vertex_count));
        each(i, solved);
        bar.update(i + 1, reader.solved_frame_count());
      }
      return;
    }
  }
  const auto& h = reader.header();
  if (reader.marker_frame_count() == 0)
    throw file_error(reader.name(), "has no solved vertices and no marker frames to solve them from");
  if (h.calibration.empty())
    throw file_error(reader.name(), "has no solved vertices and no calibration to solve its marker frames with");
  const Rig rig = recording_rig(reader, rig_spec, "solving the vertices again");
  const align::Calibration calibration = pipeline::read_calibration(h.calibration, reader.name() + " [calibration]", rig);
  const SolveConfig settings = load_solve_config(
      {}, h.solver_settings.empty() ? std::nullopt : std::optional<std::string>(h.solver_settings),
      reader.name() + " [solver settings]");
  const formats::MarkerTake take = formats::take_from_recording(reader);
  pipeline::SolvePipeline solve(rig, calibration, pipeline::SourceDescription{take.labels, take.units},
                                pipeline::solve_settings(settings.values, pipeline::SolveContext::kOffline));
  solved = solve.make_solved_frame(true);
  start(frame_times_s(reader, formats::ChunkKind::kMarkerFrame), rig.vertex_count());
  // Always shown: solving takes long enough that silence would look like a hang.
  ProgressBar bar(fmt::format("no vertices recorded: solving {} frames again", take.frames.size()), true);
  for (std::size_t i = 0; i < take.frames.size(); ++i) {
    solve.process(take.frames[i], solved);
    each(i, solved);
    bar.update(i + 1, take.frames.size());
  }
}

void export_point_cache(const ExportOptions& o, const formats::RecordingReader& reader, formats::PointCacheFormat format) {
  std::unique_ptr<formats::PointCacheWriter> writer;
  std::size_t frames = 0;
  Eigen::Index vertices = 0;
  for_each_solved_mesh(
      reader, o.rig,
      [&](const std::vector<double>& times, Eigen::Index vertex_count) {
        writer = std::make_unique<formats::PointCacheWriter>(o.output, format, std::size_t(vertex_count), times);
        frames = times.size();
        vertices = vertex_count;
      },
      [&](std::size_t i, const SolvedFrame& frame) {
        if (!frame.vertices.allFinite())
          throw file_error(o.input, fmt::format("solved frame {} has a vertex that is not a finite number", i));
        writer->append(frame.vertices, float(o.scale));
      },
      o.progress);
  writer->close();
  fmt::print("{} -> {} ({}): {} frames of {} vertices, scale {:g}\n", o.input, o.output,
             format == formats::PointCacheFormat::kPc2 ? "PC2" : "MDD", frames, vertices, o.scale);
}

void export_obj_frame(const ExportOptions& o, const formats::RecordingReader& reader) {
  if (!o.frame) throw file_error(o.output, "an OBJ holds one frame: pass --frame N (0 is the first)");
  const Rig rig = recording_rig(reader, o.rig, "an OBJ (the rig's triangles)");
  std::optional<Eigen::Matrix3Xd> vertices;
  std::size_t frames = 0;
  for_each_solved_mesh(
      reader, o.rig,
      [&](const std::vector<double>& times, Eigen::Index vertex_count) {
        frames = times.size();
        if (*o.frame >= frames)
          throw file_error(o.input, fmt::format("--frame {}: the recording has frames 0 to {}", *o.frame, frames - 1));
        if (vertex_count != rig.vertex_count())
          throw file_error(o.input, fmt::format("its meshes have {} vertices, the rig {}", vertex_count, rig.vertex_count()));
      },
      [&](std::size_t i, const SolvedFrame& frame) {
        if (i == *o.frame) vertices = frame.vertices.cast<double>() * o.scale;
      },
      o.progress);
  const std::string text = format_obj(*vertices, rig.triangles);
  write_file_atomically(o.output, std::span<const char>(text.data(), text.size()));
  fmt::print("{} frame {} of {} -> {}: {} vertices, {} triangles, scale {:g}\n", o.input, *o.frame, frames, o.output,
             vertices->cols(), rig.triangle_count(), o.scale);
}

// Metres per rig unit: the recording's rig units, else guessed from the rig's size.
double metres_per_rig_unit(const formats::RecordingReader& reader, const Rig* rig) {
  std::string units = reader.header().rig_units;
  if (units.empty() && rig) units = guess_face_units(bounding_box(rig->neutral));
  const auto mm = millimetres_per_unit(units);
  if (!mm)
    throw file_error(reader.name(), "the rig's units are not recorded and cannot be guessed: glTF needs metres");
  return *mm / 1000.0;
}

void export_gltf(const ExportOptions& o, const formats::RecordingReader& reader) {
  require_solved_frames(reader);
  const auto& h = reader.header();
  std::optional<Rig> rig;
  if (!o.weights_only) rig = recording_rig(reader, o.rig, "a glTF with geometry (or --weights-only)");
  GltfTake take;
  take.shape_names = h.shape_names;
  std::vector<double> times = frame_times_s(reader, formats::ChunkKind::kSolvedFrame);
  // glTF requires strictly increasing key times; a recording whose times repeat (a source
  // without its own clock) is keyed at its nominal rate instead.
  const bool increasing = std::adjacent_find(times.begin(), times.end(), std::greater_equal<>()) == times.end();
  if (!increasing) {
    if (h.rate_hz <= 0)
      throw file_error(o.input, "its frame times do not increase and it states no rate: no glTF key times");
    fmt::print(stderr, "facecap: warning: {}: frame times do not always increase; keyed at {:g} Hz instead\n", o.input,
               h.rate_hz);
    for (std::size_t i = 0; i < times.size(); ++i) times[i] = double(i) / h.rate_hz;
  }
  take.times_s.assign(times.begin(), times.end());
  ProgressBar bar(fmt::format("reading {}", o.input), o.progress);
  SolvedFrame solved;
  for (std::size_t i = 0; i < reader.solved_frame_count(); ++i) {
    read_solved_frame_checked(reader, i, solved);
    if (!solved.weights.allFinite() || !solved.head_rotation.coeffs().allFinite() || !solved.head_translation.allFinite())
      throw file_error(o.input, fmt::format("solved frame {} has a weight or head pose that is not a finite number", i));
    take.weights.insert(take.weights.end(), solved.weights.data(), solved.weights.data() + solved.weights.size());
    take.head_rotation.push_back(solved.head_rotation.cast<float>());
    take.head_translation.push_back(solved.head_translation.cast<float>());
    if (i == 0) take.extras.emplace_back("timecode", livelink_timecode_of(solved));
    bar.update(i + 1, reader.solved_frame_count());
  }
  bar.finish();
  for (const auto& [key, value] : {std::pair<const char*, const std::string&>{"take", h.take}, {"actor", h.actor},
                                   {"scene", h.scene}, {"shot", h.shot}, {"notes", h.notes},
                                   {"source", h.source_description}, {"rig", h.rig_name}})
    take.extras.emplace_back(key, value);
  if (h.rate_hz > 0) take.extras.emplace_back("rate_hz", fmt::format("{:g}", h.rate_hz));
  write_gltf_take(o.output, take, rig ? &*rig : nullptr, metres_per_rig_unit(reader, rig ? &*rig : nullptr));
  fmt::print("{} -> {} (glTF{}): {} frames, {} shapes, {:.3f} s\n", o.input, o.output,
             o.weights_only ? ", weights only" : "", take.times_s.size(), take.shape_names.size(),
             take.times_s.back());
}

}  // namespace

void export_weights_csv(const WeightsCsvOptions& o) {
  const formats::RecordingReader reader =
      open_recording(o.input.string(), o.rig_names ? "a CSV of the rig's shapes" : "a Live Link Face CSV");
  require_solved_frames(reader);
  const auto& names = reader.header().shape_names;
  ProgressBar bar(fmt::format("writing {}", o.output.filename().string()), o.progress);
  SolvedFrame solved;
  if (o.rig_names) {
    // The rig's own names: Timecode, seconds from the first frame, one column per shape.
    std::string text = "Timecode,Seconds";
    for (const auto& name : names) text += "," + name;
    text += "\n";
    int64_t first_ns = 0;
    bool moved = false;
    for (std::size_t i = 0; i < reader.solved_frame_count(); ++i) {
      read_solved_frame_checked(reader, i, solved);
      if (i == 0) first_ns = solved.source_time_ns;
      text += fmt::format("{},{:.6f}", livelink_timecode_of(solved),
                          double(solved.source_time_ns - first_ns) * 1e-9);
      for (Eigen::Index s = 0; s < solved.weights.size(); ++s) {
        text += fmt::format(",{:.9g}", solved.weights[s]);
        moved = moved || solved.weights[s] != 0.0f;
      }
      text += "\n";
      bar.update(i + 1, reader.solved_frame_count());
    }
    if (!moved)
      throw file_error(o.input, fmt::format("every one of its {} shapes stays at 0 in all {} frames: nothing to animate",
                                            names.size(), reader.solved_frame_count()));
    write_file_atomically(o.output, std::span<const char>(text.data(), text.size()));
    bar.finish();
    fmt::print("{} -> {} (the rig's {} shape names): {} frames\n", o.input.string(), o.output.string(), names.size(),
               reader.solved_frame_count());
    return;
  }
  const formats::ArkitWeights arkit = o.map.empty()
                                          ? formats::ArkitWeights(names)
                                          : formats::ArkitWeights(bind_shape_map(read_shape_map(o.map), names));
  if (arkit.realised() == 0)
    throw file_error(o.input, fmt::format("none of the rig's {} shapes ({}{}) {}: a Live Link Face CSV would hold only "
                                          "zeros; pass --map names.toml (examples in config/shape-maps/) or "
                                          "--rig-names for the rig's own names",
                                          names.size(), fmt::join(names.begin(), names.begin() + std::min<std::size_t>(names.size(), 5), ", "),
                                          names.size() > 5 ? ", ..." : "",
                                          o.map.empty() ? "has an ARKit name" : "is mapped by " + o.map.string()));
  formats::FaceTake face;
  face.rate_hz = reader.header().rate_hz;
  bool moved = false;
  for (std::size_t i = 0; i < reader.solved_frame_count(); ++i) {
    read_solved_frame_checked(reader, i, solved);
    face.frames.push_back(formats::face_frame_from_solved(solved, arkit));
    for (const float w : face.frames.back().weights) moved = moved || w != 0.0f;
    bar.update(i + 1, reader.solved_frame_count());
  }
  if (!moved)
    throw file_error(o.input, fmt::format("the {} ARKit shapes the rig realises stay at 0 in all {} frames: nothing to "
                                          "animate", arkit.realised(), face.frames.size()));
  write_live_link_csv(o.output, face);
  bar.finish();
  fmt::print("{} (solved weights) -> {} (Live Link Face): {} frames, {} of 52 ARKit shapes{}\n", o.input.string(),
             o.output.string(), face.frames.size(), arkit.realised(),
             o.map.empty() ? std::string() : " through " + o.map.string());
}

void add_export_command(CLI::App& app, int& exit_code) {
  auto opts = std::make_shared<ExportOptions>();
  auto* cmd = app.add_subcommand("export", "Export a solved take (.fcrec) as glTF animation, PC2/MDD point caches of the "
                                           "solved mesh, one frame as OBJ, or weights as CSV");
  cmd->add_option("in", opts->input, "A recording with solved frames (facecapd's, or facecap solve -o take.fcrec)")
      ->required()->check(CLI::ExistingFile);
  cmd->add_option("out", opts->output, "Output; its extension picks the format: .glb/.gltf, .pc2, .mdd, .obj (with "
                                       "--frame), .csv (Live Link Face, or --rig-names)")->required();
  cmd->add_option("--rig", opts->rig, "The rig the take was solved on (glTF geometry, OBJ, re-solving a recording "
                                      "without vertices); checked against the recording's rig hash");
  cmd->add_flag("--weights-only", opts->weights_only, "glTF: the morph weights and head track with their names, no "
                                                      "geometry (for an engine that has the rig)");
  cmd->add_option("--scale", opts->scale, "PC2, MDD, OBJ: multiply positions (rig units) by this")
      ->check(CLI::PositiveNumber)->capture_default_str();
  cmd->add_option("--frame", opts->frame, "OBJ: the frame to write (0 is the first)");
  cmd->add_option("--map", opts->map, "Live Link Face CSV: a TOML map of rig shape names to ARKit names")
      ->check(CLI::ExistingFile);
  cmd->add_flag("--rig-names", opts->rig_names, "CSV: the rig's own shape names with timecode, not ARKit's");
  cmd->add_flag("--progress", opts->progress, "Show progress on stderr");
  cmd->add_flag("--force", opts->force, "Replace the output file if it exists");
  cmd->callback([opts, &exit_code] {
    const ExportOptions& o = *opts;
    const std::filesystem::path output(o.output);
    std::error_code ec;
    if (std::filesystem::equivalent(o.input, output, ec)) throw file_error(o.output, "output is the input file");
    if (!o.force && std::filesystem::exists(output)) throw file_error(o.output, "exists; pass --force to replace it");
    const auto kind = export_kind(output);
    if (!kind) throw file_error(o.output, "output must end in .glb, .gltf, .pc2, .mdd, .obj or .csv");
    auto only_for = [&](bool given, const char* option, bool allowed, const char* formats) {
      if (given && !allowed) throw file_error(o.output, fmt::format("{} applies to {} only", option, formats));
    };
    only_for(o.weights_only, "--weights-only", kind == ExportKind::kGltf, ".glb and .gltf");
    only_for(o.frame.has_value(), "--frame", kind == ExportKind::kObj, ".obj");
    only_for(!o.map.empty(), "--map", kind == ExportKind::kCsv, ".csv");
    only_for(o.rig_names, "--rig-names", kind == ExportKind::kCsv, ".csv");
    only_for(o.scale != 1.0, "--scale", kind == ExportKind::kPc2 || kind == ExportKind::kMdd || kind == ExportKind::kObj,
             ".pc2, .mdd and .obj");
    if (!o.map.empty() && o.rig_names) throw file_error(o.output, "--map names ARKit columns; --rig-names keeps the rig's");
    switch (*kind) {
      case ExportKind::kCsv:
        export_weights_csv({.input = o.input, .output = output, .map = o.map, .rig_names = o.rig_names,
                            .progress = o.progress});
        break;
      case ExportKind::kGltf:
        export_gltf(o, open_recording(o.input, "a glTF"));
        break;
      case ExportKind::kPc2:
        export_point_cache(o, open_recording(o.input, "a PC2 point cache"), formats::PointCacheFormat::kPc2);
        break;
      case ExportKind::kMdd:
        export_point_cache(o, open_recording(o.input, "an MDD point cache"), formats::PointCacheFormat::kMdd);
        break;
      case ExportKind::kObj:
        export_obj_frame(o, open_recording(o.input, "an OBJ frame"));
        break;
    }
    exit_code = 0;
  });
}

}  // namespace facecap::tools
