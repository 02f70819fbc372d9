// facecap eval: solves a synthetic take (from facecap synth) with every selected solver
// and compares with the ground truth: vertex error, jitter, intersecting and flipped
// triangles. Definitions: docs/tools.md. With --calib it evaluates a real, calibrated
// take instead (no truth): leave-one-out held-out marker error and the same mesh
// figures (tools/eval_take.cpp, docs/alignment.md).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>

#include <Eigen/Geometry>
#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "core/error.hpp"
#include "core/units.hpp"
#include "formats/take.hpp"
#include "solver/collide/folds.hpp"
#include "solver/collide/metrics.hpp"
#include "solver/solver_model.hpp"
#include "tools/commands.hpp"
#include "pipeline/settings.hpp"
#include "tools/eval_take.hpp"
#include "tools/solve_config.hpp"
#include "tools/synth_truth.hpp"
#include "tools/tool_support.hpp"

namespace facecap::tools {
namespace {

struct EvalOptions {
  std::string rig, take, truth, solvers = "all", rig_units_override;
  bool json = false;
  bool truth_weights = false;
  // Real takes (--calib).
  std::string calib, take_units;
  int every = 10;
  int offline_every = 200;
  int max_frames = 0;
  bool progress = false;
  std::vector<std::string> swaps;
  SolveConfigOptions settings;
};

// Vertex errors in mm, binned at 1 micrometre: the p95 over millions of samples without
// keeping them. Errors beyond the last bin land in it.
class ErrorHistogram {
 public:
  static constexpr double kBinMm = 0.001;
  static constexpr std::size_t kBins = 200000;  // up to 200 mm
  ErrorHistogram() : bins_(kBins, 0) {}
  void add(double mm) {
    sum_ += mm;
    ++count_;
    bins_[std::min(std::size_t(std::max(mm, 0.0) / kBinMm), kBins - 1)]++;
  }
  double mean() const { return count_ ? sum_ / double(count_) : 0.0; }
  // Upper edge of the bin holding the nearest-rank percentile p.
  double percentile(double p) const {
    if (count_ == 0) return 0.0;
    const uint64_t rank = std::max<uint64_t>(1, uint64_t(std::ceil(p / 100.0 * double(count_))));
    uint64_t seen = 0;
    for (std::size_t b = 0; b < kBins; ++b) {
      seen += bins_[b];
      if (seen >= rank) return double(b + 1) * kBinMm;
    }
    return double(kBins) * kBinMm;
  }

