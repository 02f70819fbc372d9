#include "tools/eval_take.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <optional>

#include <fmt/format.h>

#include "core/error.hpp"
#include "formats/take.hpp"
#include "pipeline/calibration.hpp"
#include "pipeline/marker_mapper.hpp"
#include "pipeline/solve_pipeline.hpp"
#include "pipeline/source_units.hpp"
#include "solver/collide/folds.hpp"
#include "solver/collide/metrics.hpp"
#include "solver/marker_layout.hpp"
#include "solver/solver_model.hpp"
#include "tools/align_support.hpp"
#include "tools/progress.hpp"
#include "tools/tool_support.hpp"

namespace facecap::tools {
namespace {

struct Summary {
  std::vector<double> values;
  void add(double v) { values.push_back(v); }
  double percentile(double p) {
    if (values.empty()) return std::nan("");
    std::sort(values.begin(), values.end());
    const std::size_t rank = std::max<std::size_t>(1, std::size_t(std::ceil(p / 100.0 * double(values.size()))));
    return values[rank - 1];
  }
  double mean() const {
    double s = 0;
    for (double v : values) s += v;
    return values.empty() ? std::nan("") : s / double(values.size());
  }
  nlohmann::json json() {
    return {{"median", percentile(50)}, {"p95", percentile(95)}, {"mean", mean()}, {"samples", values.size()}};
  }
};

// Flips or crossings per region, split into those the rig's own linear blend of the same
// weights already has and those the solve adds.
struct RegionCounts {
  std::array<int64_t, kFaceRegionCount> in_rig_blend{}, added_by_solve{};
  nlohmann::json json(int64_t frames) const {
    nlohmann::json j = nlohmann::json::object();
    const double n = double(std::max<int64_t>(frames, 1));
    for (int r = 0; r < kFaceRegionCount; ++r)
      j[kFaceRegionNames[r]] = {{"in_rig_blend", double(in_rig_blend[std::size_t(r)]) / n},
                            {"added_by_solve", double(added_by_solve[std::size_t(r)]) / n}};
    return j;
  }
  int64_t added() const { return added_by_solve[0] + added_by_solve[1] + added_by_solve[2]; }
};

// The fold metric (solver/collide/folds.hpp) over a take's frames: frames with a folded
// triangle, folded triangles per region, the largest edge stretch, and the worst frames.
struct FoldTally {
  int64_t frames = 0, folded_frames = 0, flagged_frames = 0;
  std::array<int64_t, kFaceRegionCount> folded_by_region{};
  Summary stretch_mm;
  int64_t stretched_frames = 0;  // edge stretched by more than kTornMm
  std::vector<std::pair<uint32_t, int64_t>> worst;  // (folded triangles, frame), the most folded first
  static constexpr double kTornMm = 20.0;  // an edge stretched this much is a torn face (rig mm)

