// facecap solve: offline batch solve of a calibrated take to a Live Link Face style CSV
// (ARKit weights where the rig has the shapes, head angles) or to a .fcrec recording
// (marker frames and solved frames, the calibration in the header).
#include <filesystem>
#include <optional>
#include <vector>

#include <fmt/format.h>

#include "core/error.hpp"
#include "formats/arkit.hpp"
#include "formats/livelinkface.hpp"
#include "formats/recording.hpp"
#include "formats/take.hpp"
#include "pipeline/calibration.hpp"
#include "pipeline/pipeline_state.hpp"
#include "pipeline/recording_header.hpp"
#include "pipeline/settings.hpp"
#include "pipeline/solve_pipeline.hpp"
#include "pipeline/source_units.hpp"
#include "tools/align_support.hpp"
#include "tools/commands.hpp"
#include "tools/progress.hpp"
#include "tools/solve_config.hpp"
#include "tools/tool_support.hpp"

namespace facecap::tools {
namespace {

struct SolveOptions {
  std::string rig, calib, take, output, solver, rig_units, units;
  bool force = false, quiet = false, vertices = false, check_labels = false;
  SolveConfigOptions settings;
};

// What a recording stores about its solve, when the take is one.
struct Stored {
  std::optional<std::string> solver_settings;
  std::optional<std::string> calibration;
  std::optional<formats::RecordingReader> recording;
};

Stored stored_in(const std::string& take_path) {
  Stored stored;
  if (formats::detect_file_format(take_path) != formats::TakeFormat::kRecording) return stored;
  const formats::RecordingReader& reader = stored.recording.emplace(take_path);
  if (!reader.header().solver_settings.empty()) stored.solver_settings = reader.header().solver_settings;
  if (!reader.header().calibration.empty()) stored.calibration = reader.header().calibration;
  return stored;
}

// Continues `solve` from the recording's state before its first frame (a take started
// mid-run then re-solves to itself from that frame). A state that is damaged or does not
// fit is warned about and the solve starts cold. Returns how the solve starts, for the
// summary.
std::string restore_start_state(const formats::RecordingReader& reader, pipeline::SolvePipeline& solve) {
  const std::string cold = "from a cold start: ";
  if (!reader.start_state_damage().empty()) {
    fmt::print(stderr, "facecap: warning: {}: its start state is unreadable ({}); solving from a cold start\n", reader.name(),
               reader.start_state_damage());
    return cold + "the recording's start state is unreadable";
  }
  if (reader.start_state().empty()) return cold + "the recording carries no start state";
  try {
    solve.restore_state(pipeline::decode_pipeline_state(reader.start_state(), reader.name()));
  } catch (const Error& e) {
    fmt::print(stderr, "facecap: warning: {}: {}; solving from a cold start\n", reader.name(), e.what());
    return cold + "the recording's start state does not fit this solve";
  }
  return "from the recording's start state";
}

// Per frame, the fold rounds the recorded solve ran before its deadline stopped them (-1:
// not stopped), so that the re-solve stops there too; empty when the recording's solved
// frames are not one per marker frame.
std::vector<int> fold_deadline_rounds(const formats::RecordingReader& reader, std::size_t frames) {
  if (reader.solved_frame_count() != frames) return {};
  std::vector<int> rounds(frames);
  SolvedFrame solved;
  for (std::size_t f = 0; f < frames; ++f) {
    reader.read_solved_frame(f, solved);
    rounds[f] = solved.fold_deadline_rounds;
  }
  return rounds;
}

void run_solve(const SolveOptions& o) {
  const std::filesystem::path output(o.output);
  const auto format = formats::format_from_extension(output);
  const bool csv = format == formats::TakeFormat::kLiveLinkFace;
  const bool fcrec = format == formats::TakeFormat::kRecording;
  if (!csv && !fcrec) throw file_error(o.output, "output must end in .csv (Live Link Face) or .fcrec (recording)");
  if (!o.force && std::filesystem::exists(output)) throw file_error(o.output, "exists; pass --force to replace it");

  const Rig rig = load_rig(o.rig);
  (void)rig_mm_per_unit(rig, o.rig_units);
  const Stored stored = stored_in(o.take);
  if (o.calib.empty() && !stored.calibration)
    throw file_error(o.take, "has no calibration of its own: pass --calib PROFILE");
  const align::Calibration cal = o.calib.empty()
                                     ? pipeline::read_calibration(*stored.calibration, o.take + " [calibration]", rig)
                                     : pipeline::load_calibration({.file = o.calib}, rig);
  SolveConfigOptions settings_options = o.settings;
  if (!o.solver.empty()) settings_options.sets.push_back("solver.method=" + o.solver);
  const SolveConfig settings = load_solve_config(settings_options, stored.solver_settings, o.take + " [solver settings]");
  const formats::MarkerTake take = formats::read_take(o.take);
  for (const auto& w : take.warnings) fmt::print(stderr, "facecap: warning: {}: {}\n", o.take, w);
  if (take.frames.empty()) throw file_error(o.take, "the take has no frames");
  pipeline::require_plausible_units(take, o.units, cal, o.take);

  const pipeline::SourceDescription source{take.labels, o.units.empty() ? take.units : o.units};
  pipeline::SolveSettings solve_settings = pipeline::solve_settings(settings.values, pipeline::SolveContext::kOffline);
  solve_settings.check_labels = o.check_labels;
  pipeline::SolvePipeline solve(rig, cal, source, solve_settings);
  if (!cal.stable_markers.empty() && solve_settings.mapper.stabilise_head && !solve.mapper().stabilising())
    throw file_error(o.take, fmt::format("head stabilisation needs 3 stable markers; {} of the calibration's {} are in the take",
                                         solve.mapper().stable_markers_found(), cal.stable_markers.size()));
  const std::string method(solve.method());
  const std::string start = stored.recording ? restore_start_state(*stored.recording, solve) : std::string();
  const std::vector<int> fold_rounds =
      stored.recording ? fold_deadline_rounds(*stored.recording, take.frames.size()) : std::vector<int>();

  const formats::ArkitWeights arkit(rig.shape_names);
  formats::FaceTake face;
  face.rate_hz = take.rate_hz;
  std::unique_ptr<formats::RecordingWriter> recording;
  if (fcrec) {
    const formats::RecordingHeader header = pipeline::make_recording_header(
        rig, cal, source, fmt::format("facecap solve --solver {} of {}", method, o.take), take.rate_hz,
        pipeline::solve_settings_toml(settings.values, pipeline::SolveContext::kOffline));
    recording = std::make_unique<formats::RecordingWriter>(output, header, formats::RecordingWriter::Options{.overwrite = o.force});
  }
  ProgressBar bar(fmt::format("solving {} ({})", std::filesystem::path(o.take).filename().string(), method), !o.quiet);
  SolvedFrame solved = solve.make_solved_frame(o.vertices);
  std::size_t held_head = 0, held_face = 0, relabelled = 0;
  for (std::size_t f = 0; f < take.frames.size(); ++f) {
    const MarkerFrame& frame = take.frames[f];
    if (!fold_rounds.empty()) solve.stop_folds_after(fold_rounds[f]);
    solve.process(frame, solved);
    relabelled += std::size_t(solve.label_stats().relabelled);
    held_head += (solved.flags & kSolvedHeadPoseHeld) != 0;
    held_face += (solved.flags & kSolvedTooFewMarkers) != 0;
    if (csv) {
      face.frames.push_back(formats::face_frame_from_solved(solved, arkit));
    } else {
      recording->append_marker_frame(frame);
      recording->append_solved_frame(solved);
    }
    bar.update(f + 1, take.frames.size());
  }
  bar.finish();
  if (csv) {
    write_live_link_csv(output, face);
  } else {
    recording->close();
  }
  const std::size_t mapped_shapes = arkit.realised();
  fmt::print("{} -> {}: {} frames with {} ({}; {} of 52 ARKit shapes on the rig){}; head pose held in {}, face held in {}{}\n",
             o.take, o.output, take.frames.size(), method, settings.origin, mapped_shapes,
             start.empty() ? std::string() : ", " + start, held_head, held_face,
             o.check_labels ? fmt::format(", {} markers relabelled", relabelled) : std::string());
  if (!cal.unobserved_shapes.empty())
    fmt::print("{} shapes the calibrated markers cannot observe stayed at 0: {}\n", cal.unobserved_shapes.size(),
               fmt::join(cal.unfitted_shapes(), ", "));
}

}  // namespace

void add_solve_command(CLI::App& app, int& exit_code) {
  auto opts = std::make_shared<SolveOptions>();
  auto* cmd = app.add_subcommand("solve", "Solve a calibrated take offline to a Live Link Face CSV or a .fcrec recording");
  cmd->add_option("--rig", opts->rig, "builtin, an OBJ directory, a rig.toml manifest, a .gltf/.glb or an .fbx file")->required();
  cmd->add_option("--calib", opts->calib, "Calibration profile (facecap calibrate) or hand-written calibration file; "
                                          "default: the recording's own, when the take is a recording")
      ->check(CLI::ExistingFile);
  cmd->add_option("--take", opts->take, "Marker take (.trc, .c3d, .fcrec)")->required()->check(CLI::ExistingFile);
  cmd->add_option("-o,--output", opts->output, "out.csv (Live Link Face) or out.fcrec (recording)")->required();
  cmd->add_option("--solver", opts->solver, "nonlinear, linear, dt or meshik (offline only: slow); the same as --set "
                                            "solver.method=NAME");
  cmd->add_option("--rig-units", opts->rig_units, "Rig units mm|cm|m (default: guessed from the face's size)");
  cmd->add_option("--units", opts->units, "The take's units mm|cm|m, when it states them wrongly or not at all "
                                          "(default: as it states them)")
      ->check(CLI::IsMember({"mm", "cm", "m"}));
  add_solve_config_options(*cmd, opts->settings);
  cmd->add_flag("--check-labels", opts->check_labels, "Check the take's labels each frame and correct swaps");
  cmd->add_flag("--vertices", opts->vertices, "Store solved meshes in a .fcrec (large)");
  cmd->add_flag("--force", opts->force, "Replace the output file if it exists");
  cmd->add_flag("-q,--quiet", opts->quiet, "No progress bar");
  cmd->callback([opts, &exit_code] {
    run_solve(*opts);
    exit_code = 0;
  });
}

}  // namespace facecap::tools