 private:
  std::vector<uint64_t> bins_;
  double sum_ = 0;
  uint64_t count_ = 0;
};

struct SolverRun {
  std::string name;
  std::unique_ptr<FaceSolver> solver;
  SolveResult result;
  ErrorHistogram errors;
  Eigen::Matrix3Xd previous_error;
  double jitter_sum_mm = 0;
  uint64_t jitter_samples = 0;
  int64_t intersections = 0, flipped = 0, frames_with_intersections = 0;
  int64_t folded_frames = 0, folded_triangles = 0;  // against the linear blend of the solved weights
  double max_edge_stretch_mm = 0;
  std::size_t held = 0;
};

void run_eval(const EvalOptions& o, const SolverParams& params) {
  const auto solver_list = select_solvers(o.solvers);
  const std::filesystem::path take_path(o.take);
  const std::filesystem::path truth_path =
      o.truth.empty() ? std::filesystem::path((take_path.parent_path() / take_path.stem()).string() + ".truth.json")
                      : std::filesystem::path(o.truth);
  const SynthTruth truth = read_synth_truth(truth_path);
  const Rig rig = load_rig(o.rig);
  const std::string hash = fmt::format("{:016x}", rig.content_hash());
  if (hash != truth.rig_hash)
    throw file_error(truth_path.string(), fmt::format("the take was made from rig '{}' ({}), not from '{}' ({})",
                                                      truth.rig_name, truth.rig_hash, rig.name, hash));
  if (truth.shape_names != rig.shape_names) throw file_error(truth_path.string(), "the truth's shapes are not the rig's");
  const std::string rig_unit = rig_units(rig, o.rig_units_override.empty() ? truth.rig_units : o.rig_units_override);
  const double mm_per_rig = *millimetres_per_unit(rig_unit);

  const formats::MarkerTake take = formats::read_take(take_path);
  const auto take_mm = millimetres_per_unit(take.units);
  if (!take_mm) throw file_error(o.take, fmt::format("units '{}' are not mm, cm or m", take.units));
  const double take_to_rig = *take_mm / mm_per_rig;
  const std::size_t F = take.frames.size();
  if (F != truth.frame_count())
    throw file_error(o.take, fmt::format("{} frames, the truth has {}", F, truth.frame_count()));
  if (F == 0) throw file_error(o.take, "no frames");

  std::vector<MarkerBinding> bindings;
  for (const auto& label : take.labels) {
    const auto it = std::find(truth.marker_labels.begin(), truth.marker_labels.end(), label);
    if (it == truth.marker_labels.end())
      throw file_error(o.take, fmt::format("marker '{}' is not in the truth manifest {}", label, truth_path.string()));
    const int vertex = truth.marker_vertices[std::size_t(it - truth.marker_labels.begin())];
    if (vertex < 0 || vertex >= rig.vertex_count())
      throw file_error(truth_path.string(), fmt::format("marker '{}' sits on vertex {}, outside the rig", label, vertex));
    bindings.push_back(MarkerBinding::at_vertex(label, vertex));
  }
  const Eigen::Index K = Eigen::Index(bindings.size());

  std::unique_ptr<TruthVerticesReader> truth_vertices;
  if (!truth.vertices_file.empty()) {
    truth_vertices = std::make_unique<TruthVerticesReader>(truth_path.parent_path() / truth.vertices_file);
    if (truth_vertices->vertex_count() != rig.vertex_count() || truth_vertices->frame_count() != int64_t(F))
      throw file_error(truth.vertices_file, fmt::format("{} frames of {} vertices; expected {} of {}", truth_vertices->frame_count(),
                                                        truth_vertices->vertex_count(), F, rig.vertex_count()));
  }
  const std::string truth_source = truth_vertices ? "articulated vertices" : "linear blend of the truth weights";

  const auto model = build_solver_model(rig, bindings, params);
  std::vector<SolverRun> runs;
  for (const SolverMethod method : solver_list) {
    SolverRun run;
    run.name = kSolverMethods.name(method);
    run.solver = make_solver(method, model);
    run.result = run.solver->make_result();
    runs.push_back(std::move(run));
  }

  // Intersections are counted against the neutral's own (ICT's neutral already has some
  // at the lip corners): a pair counts when it intersects now and not at rest.
  IntersectionCounter intersections;  // one tree, refitted per pose
  intersections.configure(rig.triangles, rig.neutral);
  const std::vector<TrianglePair> rest_pairs = intersections.pairs(rig.neutral);
  auto new_intersections = [&](const Eigen::Matrix3Xd& positions) {
    int64_t count = 0;
    for (const auto& p : intersections.pairs(positions))
      count += !std::binary_search(rest_pairs.begin(), rest_pairs.end(), p);
    return count;
  };

  FoldDetector folds;
  folds.configure(rig.triangles, triangle_regions(rig), model->params.fold_crease_degrees, fold_tolerance(rig));

  Eigen::Matrix3Xd targets(3, K), truth_pose_now(3, rig.vertex_count());
  std::vector<uint8_t> present(static_cast<std::size_t>(K));
  int64_t truth_intersections = 0;
  for (std::size_t f = 0; f < F; ++f) {
    // Back to rig space: undo the unit scale and the recorded head motion.
    const Eigen::Matrix3d R = rotation_exp(truth.head_rotation[f]);
    const Eigen::Vector3d& t = truth.head_translation[f];
    for (Eigen::Index k = 0; k < K; ++k) {
      const Marker& m = take.frames[f].markers[std::size_t(k)];
      present[std::size_t(k)] = m.present() && m.position.allFinite();
      targets.col(k) = present[std::size_t(k)] ? Eigen::Vector3d(R.transpose() * (m.position * take_to_rig - t))
                                               : Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN());
    }
    if (truth_vertices) truth_vertices->read(int64_t(f), truth_pose_now);
    else truth_pose_now = rig.linear_blend(truth.weights[f]);
    truth_intersections += new_intersections(truth_pose_now);

    for (auto& run : runs) {
      if (o.truth_weights) run.solver->solve_with_weights(truth.weights[f], targets, present, run.result);
      else run.solver->solve(targets, present, run.result);
      run.held += (run.result.status & kSolvedTooFewMarkers) != 0;
      const Eigen::Matrix3Xd error = run.result.vertices - truth_pose_now;
      for (Eigen::Index v = 0; v < error.cols(); ++v) run.errors.add(error.col(v).norm() * mm_per_rig);
      if (f > 0) {
        run.jitter_sum_mm += (error - run.previous_error).colwise().norm().sum() * mm_per_rig;
        run.jitter_samples += uint64_t(error.cols());
      }
      run.previous_error = error;
      const int64_t pairs = new_intersections(run.result.vertices);
      run.intersections += pairs;
      run.frames_with_intersections += pairs > 0;
      run.flipped += count_flipped_triangles(rig.triangles, rig.neutral, run.result.vertices);
      const FoldReport& fold = folds.measure(run.result.vertices, rig.linear_blend(run.result.weights));
      run.folded_frames += fold.folded > 0;
      run.folded_triangles += fold.folded;
      run.max_edge_stretch_mm = std::max(run.max_edge_stretch_mm, fold.max_edge_stretch * mm_per_rig);
    }
  }