  void add(const FoldReport& r, double rig_mm, int64_t frame, bool flagged) {
    ++frames;
    folded_frames += r.folded > 0;
    flagged_frames += flagged;
    for (int g = 0; g < kFaceRegionCount; ++g) folded_by_region[std::size_t(g)] += r.folded_by_region[std::size_t(g)];
    stretch_mm.add(r.max_edge_stretch * rig_mm);
    stretched_frames += r.max_edge_stretch * rig_mm > kTornMm;
    if (r.folded > 0) {
      worst.push_back({r.folded, frame});
      std::sort(worst.begin(), worst.end(), [](const auto& a, const auto& b) { return a.first > b.first; });
      if (worst.size() > 5) worst.pop_back();
    }
  }
  nlohmann::json json() {
    nlohmann::json regions = nlohmann::json::object(), worst_frames = nlohmann::json::array();
    for (int g = 0; g < kFaceRegionCount; ++g) regions[kFaceRegionNames[g]] = folded_by_region[std::size_t(g)];
    for (const auto& [count, frame] : worst) worst_frames.push_back({{"frame", frame}, {"folded_triangles", count}});
    return {{"frames", frames},
            {"folded_frames", folded_frames},
            {"flagged_frames", flagged_frames},
            {"folded_triangles_by_region", regions},
            {"max_edge_stretch_mm", {{"max", stretch_mm.percentile(100)}, {"p95", stretch_mm.percentile(95)}}},
            {"frames_stretched_over_20mm", stretched_frames},
            {"worst_frames", worst_frames}};
  }
};

struct SolverRun {
  std::string name;
  bool offline = false;  // too slow to solve every frame: sampled frames only
  std::unique_ptr<FaceSolver> full;                    // every marker, every frame
  std::vector<std::unique_ptr<FaceSolver>> held_out;   // one per face marker, that marker removed
  SolveResult result, held_result;
  Eigen::Matrix3Xd previous, previous2;                // the two previous frames' meshes
  int frames_solved = 0;
  Summary heldout_mm, fit_mm, jitter_mm, solve_ms;
  // The weights sent out (filtered with [filter] weights), their jitter, and for the
  // weight filter's lag the weights as solved and as sent, per frame.
  std::optional<pipeline::OneEuroFilter> weight_filter;
  Eigen::VectorXd weights, previous_weights, previous2_weights;
  Summary weight_jitter;
  std::vector<Eigen::VectorXd> solved_weights_history, sent_weights_history;
  std::vector<Summary> heldout_by_marker;              // one per held-out marker
  // The held-out error scaled by `scale`: in the actor's millimetres.
  nlohmann::json scaled(Summary& s, double scale) {
    Summary out;
    for (const double v : s.values) out.add(v * scale);
    return out.json();
  }
  int64_t intersections = 0, intersection_frames = 0, flipped = 0, flipped_frames = 0, checked_frames = 0;
  RegionCounts flipped_by_region, intersections_by_region;  // per checked frame once divided
  int held = 0;
  // The label consistency check with this solver's previous weights, and the targets it
  // leaves (calibration.marker_consistency_mm > 0).
  std::optional<pipeline::MarkerConsistency> consistency;
  Eigen::Matrix3Xd targets;
  std::vector<uint8_t> present;
  int64_t inconsistent_frames = 0, markers_dropped = 0, pairs_unswapped = 0;
  // The fold metric against the linear blend of the same weights, every solved frame.
  FoldTally folds;
};

// The delay d (seconds) that best explains the filtered values (targets: one column per
// marker; weights: one column) as the unfiltered ones d earlier: argmin_d of the mean
// squared distance |filtered(t) - raw(t - d)| over the columns present, with raw(t - d)
// interpolated linearly between frames; searched in steps of a tenth of a frame up to 20
// frames.
template <typename Matrix>
double filter_lag_s(const std::vector<Matrix>& raw, const std::vector<Matrix>& filtered, double rate_hz) {
  constexpr int kMaxFrames = 20, kSteps = 10;
  double best_cost = std::numeric_limits<double>::infinity(), best_shift = 0.0;
  for (int step = 0; step <= kMaxFrames * kSteps; ++step) {
    const double shift = double(step) / kSteps;
    const auto whole = std::size_t(shift);
    const double frac = shift - double(whole);
    double cost = 0.0;
    std::size_t n = 0;
    for (std::size_t f = whole + 1; f < raw.size(); ++f) {
      const Matrix earlier = (1.0 - frac) * raw[f - whole] + frac * raw[f - whole - 1];
      for (Eigen::Index k = 0; k < earlier.cols(); ++k) {
        const double d2 = (filtered[f].col(k) - earlier.col(k)).squaredNorm();
        if (std::isfinite(d2)) cost += d2, ++n;
      }
    }
    if (n > 0 && cost / double(n) < best_cost) best_cost = cost / double(n), best_shift = shift;
  }
  return best_shift / rate_hz;
}

}  // namespace

nlohmann::json evaluate_take(const TakeEvalOptions& o) {
  if (o.every < 1 || o.offline_every < 1) throw Error("--every and --offline-every must be at least 1");
  const Rig rig = load_rig(o.rig);
  const align::Calibration cal = pipeline::load_calibration({.file = o.calib}, rig);
  // The rig's units as calibrated, unless overridden.
  const double rig_mm = o.rig_units.empty() ? cal.rig_mm_per_unit : rig_mm_per_unit(rig, o.rig_units);
  formats::MarkerTake take = formats::read_take(o.take);
  if (take.frames.empty()) throw file_error(o.take, "the take has no frames");
  for (const LabelSwap& swap : o.swaps) inject_label_swap(take, swap);
  const std::size_t F = o.max_frames > 0 ? std::min<std::size_t>(take.frames.size(), std::size_t(o.max_frames)) : take.frames.size();

  pipeline::require_plausible_units(take, o.units, cal, o.take);
  pipeline::MarkerMapper mapper(cal, take.labels, o.units.empty() ? take.units : o.units, o.settings.mapper);
  if (!mapper.stabilising() && o.settings.mapper.stabilise_head)
    throw file_error(o.take, fmt::format("head stabilisation needs 3 stable markers; {} of the calibration's {} are in the take",
                                         mapper.stable_markers_found(), cal.stable_markers.size()));
  const auto model = build_solver_model(rig, cal.bindings(), o.settings.params, cal.unfitted_shapes());
  const auto methods = select_solvers(o.solvers);

  const Eigen::Index K = mapper.marker_count();
  std::vector<int> face_markers;  // held-out candidates: calibrated, in the take, not stable
  for (Eigen::Index k = 0; k < K; ++k)
    if (mapper.slots()[std::size_t(k)] >= 0 && !mapper.is_stable()[std::size_t(k)]) face_markers.push_back(int(k));

  std::vector<SolverRun> runs;
  for (const SolverMethod method : methods) {
    SolverRun run;
    run.name = kSolverMethods.name(method);
    run.offline = !solver_method_is_realtime(method);
    run.full = make_solver(method, model);
    run.result = run.full->make_result();
    for (std::size_t i = 0; i < face_markers.size(); ++i) run.held_out.push_back(make_solver(method, model));
    run.heldout_by_marker.resize(face_markers.size());
    run.held_result = run.full->make_result();
    if (o.settings.marker_consistency_mm > 0.0)
      run.consistency.emplace(*model, o.settings.marker_consistency_mm / cal.rig_mm_per_unit);
    if (o.settings.filter.weights) run.weight_filter.emplace(pipeline::make_weight_filter(o.settings.filter, run.result.weights.size()));
    runs.push_back(std::move(run));
  }

  // Intersections as in the synthetic eval: pairs that intersect now and not at rest (the
  // ICT neutral already has 124 at the lip corners).
  IntersectionCounter intersections;  // one tree, refitted per pose
  intersections.configure(rig.triangles, rig.neutral);
  const std::vector<TrianglePair> rest_pairs = intersections.pairs(rig.neutral);
  const int64_t neutral_intersections = int64_t(rest_pairs.size());
  auto new_intersections = [&](const Eigen::Matrix3Xd& positions) {
    std::vector<TrianglePair> out;
    for (const auto& p : intersections.pairs(positions))
      if (!std::binary_search(rest_pairs.begin(), rest_pairs.end(), p)) out.push_back(p);
    return out;
  };
  const std::vector<uint8_t> region = triangle_regions(rig);
  FoldDetector folds;
  folds.configure(rig.triangles, region, model->params.fold_crease_degrees, fold_tolerance(rig));
  auto mapped = mapper.make_output();
  // With the filter on, the solvers see filtered targets; fit and held-out error are measured
  // against the unfiltered ones, so that the lag the filter adds counts as error.
  std::optional<pipeline::OneEuroFilter> filter;
  if (o.settings.filter.targets) filter.emplace(pipeline::make_target_filter(o.settings.filter, K, cal.rig_mm_per_unit));
  Eigen::Matrix3Xd raw_targets(3, K);
  std::vector<Eigen::Matrix3Xd> raw_history, filtered_history;  // per frame, for the filter's lag
  Summary stable_mm;
  int head_held = 0;
  std::size_t sampled = 0;
  std::vector<uint8_t> present(static_cast<std::size_t>(K));
  const bool show = o.progress || (stderr_is_terminal() && F >= 200);
  ProgressBar bar("evaluating", show);
  const auto& bindings = model->markers;
  for (std::size_t f = 0; f < F; ++f) {
    mapper.process(take.frames[f], mapped);
    raw_targets = mapped.targets;
    if (filter) {
      filter->filter(mapped.targets, mapped.present, take.frames[f].source_time_ns);
      raw_history.push_back(raw_targets);
      filtered_history.push_back(mapped.targets);
    }
    head_held += mapped.head_held;
    for (std::size_t i = 0; i < mapper.stable_residual_count(); ++i)
      if (const double r = mapper.stable_residual_mm(i); !std::isnan(r)) stable_mm.add(r);
    const bool sample = f % std::size_t(o.every) == 0;
    sampled += sample;
    for (auto& run : runs) {
      const bool run_sample = run.offline ? f % std::size_t(o.offline_every) == 0 : sample;
      if (run.offline && !run_sample) continue;
      run.targets = mapped.targets;
      run.present = mapped.present;
      if (run.consistency) {
        const auto checked = run.consistency->check(run.targets, run.present, run.result.weights);
        run.inconsistent_frames += checked.dropped + checked.unswapped > 0;
        run.markers_dropped += checked.dropped;
        run.pairs_unswapped += checked.unswapped;
      }
      const auto t0 = std::chrono::steady_clock::now();
      run.full->solve(run.targets, run.present, run.result);
      run.solve_ms.add(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
      run.held += (run.result.status & kSolvedTooFewMarkers) != 0;
      run.folds.add(folds.measure(run.result.vertices, rig.linear_blend(run.result.weights)), rig_mm, int64_t(f),
                    (run.result.status & kSolvedFolded) != 0);
      for (Eigen::Index k = 0; k < K; ++k)
        if (mapped.present[std::size_t(k)])
          run.fit_mm.add((binding_point(bindings[std::size_t(k)], run.result.vertices) - raw_targets.col(k)).norm() * rig_mm);
      run.weights = run.result.weights;
      if (run.weight_filter) {
        pipeline::filter_weights(*run.weight_filter, run.weights, take.frames[f].source_time_ns);
        run.solved_weights_history.push_back(run.result.weights);
        run.sent_weights_history.push_back(run.weights);
      }
      if (run.frames_solved >= 2 && !run.offline) {
        // Second difference: how much the mesh (the weights) shake beyond steady motion.
        run.jitter_mm.add(((run.result.vertices - 2.0 * run.previous + run.previous2).colwise().norm().mean()) * rig_mm);
        run.weight_jitter.add((run.weights - 2.0 * run.previous_weights + run.previous2_weights).cwiseAbs().mean());
      }
      run.previous2 = run.frames_solved >= 1 ? run.previous : run.result.vertices;
      run.previous = run.result.vertices;
      run.previous2_weights = run.frames_solved >= 1 ? run.previous_weights : run.weights;
      run.previous_weights = run.weights;
      ++run.frames_solved;
      if (!run_sample) continue;
      const std::vector<TrianglePair> hits = new_intersections(run.result.vertices);
      run.intersections += int64_t(hits.size());
      run.intersection_frames += !hits.empty();
      const std::vector<Eigen::Index> flips = flipped_triangles(rig.triangles, rig.neutral, run.result.vertices);
      run.flipped += int64_t(flips.size());
      run.flipped_frames += !flips.empty();
      // The same weights through the rig's own linear blend: what the shapes already do.
      const Eigen::Matrix3Xd blend = rig.linear_blend(run.result.weights);
      const std::vector<Eigen::Index> blend_flips = flipped_triangles(rig.triangles, rig.neutral, blend);
      for (const Eigen::Index t : flips) {
        auto& counts = std::binary_search(blend_flips.begin(), blend_flips.end(), t) ? run.flipped_by_region.in_rig_blend
                                                                                    : run.flipped_by_region.added_by_solve;
        ++counts[region[std::size_t(t)]];
      }
      const std::vector<TrianglePair> blend_hits = new_intersections(blend);
      for (const auto& p : hits) {
        auto& counts = std::binary_search(blend_hits.begin(), blend_hits.end(), p) ? run.intersections_by_region.in_rig_blend
                                                                                  : run.intersections_by_region.added_by_solve;
        ++counts[std::min(region[std::size_t(p.first)], region[std::size_t(p.second)])];
      }
      ++run.checked_frames;
      for (std::size_t i = 0; i < face_markers.size(); ++i) {
        const int k = face_markers[i];
        if (!mapped.present[std::size_t(k)]) continue;
        std::copy(run.present.begin(), run.present.end(), present.begin());
        present[std::size_t(k)] = 0;
        run.held_out[i]->solve(run.targets, present, run.held_result);
        if (run.held_result.status & kSolvedTooFewMarkers) continue;
        const double error = (binding_point(bindings[std::size_t(k)], run.held_result.vertices) - raw_targets.col(k)).norm() * rig_mm;
        run.heldout_mm.add(error);
        run.heldout_by_marker[i].add(error);
      }
    }
    bar.update(f + 1, F);
  }
  bar.finish();

  nlohmann::json j;
  j["take"] = o.take;
  j["rig"] = {{"name", rig.name}, {"content_hash", fmt::format("{:016x}", rig.content_hash())}};
  j["calib"] = o.calib;
  // As decided for the rig (SolverParams' kByRig settings), not as given.
  j["solver"] = {{"alpha", model->params.alpha},
                 {"mu", model->params.mu},
                 {"beta", model->params.beta},
                 {"weight_refinements", model->params.weight_refinements},
                 {"boundary_hold", model->params.boundary_hold}};
  j["frames"] = F;
  nlohmann::json swaps = nlohmann::json::array();
  for (const LabelSwap& swap : o.swaps)
    swaps.push_back({{"first", swap.first}, {"second", swap.second}, {"start", swap.start}, {"frames", swap.frames}, {"glide", swap.glide}});
  j["injected_swaps"] = swaps;
  j["markers"] = K;
  std::vector<std::string> face_labels, stable_labels;
  for (int k : face_markers) face_labels.push_back(cal.markers[std::size_t(k)].label);
  j["heldout_markers"] = face_labels;
  j["stable_markers"] = cal.stable_markers;
  j["sampling"] = {{"every", o.every},
                   {"sampled_frames", sampled},
                   {"offline_every", o.offline_every},
                   {"what", "every frame is solved with all markers (fit, jitter, timing); held-out error, intersections and "
                            "flips on frames 0, every, 2*every, ...; held-out solvers see only those frames. Offline solvers "
                            "(meshik) are solved on frames 0, offline_every, ... only, and report no jitter"}};
  j["stable_residual_mm"] = stable_mm.json();
  const double rate_hz = take.rate_hz > 0 ? take.rate_hz : 60.0;
  if (filter) {
    const pipeline::OneEuroParams& p = o.settings.filter.target_params;
    j["filter"] = {{"min_cutoff_hz", p.min_cutoff_hz},
                   {"beta", p.beta},
                   {"d_cutoff_hz", p.d_cutoff_hz},
                   {"lag_ms", filter_lag_s(raw_history, filtered_history, rate_hz) * 1e3}};
    if (o.settings.filter.weights)
      j["filter"]["weights"] = {{"min_cutoff_hz", o.settings.filter.weight_params.min_cutoff_hz},
                                {"beta", o.settings.filter.weight_params.beta},
                                {"d_cutoff_hz", o.settings.filter.weight_params.d_cutoff_hz}};
  }
  j["head_pose_held_frames"] = head_held;
  j["rest_intersections"] = neutral_intersections;
  // Rig mm to the actor's mm: take length = rig length / scale, in the take's units.
  const double actor_mm_per_rig_mm = cal.take_mm_per_unit / (cal.take_to_rig.scale * rig_mm);
  j["actor_mm_per_rig_mm"] = actor_mm_per_rig_mm;
  nlohmann::json per = nlohmann::json::object();
  for (auto& run : runs) {
    nlohmann::json by_marker = nlohmann::json::object();
    for (std::size_t i = 0; i < face_markers.size(); ++i)
      by_marker[face_labels[i]] = run.scaled(run.heldout_by_marker[i], actor_mm_per_rig_mm);
    per[run.name] = {{"heldout_mm", run.heldout_mm.json()},
                     {"heldout_actor_mm", run.scaled(run.heldout_mm, actor_mm_per_rig_mm)},
                     {"heldout_actor_mm_by_marker", by_marker},
                     {"fit_mm", run.fit_mm.json()},
                     {"jitter_mm", run.offline ? nlohmann::json(nullptr) : run.jitter_mm.json()},
                     {"weight_jitter", run.offline ? nlohmann::json(nullptr) : run.weight_jitter.json()},
                     {"weight_filter_lag_ms", run.weight_filter ? nlohmann::json(filter_lag_s(run.solved_weights_history,
                                                                                              run.sent_weights_history, rate_hz) * 1e3)
                                                                : nlohmann::json(nullptr)},
                     {"intersections", {{"new_pairs_per_checked_frame", run.checked_frames ? double(run.intersections) / double(run.checked_frames) : 0.0},
                                        {"frames_with_new", run.intersection_frames},
                                        {"added_by_solve_per_checked_frame", double(run.intersections_by_region.added()) / double(std::max<int64_t>(run.checked_frames, 1))},
                                        {"per_checked_frame_by_region", run.intersections_by_region.json(run.checked_frames)}}},
                     {"flipped", {{"triangles_per_checked_frame", run.checked_frames ? double(run.flipped) / double(run.checked_frames) : 0.0},
                                  {"frames_with", run.flipped_frames},
                                  {"added_by_solve_per_checked_frame", double(run.flipped_by_region.added()) / double(std::max<int64_t>(run.checked_frames, 1))},
                                  {"per_checked_frame_by_region", run.flipped_by_region.json(run.checked_frames)}}},
                     {"folds", run.folds.json()},
                     {"marker_consistency", run.consistency ? nlohmann::json{{"frames_with_inconsistent_markers", run.inconsistent_frames},
                                                                             {"markers_dropped", run.markers_dropped},
                                                                             {"pairs_swapped_back", run.pairs_unswapped}}
                                                            : nlohmann::json(nullptr)},
                     {"checked_frames", run.checked_frames},
                     {"frames_solved", run.frames_solved},
                     {"solve_ms", run.solve_ms.json()},
                     {"held_frames", run.held}};
  }
  j["solvers"] = per;
  return j;
}

void print_take_evaluation(const nlohmann::json& j) {
  fmt::print("{}: {} frames, {} markers ({} held out), sampled every {} ({} frames)\n", j["take"].get<std::string>(),
             j["frames"].get<int64_t>(), j["markers"].get<int64_t>(), j["heldout_markers"].size(),
             j["sampling"]["every"].get<int>(), j["sampling"]["sampled_frames"].get<int64_t>());
  fmt::print("stable markers after stabilisation: median {:.3f} mm, p95 {:.3f} mm; head pose held in {} frames\n",
             j["stable_residual_mm"]["median"].get<double>(), j["stable_residual_mm"]["p95"].get<double>(),
             j["head_pose_held_frames"].get<int64_t>());
  fmt::print("\n{:<10} {:>16} {:>16} {:>10} {:>14} {:>10} {:>10}\n", "solver", "held-out mm", "fit mm", "jitter mm",
             "new isect/frm", "flip/frm", "solve ms");
  fmt::print("{:<10} {:>16} {:>16} {:>10} {:>14} {:>10} {:>10}\n", "", "median / p95", "median / p95", "mean",
             fmt::format("(rest has {})", j["rest_intersections"].get<int64_t>()), "", "mean");
  for (const auto& [name, s] : j["solvers"].items()) {
    fmt::print("{:<10} held-out in the actor's mm (x{:.3f}): median {:.2f}, p95 {:.2f}\n", name,
               j["actor_mm_per_rig_mm"].get<double>(), s["heldout_actor_mm"]["median"].get<double>(),
               s["heldout_actor_mm"]["p95"].get<double>());
  }
  for (const auto& [name, s] : j["solvers"].items()) {
    const std::string jitter = s["jitter_mm"].is_null() ? "-" : fmt::format("{:.4f}", s["jitter_mm"]["mean"].get<double>());
    fmt::print("{:<10} {:>7.2f} / {:>6.2f} {:>7.2f} / {:>6.2f} {:>10} {:>14.1f} {:>10.2f} {:>10.3f}\n", name,
               s["heldout_mm"]["median"].get<double>(), s["heldout_mm"]["p95"].get<double>(), s["fit_mm"]["median"].get<double>(),
               s["fit_mm"]["p95"].get<double>(), jitter,
               s["intersections"]["new_pairs_per_checked_frame"].get<double>(), s["flipped"]["triangles_per_checked_frame"].get<double>(),
               s["solve_ms"]["mean"].get<double>());
  }
  for (const auto& [name, s] : j["solvers"].items()) {
    if (s["weight_jitter"].is_null()) continue;
    fmt::print("{:<10} weights sent out: jitter {:.5f} (mean |second difference|){}\n", name, s["weight_jitter"]["mean"].get<double>(),
               s["weight_filter_lag_ms"].is_null() ? "" : fmt::format(", the weight filter's lag {:.0f} ms", s["weight_filter_lag_ms"].get<double>()));
  }
  fmt::print("\nfolds against the rig's linear blend of the same weights, every solved frame:\n");
  for (const auto& [name, s] : j["solvers"].items()) {
    const auto& f = s["folds"];
    fmt::print("{:<10} folded frames {} of {}, lips {} eyelids {} elsewhere {} triangles; edge stretch max {:.2f} mm, "
               "p95 {:.2f} mm, frames over 20 mm {}\n", name, f["folded_frames"].get<int64_t>(), f["frames"].get<int64_t>(),
               f["folded_triangles_by_region"]["lips"].get<int64_t>(), f["folded_triangles_by_region"]["eyelids"].get<int64_t>(),
               f["folded_triangles_by_region"]["elsewhere"].get<int64_t>(), f["max_edge_stretch_mm"]["max"].get<double>(),
               f["max_edge_stretch_mm"]["p95"].get<double>(), f["frames_stretched_over_20mm"].get<int64_t>());
  }
  fmt::print("\nper checked frame, added by the solve (already in the rig's linear blend of the same weights):\n");
  for (const auto& [name, s] : j["solvers"].items()) {
    std::string line;
    for (const char* what : {"flipped", "intersections"})
      for (const char* region : kFaceRegionNames) {
        const auto& r = s[what]["per_checked_frame_by_region"][region];
        line += fmt::format("  {} {} {:.1f} ({:.1f})", what, region, r["added_by_solve"].get<double>(), r["in_rig_blend"].get<double>());
      }
    fmt::print("{:<10}{}\n", name, line);
  }
}

}  // namespace facecap::tools
