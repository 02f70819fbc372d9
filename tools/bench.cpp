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
#include "solver/blend_terms.hpp"
#include "solver/fold_stage.hpp"
#include "solver/kernels/kernels.hpp"
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
  std::string kernels;  // empty: the configuration's solver.kernels
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

// How fast one core reads memory that is not in its caches: the best of three passes
// summing a buffer four times the size of a large last-level cache. The stages that
// stream their data can go no faster than bytes / this.
double read_bandwidth_bytes_per_s() {
  constexpr std::size_t kBytes = std::size_t(128) << 20;
  std::vector<uint64_t> buffer(kBytes / sizeof(uint64_t));
  for (std::size_t i = 0; i < buffer.size(); ++i) buffer[i] = i;
  double best = 0.0;
  volatile uint64_t sink = 0;
  for (int pass = 0; pass < 3; ++pass) {
    const int64_t start = thread_cpu_ns();
    uint64_t s0 = 0, s1 = 0, s2 = 0, s3 = 0;
    for (std::size_t i = 0; i < buffer.size(); i += 4) s0 += buffer[i], s1 += buffer[i + 1], s2 += buffer[i + 2], s3 += buffer[i + 3];
    sink = sink + s0 + s1 + s2 + s3;
    best = std::max(best, double(kBytes) / (double(thread_cpu_ns() - start) * 1e-9));
  }
  return best;
}

