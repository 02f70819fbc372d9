// facecap solve: offline batch solve of a calibrated take to a Live Link Face style CSV
// (ARKit weights where the rig has the shapes, head angles) or to a .fcrec recording
// (marker frames and solved frames, the calibration in the header).
#include <cmath>
#include <filesystem>
#include <numbers>

#include <Eigen/Geometry>
#include <fmt/format.h>

#include "core/error.hpp"
#include "core/io.hpp"
#include "formats/arkit.hpp"
#include "formats/livelinkface.hpp"
#include "formats/recording.hpp"
#include "formats/take.hpp"
#include "solver/align/label.hpp"
#include "solver/align/profile.hpp"
#include "solver/solver_model.hpp"
#include "tools/align_support.hpp"
#include "tools/commands.hpp"
#include "tools/progress.hpp"
#include "tools/tool_support.hpp"

namespace facecap::tools {
namespace {

struct Options {
  std::string rig, calib, take, output, solver = "nonlinear", rig_units;
  bool force = false, quiet = false, vertices = false, check_labels = false;
  int max_pins = SolverParams{}.collision_max_pins;
};

Timecode timecode_at(int64_t time_ns) {
  const double frames = double(time_ns) * 1e-9 * formats::kLiveLinkTimecodeRate;
  const auto whole = int64_t(std::floor(frames));
  Timecode tc;
  tc.rate_hz = formats::kLiveLinkTimecodeRate;
  tc.frames = uint8_t(whole % formats::kLiveLinkTimecodeRate);
  const int64_t seconds = whole / formats::kLiveLinkTimecodeRate;
  tc.seconds = uint8_t(seconds % 60);
  tc.minutes = uint8_t((seconds / 60) % 60);
  tc.hours = uint8_t((seconds / 3600) % 24);
  tc.subframe = float(frames - double(whole));
  return tc;
}

void run_solve(const Options& o) {
  const std::filesystem::path output(o.output);
  const auto format = formats::format_from_extension(output);
  const bool csv = format == formats::TakeFormat::kLiveLinkFace;
  const bool fcrec = format == formats::TakeFormat::kRecording;
  if (!csv && !fcrec) throw file_error(o.output, "output must end in .csv (Live Link Face) or .fcrec (recording)");
  if (!o.force && std::filesystem::exists(output)) throw file_error(o.output, "exists; pass --force to replace it");

  const Rig rig = load_rig(o.rig);
  (void)rig_mm_per_unit(rig, o.rig_units);
  const align::Calibration cal = align::load_calibration_profile(o.calib);
  align::check_profile_matches_rig(cal, rig, o.calib);
  const formats::MarkerTake take = formats::read_take(o.take);
  for (const auto& w : take.warnings) fmt::print(stderr, "facecap: warning: {}: {}\n", o.take, w);
  if (take.frames.empty()) throw file_error(o.take, "the take has no frames");

  SolverParams params;
  params.collision_max_pins = o.max_pins;
  auto setup = make_calibrated_setup(rig, cal, take.labels, params);
  const auto solver_ptr = make_solver(o.solver, setup.model);
  FaceSolver& solver = *solver_ptr;
  SolveResult result = solver.make_result();
  auto mapped = setup.mapper->make_output();

  // Optional label check: predictions from the previous frame, the calibration frame to start.
  std::unique_ptr<align::MarkerLabeller> labeller;
  if (o.check_labels) {
    Eigen::Matrix3Xd reference(3, Eigen::Index(take.labels.size()));
    for (std::size_t s = 0; s < take.labels.size(); ++s) {
      const int m = cal.find(take.labels[s]);
      reference.col(Eigen::Index(s)) = m >= 0 ? cal.markers[std::size_t(m)].neutral : Eigen::Vector3d::Zero();
    }
    align::LabellerParams lp;
    lp.gate = 6.0 / cal.take_mm_per_unit;  // mm in take units
    lp.gate_growth = 1.0 / cal.take_mm_per_unit;
    lp.max_gate = 20.0 / cal.take_mm_per_unit;
    lp.label_margin = 1.0 / cal.take_mm_per_unit;
    labeller = std::make_unique<align::MarkerLabeller>(take.labels, reference, lp);
  }

  const auto arkit = formats::match_arkit_to_rig(rig.shape_names);
  formats::FaceTake face;
  face.rate_hz = take.rate_hz;
  std::unique_ptr<formats::RecordingWriter> recording;
  if (fcrec) {
    formats::RecordingHeader h;
    h.rig_name = rig.name;
    h.rig_hash = rig.content_hash();
    h.source_description = fmt::format("facecap solve --solver {} of {}", o.solver, o.take);
    h.calibration = align::write_calibration_profile(cal);
    h.units = take.units;
    h.rate_hz = take.rate_hz;
    h.marker_labels = take.labels;
    h.shape_names = rig.shape_names;
    recording = std::make_unique<formats::RecordingWriter>(output, h, formats::RecordingWriter::Options{.overwrite = o.force});
  }
  ProgressBar bar(fmt::format("solving {} ({})", std::filesystem::path(o.take).filename().string(), o.solver), !o.quiet);
  SolvedFrame solved;
  solved.resize(rig.shape_count(), o.vertices ? rig.vertex_count() : 0);
  MarkerFrame frame;
  std::size_t held_head = 0, held_face = 0, relabelled = 0;
  for (std::size_t f = 0; f < take.frames.size(); ++f) {
    frame = take.frames[f];
    if (labeller) relabelled += std::size_t(labeller->check(frame).relabelled);
    setup.mapper->process(frame, mapped);
    solver.solve(mapped.targets, mapped.present, result);
    held_head += mapped.head_held;
    held_face += result.held;
    const Eigen::Vector3d euler = mapped.head_rotation.toRotationMatrix().eulerAngles(1, 0, 2);  // yaw (Y), pitch (X), roll (Z)
    auto wrap = [](double a) { return a > std::numbers::pi / 2 ? a - std::numbers::pi : a < -std::numbers::pi / 2 ? a + std::numbers::pi : a; };
    if (csv) {
      formats::FaceFrame out;
      out.source_time_ns = frame.source_time_ns;
      out.timecode = frame.timecode.valid() ? frame.timecode : timecode_at(frame.source_time_ns);
      for (std::size_t a = 0; a < formats::kArkitShapeCount; ++a) {
        double w = 0;
        for (std::size_t s : arkit[a]) w += result.weights[Eigen::Index(s)];
        out.weights[a] = arkit[a].empty() ? 0.0f : float(w / double(arkit[a].size()));
      }
      out.angles = {};
      out.angles[0] = float(wrap(euler[0]));
      out.angles[1] = float(wrap(euler[1]));
      out.angles[2] = float(wrap(euler[2]));
      face.frames.push_back(out);
    } else {
      solved.frame_no = frame.frame_no;
      solved.source_time_ns = frame.source_time_ns;
      solved.timecode = frame.timecode;
      solved.head_rotation = mapped.head_rotation;
      solved.head_translation = mapped.head_translation;
      solved.weights = result.weights.cast<float>();
      if (o.vertices) solved.vertices = result.vertices.cast<float>();
      solved.stage_ns = result.stage_ns;
      solved.collision_constraints = result.collision_constraints;
      solved.markers_used = result.markers_used;
      solved.flags = (mapped.head_held ? kSolvedHeadPoseHeld : 0u) | (result.held ? kSolvedTooFewMarkers : 0u);
      recording->append_marker_frame(frame);
      recording->append_solved_frame(solved);
    }
    bar.update(f + 1, take.frames.size());
  }
  bar.finish();
  if (csv) {
    const std::string text = formats::write_livelinkface(face);
    write_file_atomically(output, std::span<const char>(text.data(), text.size()));
  } else {
    recording->close();
  }
  std::size_t mapped_shapes = 0;
  for (const auto& a : arkit) mapped_shapes += !a.empty();
  fmt::print("{} -> {}: {} frames with {} ({} of 52 ARKit shapes on the rig); head pose held in {}, face held in {}{}\n",
             o.take, o.output, take.frames.size(), o.solver, mapped_shapes, held_head, held_face,
             labeller ? fmt::format(", {} markers relabelled", relabelled) : std::string());
}

}  // namespace

void add_solve_command(CLI::App& app, int& exit_code) {
  auto opts = std::make_shared<Options>();
  auto* cmd = app.add_subcommand("solve", "Solve a calibrated take offline to a Live Link Face CSV or a .fcrec recording");
  cmd->add_option("--rig", opts->rig, "builtin, an OBJ directory, a rig.toml manifest, or a .gltf/.glb file")->required();
  cmd->add_option("--calib", opts->calib, "Calibration profile from facecap calibrate")->required()->check(CLI::ExistingFile);
  cmd->add_option("--take", opts->take, "Marker take (.trc, .c3d, .fcrec)")->required()->check(CLI::ExistingFile);
  cmd->add_option("-o,--output", opts->output, "out.csv (Live Link Face) or out.fcrec (recording)")->required();
  cmd->add_option("--solver", opts->solver, "nonlinear, linear, dt or meshik (offline only: slow)")->capture_default_str();
  cmd->add_option("--rig-units", opts->rig_units, "Rig units mm|cm|m (default: guessed from the face's size)");
  cmd->add_option("--max-pins", opts->max_pins, "Collision pins per frame at most (offline, more removes more lip crossings)")
      ->capture_default_str()->check(CLI::Range(0, 1024));
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