  nlohmann::json report;
  report["frames"] = F;
  report["markers"] = K;
  report["truth"] = truth_source;
  report["weights"] = o.truth_weights ? "truth" : "solved";
  report["truth_intersections"] = truth_intersections;
  report["rest_intersections"] = rest_pairs.size();
  report["solvers"] = nlohmann::json::object();
  for (const auto& run : runs) {
    nlohmann::json entry;
    entry["truth_vertex_mm"] = {{"mean", run.errors.mean()}, {"p95", run.errors.percentile(95.0)}};
    entry["jitter_mm"] = run.jitter_samples ? run.jitter_sum_mm / double(run.jitter_samples) : 0.0;
    entry["intersections"] = run.intersections;
    entry["frames_with_intersections"] = run.frames_with_intersections;
    entry["flipped_triangles"] = run.flipped;
    entry["folds"] = {{"folded_frames", run.folded_frames},
                      {"folded_triangles", run.folded_triangles},
                      {"max_edge_stretch_mm", run.max_edge_stretch_mm}};
    entry["held_frames"] = run.held;
    report["solvers"][run.name] = entry;
  }
  if (o.json) {
    std::puts(report.dump(2).c_str());
    return;
  }
  fmt::print("take {}: {} frames, {} markers; rig {}; truth: {}\n", o.take, F, K, rig.name, truth_source);
  if (o.truth_weights) fmt::print("weights: the truth's (Eq. 2 skipped: solve_with_weights)\n");
  fmt::print("noise {} mm, dropout {}, head motion {} (undone with the recorded head pose)\n", truth.noise_mm, truth.dropout,
             truth.head_motion ? "on" : "off");
  fmt::print("intersecting triangle pairs (not intersecting at rest; {} do) in the truth itself: {} over all frames\n\n",
             rest_pairs.size(), truth_intersections);
  fmt::print("{:<10} {:>14} {:>13} {:>10} {:>14} {:>9} {:>14} {:>12} {:>6}\n", "solver", "error mean mm", "error p95 mm",
             "jitter mm", "intersections", "flipped", "folded frames", "stretch mm", "held");
  for (const auto& run : runs)
    fmt::print("{:<10} {:>14.4f} {:>13.3f} {:>10.4f} {:>14} {:>9} {:>14} {:>12.2f} {:>6}\n", run.name, run.errors.mean(),
               run.errors.percentile(95.0), run.jitter_samples ? run.jitter_sum_mm / double(run.jitter_samples) : 0.0,
               run.intersections, run.flipped, run.folded_frames, run.max_edge_stretch_mm, run.held);
}

}  // namespace