// Bytes of `terms` a frame reads for each shape active in it: the shape's stored values,
// scales and offsets (BlendTerms' layout).
std::vector<double> bytes_per_shape(const BlendTerms& terms, Eigen::Index shapes) {
  std::vector<double> bytes(std::size_t(shapes), 0.0);
  const std::size_t values_per_entry = std::size_t(terms.components) * ShapeBlocks::kBlock;
  for (const BlendTerms::BlockRun& run : terms.blocks) {
    int32_t position = run.first;
    for (int w = 0; w < BlendTerms::kWidths; ++w)
      for (int32_t k = 0; k < run.count[w]; ++k, ++position)
        bytes[std::size_t(terms.shape[std::size_t(position)])] +=
            double(values_per_entry * std::size_t(BlendTerms::kBytesPerValue[w]) + std::size_t(terms.components) * 6);
  }
  return bytes;
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

  SolverParams solver_params = params;
  if (!o.kernels.empty()) solver_params.kernels = kKernelPaths.parse(o.kernels).value();
  const auto build_start = Clock::now();
  const auto model = build_solver_model(rig, layout, solver_params);
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
  report["kernels"] = {{"path", kKernelPaths.name(model->kernels->path)}, {"cpu", kernels::cpu_features()}};
  const double bandwidth = read_bandwidth_bytes_per_s();
  report["read_bandwidth_gb_s"] = bandwidth * 1e-9;
  // Per frame, the bytes each streaming stage reads: the blend's terms of the active
  // shapes (and the triangles' rest frames), the factor's entries twice (two sweeps).
  const std::vector<double> triangle_bytes = bytes_per_shape(model->blend.triangle_nonlinear, rig.shape_count());
  const std::vector<double> gradient_bytes = bytes_per_shape(model->blend.triangle_gradient, rig.shape_count());
  const std::vector<double> vertex_bytes = bytes_per_shape(model->blend.vertex_deltas, rig.shape_count());
  const double operator_bytes = double(model->blend.triangle_blocks.element_of_slot.size()) * (9 * 4 + 12);
  const double factor_bytes = 2.0 * double(model->poisson.factor->factor_nonzeros()) * 10.0 +
                              double(model->vertex_count()) * (4 + 4 + 8 + 2 * 32);

  std::vector<std::string> lines, floor_lines;
  for (const SolverMethod method : solver_list) {
    const std::string name(kSolverMethods.name(method));
    auto solver = make_solver(method, model);
    SolveResult result = solver->make_result();
    const std::size_t frames = !solver_method_is_realtime(method) ? std::min<std::size_t>(F, std::size_t(std::max(1L, o.meshik_frames))) : F;
    std::vector<double> total_us(frames), cpu_us(frames);
    std::vector<std::vector<double>> stage_us(kSolveStageCount, std::vector<double>(frames));
    std::vector<double> collision_pairs(frames), collision_pins(frames), blend_bytes(frames), fold_measure_us(frames),
        fold_pins(frames);
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
      const std::vector<double>& shape_bytes = method == SolverMethod::kLinear ? vertex_bytes
                                               : method == SolverMethod::kDt    ? gradient_bytes
                                                                                : triangle_bytes;
      blend_bytes[f] = method == SolverMethod::kLinear ? 0.0 : operator_bytes;
      active_weights(result.weights, model->params.active_weight, model->blend.shape_reach, model->blend.negligible_reach, active);
      for (Eigen::Index s = 0; s < rig.shape_count(); ++s)
        if (active[std::size_t(s)] != 0.0f) blend_bytes[f] += shape_bytes[std::size_t(s)];
      collision_pairs[f] = result.collision_pairs;
      collision_pins[f] = result.collision_constraints;
      fold_pins[f] = result.fold_pins;
      if (fold_measure) {
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
    // Each streaming stage's memory floor (bytes / read bandwidth) and its median over it.
    if (solver_method_is_realtime(method)) {
      const double blend_mb = summarise(blend_bytes).median * 1e-6;
      std::vector<std::pair<SolveStage, double>> floors = {{SolveStage::kBlend, blend_mb * 1e6 / bandwidth * 1e6}};
      if (method != SolverMethod::kLinear) floors.push_back({SolveStage::kBacksolve, factor_bytes / bandwidth * 1e6});
      entry["blend_mb_per_frame"] = blend_mb;
      std::string floor_text;
      for (const auto& [stage, floor_us] : floors) {
        const double median = summarise(stage_us[std::size_t(stage)]).median;
        const std::string stage_name(solve_stage_name(stage));
        entry["floor_us"][stage_name] = floor_us;
        entry["over_floor"][stage_name] = median / floor_us;
        floor_text += fmt::format("{} {:.1f} ({:.1f}x)  ", stage_name, floor_us, median / floor_us);
      }
      floor_lines.push_back(fmt::format("{:<10} {}blend reads {:.2f} MB a frame", name, floor_text, blend_mb));
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
  fmt::print("\nkernels {} (CPU: {}); one core reads {:.1f} GB/s, so each streaming stage's floor, in microseconds, "
             "and its median over it:\n", kKernelPaths.name(model->kernels->path), kernels::cpu_features(), bandwidth * 1e-9);
  for (const auto& line : floor_lines) fmt::print("{}\n", line);
}

}  // namespace

void add_bench_command(CLI::App& app, int& exit_code) {
  auto o = std::make_shared<Options>();
  auto* cmd = app.add_subcommand("bench", "Time every selected solver on the same frames (single thread)");
  cmd->add_option("--rig", o->rig, "builtin, an OBJ directory, a rig.toml manifest, a .gltf/.glb or an .fbx file")->required();
  cmd->add_option("--weights", o->weights, "Live Link Face CSV driving the rig (default: the built-in motion)")->check(CLI::ExistingFile);
  cmd->add_option("--markers", o->markers, "Markers spread over the face")->capture_default_str()->check(CLI::PositiveNumber);
  cmd->add_option("--frames", o->frames, "Frames to solve (default: all of the CSV, or 600 of the built-in motion)")
      ->check(CLI::PositiveNumber);
  cmd->add_option("--solver", o->solvers, "all, or a comma-separated list of solvers")->capture_default_str();
  cmd->add_option("--meshik-frames", o->meshik_frames, "At most this many frames for meshik (it is an offline baseline)")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  cmd->add_option("--kernels", o->kernels,
                  "Which compiled kernels solve: auto (the widest this CPU runs), avx512, avx2 or portable "
                  "(the same as --set solver.kernels=...)")
      ->check(CLI::IsMember([] {
        std::vector<std::string> names;
        for (const auto& name : kKernelPaths.names()) names.emplace_back(name);
        return names;
      }()));
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
