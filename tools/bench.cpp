// facecap bench: every selected solver on the same frames, in one run, on this thread.
// Per-frame total and per-stage times (median, p99), heap allocations per frame
// (counted by the malloc replacement in alloc_counter.cpp, only around solve()), and the
// setup cost of the solver model. Fields: docs/tools.md.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <ctime>
#include <optional>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "core/error.hpp"
#include "core/frame.hpp"
#include "core/time.hpp"
#include "solver/fold_stage.hpp"
#include "solver/marker_layout.hpp"
#include "solver/solver_model.hpp"
#include "tools/alloc_counter.hpp"
#include "pipeline/settings.hpp"
#include "tools/commands.hpp"
#include "tools/solve_config.hpp"
#include "tools/stress.hpp"
#include "tools/tool_support.hpp"

namespace facecap::tools {
namespace {

struct Options {
  std::string rig, weights, solvers = "all";
  int markers = 60;
  long frames = -1;
  long meshik_frames = 20;
  bool json = false;
  bool stress = false;
  std::string worst_dir, pose;
  SolveConfigOptions settings;
};

struct Percentiles {
  double median = 0, p99 = 0;
};

// CPU time of this thread: unlike the solvers' wall-clock stage times it leaves out the
// time other processes held the core, which on a shared box dominates the p99.
int64_t thread_cpu_ns() noexcept {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return int64_t(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

Percentiles summarise(std::vector<double> values) {
  Percentiles p;
  p.median = percentile(values, 50.0);
  p.p99 = percentile(values, 99.0);
  return p;
}

// The stages a solver reports: those with time in any frame; nonlinear always lists the
// five of the paper's pipeline.
bool reported_stage(SolverMethod method, SolveStage stage, const std::vector<double>& times) {
  if (method == SolverMethod::kNonlinear &&
      (stage == SolveStage::kWeights || stage == SolveStage::kBlend || stage == SolveStage::kRhs ||
       stage == SolveStage::kBacksolve || stage == SolveStage::kCollide))
    return true;
  return std::any_of(times.begin(), times.end(), [](double t) { return t > 0; });
}

void run_bench(const Options& o, const SolverParams& params) {
  using Clock = std::chrono::steady_clock;
  const auto solver_list = select_solvers(o.solvers);
  RigLoadReport load;
  const Rig rig = load_rig(o.rig, {}, &load);
  const WeightCurves curves = o.weights.empty() ? builtin_motion_curves(rig, 60.0, o.frames < 0 ? 600 : o.frames)
                                                : livelinkface_curves(o.weights, rig, 0.0, o.frames);
  const std::size_t F = curves.frames.size();
  if (F == 0) throw Error("no frames to bench");
  const auto layout = spread_marker_layout(rig, o.markers);
  const Eigen::Index K = Eigen::Index(layout.size());

  const auto build_start = Clock::now();
  const auto model = build_solver_model(rig, layout, params);
  const double build_s = std::chrono::duration<double>(Clock::now() - build_start).count();

  // Markers from the pose the weights really produce (articulated for the built-in face).
  std::vector<Eigen::Matrix3Xd> targets;
  targets.reserve(F);
  const bool builtin = is_builtin_face(rig);
  for (const auto& w : curves.frames) targets.push_back(marker_positions(truth_pose(rig, builtin, w), layout));
  const std::vector<uint8_t> present(std::size_t(K), 1);

  const bool counting = allocation_counter_works();
  if (!counting) std::fprintf(stderr, "facecap bench: warning: the allocation counter is not interposed; allocations are not reported\n");

  nlohmann::json report;
  report["rig"] = {{"vertices", rig.vertex_count()}, {"triangles", rig.triangle_count()}, {"shapes", rig.shape_count()}};
  report["markers"] = K;
  report["frames"] = F;
  report["setup_s"] = {{"rig_load", load.seconds},
                       {"rig_from_cache", load.from_cache},
                       {"gradients", model->setup.gradients_s},
                       {"factor", model->setup.factor_s},
                       {"modifications", model->setup.modifications_s},
                       {"total", model->setup.total_s},
                       {"build_solver_model", build_s}};
  report["solvers"] = nlohmann::json::object();

  std::vector<std::string> lines;
  for (const SolverMethod method : solver_list) {
    const std::string name(kSolverMethods.name(method));
    auto solver = make_solver(method, model);
    SolveResult result = solver->make_result();
    const std::size_t frames = !solver_method_is_realtime(method) ? std::min<std::size_t>(F, std::size_t(std::max(1L, o.meshik_frames))) : F;
    std::vector<double> total_us(frames), cpu_us(frames);
    std::vector<std::vector<double>> stage_us(kSolveStageCount, std::vector<double>(frames));
    std::vector<double> collision_pairs(frames), collision_pins(frames), fold_measure_us(frames), fold_pins(frames);
    // The fold stage's measurement (x0 + B w and the fold metric) timed on its own, on
    // the solved mesh: the part of the collide stage every Poisson frame pays.
    std::optional<FoldStage> fold_measure;
    std::vector<float> active(std::size_t(rig.shape_count()));
    if (method == SolverMethod::kNonlinear || method == SolverMethod::kDt) fold_measure.emplace(*model);
    uint64_t allocations = 0;
    std::size_t held = 0;
    solver->reset();
    for (std::size_t f = 0; f < frames; ++f) {
      const uint64_t before = counted_allocations();
      const int64_t cpu_start = thread_cpu_ns();
      enable_allocation_counting();
      solver->solve(targets[f], present, result);
      disable_allocation_counting();
      cpu_us[f] = double(thread_cpu_ns() - cpu_start) * 1e-3;
      allocations += counted_allocations() - before;
      held += (result.status & kSolvedTooFewMarkers) != 0;
      total_us[f] = double(result.total_ns) * 1e-3;
      for (std::size_t s = 0; s < kSolveStageCount; ++s) stage_us[s][f] = double(result.stage_ns[s]) * 1e-3;
      collision_pairs[f] = result.collision_pairs;
      collision_pins[f] = result.collision_constraints;
      fold_pins[f] = result.fold_pins;
      if (fold_measure) {
        active_weights(result.weights, model->params.active_weight, active);
        const int64_t start = monotonic_now_ns();
        fold_measure->measure(active.data(), result.vertices);
        fold_measure_us[f] = double(monotonic_now_ns() - start) * 1e-3;
      }
    }
    double sum_us = 0;
    for (double t : total_us) sum_us += t;
    const Percentiles total = summarise(total_us);
    const Percentiles cpu = summarise(cpu_us);
    nlohmann::json entry;
    entry["frames"] = frames;
    entry["total_us"] = {{"median", total.median}, {"p99", total.p99}};
    entry["cpu_us"] = {{"median", cpu.median}, {"p99", cpu.p99}};
    entry["stages_us"] = nlohmann::json::object();
    std::string stage_text;
    for (std::size_t s = 0; s < kSolveStageCount; ++s) {
      const auto stage = SolveStage(s);
      if (!reported_stage(method, stage, stage_us[s])) continue;
      const Percentiles p = summarise(stage_us[s]);
      const std::string stage_name(solve_stage_name(stage));
      entry["stages_us"][stage_name] = {{"median", p.median}, {"p99", p.p99}};
      stage_text += fmt::format("  {} {:.1f}", stage_name, p.median);
    }
    if (fold_measure) {
      const Percentiles measure = summarise(fold_measure_us), pins = summarise(fold_pins);
      entry["folds"] = {{"measure_us", {{"median", measure.median}, {"p99", measure.p99}}},
                        {"pins", {{"median", pins.median}, {"p99", pins.p99}}}};
      stage_text += fmt::format("  (folds: measure {:.1f}, pins {:.0f})", measure.median, pins.median);
    }
    if (reported_stage(method, SolveStage::kCollide, stage_us[std::size_t(SolveStage::kCollide)])) {
      const Percentiles pairs = summarise(collision_pairs), pins = summarise(collision_pins);
      entry["collisions"] = {{"pairs", {{"median", pairs.median}, {"p99", pairs.p99}}},
                             {"pins", {{"median", pins.median}, {"p99", pins.p99}}}};
      stage_text += fmt::format("  (pairs {:.0f}, pins {:.0f})", pairs.median, pins.median);
    }
    const double per_frame = double(allocations) / double(frames);
    entry["allocations_per_frame"] = counting ? nlohmann::json(per_frame) : nlohmann::json(nullptr);
    entry["fps"] = sum_us > 0 ? 1e6 * double(frames) / sum_us : 0.0;
    if (held) entry["held_frames"] = held;
    report["solvers"][name] = entry;
    lines.push_back(fmt::format("{:<10} {:>6} {:>11.1f} {:>11.1f} {:>11.1f} {:>11.1f} {:>9.1f} {:>8}  {}{}", name, frames,
                                total.median, total.p99, cpu.median, cpu.p99, entry["fps"].get<double>(), counting ? fmt::format("{:.2f}", per_frame) : "n/a", stage_text,
                                frames < F ? fmt::format("  (first {} of {} frames: meshik is slow)", frames, F) : ""));
  }

  if (o.json) {
    std::puts(report.dump(2).c_str());
    return;
  }
  fmt::print("rig {}: {} vertices, {} triangles, {} shapes; {} markers; {} frames of {}\n", rig.name, rig.vertex_count(),
             rig.triangle_count(), rig.shape_count(), K, F, curves.source);
  fmt::print("setup: rig load {:.3f} s{}, gradients {:.3f} s, factor {:.3f} s, modifications {:.3f} s, total {:.3f} s\n",
             load.seconds, load.from_cache ? " (cache)" : "", model->setup.gradients_s, model->setup.factor_s,
             model->setup.modifications_s, model->setup.total_s);
  fmt::print("single thread, times in microseconds (wall clock; cpu = this thread's CPU time)\n\n"
             "{:<10} {:>6} {:>11} {:>11} {:>11} {:>11} {:>9} {:>8}  {}\n",
             "solver", "frames", "median", "p99", "cpu median", "cpu p99", "fps", "allocs", "stage medians");
  for (const auto& line : lines) fmt::print("{}\n", line);
}

}  // namespace

void add_bench_command(CLI::App& app, int& exit_code) {
  auto o = std::make_shared<Options>();
  auto* cmd = app.add_subcommand("bench", "Time every selected solver on the same frames (single thread)");
  cmd->add_option("--rig", o->rig, "builtin, an OBJ directory, a rig.toml manifest, or a .gltf/.glb file")->required();
  cmd->add_option("--weights", o->weights, "Live Link Face CSV driving the rig (default: the built-in motion)")->check(CLI::ExistingFile);
  cmd->add_option("--markers", o->markers, "Markers spread over the face")->capture_default_str()->check(CLI::PositiveNumber);
  cmd->add_option("--frames", o->frames, "Frames to solve (default: all of the CSV, or 600 of the built-in motion)")
      ->check(CLI::PositiveNumber);
  cmd->add_option("--solver", o->solvers, "all, or a comma-separated list of solvers")->capture_default_str();
  cmd->add_option("--meshik-frames", o->meshik_frames, "At most this many frames for meshik (it is an offline baseline)")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  cmd->add_flag("--json", o->json, "Print JSON instead of a table");
  cmd->add_flag("--stress", o->stress,
                "Solve the stress corpus (docs/solver.md \"Folds\") instead of timing frames: folded poses per solver");
  cmd->add_option("--worst-dir", o->worst_dir, "With --stress: write each solver's worst pose there as OBJ (and its linear blend)");
  cmd->add_option("--pose", o->pose, "With --stress and --worst-dir: write this pose (by name) instead of the worst");
  add_solve_config_options(*cmd, o->settings);
  cmd->callback([o, &exit_code] {
    const SolverParams params =
        pipeline::solve_settings(load_solve_config(o->settings).values, pipeline::SolveContext::kOffline).params;
    if (o->stress) {
      StressOptions s{.rig = o->rig, .solvers = o->solvers == "all" ? "nonlinear,dt,linear" : o->solvers,
                      .markers = o->markers, .params = params, .worst_dir = o->worst_dir, .pose = o->pose};
      const nlohmann::json report = run_stress(s);
      if (o->json) std::puts(report.dump(2).c_str());
      else print_stress(report);
    } else {
      run_bench(*o, params);
    }
    exit_code = 0;
  });
}

}  // namespace facecap::tools