void add_eval_command(CLI::App& app, int& exit_code) {
  auto o = std::make_shared<EvalOptions>();
  auto* cmd = app.add_subcommand("eval", "Evaluate solvers: a synthetic take against its ground truth, or a real take "
                                         "calibrated with --calib by held-out marker error");
  cmd->add_option("--rig", o->rig, "The rig the take was made from (or calibrated to)")->required();
  cmd->add_option("--take", o->take, "The take (.trc, .c3d, .fcrec): from facecap synth, or a real one with --calib")->required()->check(CLI::ExistingFile);
  auto* truth = cmd->add_option("--truth", o->truth, "Its truth manifest (default: <take stem>.truth.json)")->check(CLI::ExistingFile);
  auto* calib = cmd->add_option("--calib", o->calib, "A real take's calibration profile (facecap calibrate): leave-one-out evaluation")
                    ->check(CLI::ExistingFile);
  calib->excludes(truth);
  cmd->add_option("--every", o->every, "With --calib: held-out error and mesh checks on every Nth frame")
      ->capture_default_str()->check(CLI::PositiveNumber)->needs(calib);
  cmd->add_option("--offline-every", o->offline_every, "With --calib: solve offline solvers (meshik) on every Nth frame only")
      ->capture_default_str()->check(CLI::PositiveNumber)->needs(calib);
  cmd->add_option("--units", o->take_units, "With --calib: the take's units mm|cm|m, when it states them wrongly")
      ->check(CLI::IsMember({"mm", "cm", "m"}))
      ->needs(calib);
  cmd->add_option("--max-frames", o->max_frames, "With --calib: only the first N frames (0: all)")->needs(calib);
  cmd->add_option("--inject-swap", o->swaps,
                  "With --calib: two markers trade labels, FIRST:SECOND:START:FRAMES[:GLIDE] (gliding over GLIDE frames at "
                  "each end); repeatable")
      ->needs(calib);
  cmd->add_flag("--progress", o->progress, "With --calib: progress on stderr (default: on a terminal)")->needs(calib);
  cmd->add_option("--solver", o->solvers, "all, or a comma-separated list of solvers")->capture_default_str();
  cmd->add_option("--rig-units", o->rig_units_override, "The rig's units when they cannot be guessed: mm, cm or m");
  cmd->add_flag("--truth-weights", o->truth_weights,
                "Skip the weights step: mesh each frame from the truth weights (isolates the blend from the weight fit)");
  cmd->add_flag("--json", o->json, "Print JSON instead of a table");
  add_solve_config_options(*cmd, o->settings);
  cmd->callback([o, &exit_code] {
    const pipeline::SolveSettings settings = pipeline::solve_settings(load_solve_config(o->settings).values, pipeline::SolveContext::kOffline);
    if (!o->calib.empty()) {
      if (o->truth_weights) throw Error("--truth-weights needs a synthetic take's truth, not --calib");
      TakeEvalOptions t;
      t.rig = o->rig;
      t.take = o->take;
      t.calib = o->calib;
      t.solvers = o->solvers;
      t.rig_units = o->rig_units_override;
      t.units = o->take_units;
      t.every = o->every;
      t.offline_every = o->offline_every;
      t.max_frames = o->max_frames;
      t.progress = o->progress;
      t.settings = settings;
      for (const std::string& spec : o->swaps) t.swaps.push_back(parse_label_swap(spec));
      const auto report = evaluate_take(t);
      if (o->json) std::puts(report.dump(2).c_str());
      else print_take_evaluation(report);
    } else {
      run_eval(*o, settings.params);
    }
    exit_code = 0;
  });
}

}  // namespace facecap::tools
