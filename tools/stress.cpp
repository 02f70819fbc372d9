#include "tools/stress.hpp"

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <fstream>

#include <fmt/format.h>

#include "core/error.hpp"
#include "solver/collide/folds.hpp"
#include "solver/marker_layout.hpp"
#include "solver/solver_model.hpp"
#include "solver/stress_corpus.hpp"
#include "tools/tool_support.hpp"

namespace facecap::tools {
namespace {

void write_obj(const std::filesystem::path& path, const Eigen::Matrix3Xd& vertices, const Eigen::Matrix3Xi& triangles) {
  std::ofstream out(path);
  if (!out) throw Error(fmt::format("{}: cannot write", path.string()));
  for (Eigen::Index v = 0; v < vertices.cols(); ++v) out << fmt::format("v {} {} {}\n", vertices(0, v), vertices(1, v), vertices(2, v));
  for (Eigen::Index t = 0; t < triangles.cols(); ++t)
    out << fmt::format("f {} {} {}\n", triangles(0, t) + 1, triangles(1, t) + 1, triangles(2, t) + 1);
}

}  // namespace

nlohmann::json run_stress(const StressOptions& o) {
  const Rig rig = load_rig(o.rig);
  const auto layout = spread_marker_layout(rig, o.markers);
  const auto model = build_solver_model(rig, layout, o.params);
  const std::vector<StressPose> corpus = stress_corpus(rig, layout);
  const double mm_per_rig = 1.0 / rig_units_per_mm(rig);
  FoldDetector folds;
  folds.configure(rig.triangles, triangle_regions(rig), model->params.fold_crease_degrees, fold_tolerance(rig));
  const std::vector<uint8_t> present(layout.size(), 1);

  nlohmann::json report;
  report["rig"] = {{"name", rig.name}, {"vertices", rig.vertex_count()}, {"triangles", rig.triangle_count()}, {"shapes", rig.shape_count()}};
  report["markers"] = layout.size();
  report["poses"] = corpus.size();
  report["fold_max_pins"] = model->params.fold_max_pins;
  report["fold_crease_degrees"] = model->params.fold_crease_degrees;
  nlohmann::json kinds = nlohmann::json::object();
  for (const auto& pose : corpus) kinds[pose.kind] = kinds.value(pose.kind, 0) + 1;
  report["poses_by_kind"] = kinds;
  report["solvers"] = nlohmann::json::object();
  for (const SolverMethod method : select_solvers(o.solvers)) {
    if (!solver_method_is_realtime(method)) continue;  // meshik: seconds per pose
    auto solver = make_solver(method, model);
    SolveResult result = solver->make_result();
    int64_t folded_poses = 0, folded_triangles = 0, fold_pins = 0, flagged = 0;
    nlohmann::json folded_by_kind = nlohmann::json::object(), by_region = nlohmann::json::object();
    std::array<int64_t, kFaceRegionCount> region_counts{};
    double max_stretch = 0.0;
    std::vector<double> solve_ms;
    std::size_t worst = 0;
    uint32_t worst_count = 0;
    std::vector<std::string> folded_names;
    for (std::size_t p = 0; p < corpus.size(); ++p) {
      const StressPose& pose = corpus[p];
      const auto t0 = std::chrono::steady_clock::now();
      solver->solve_with_weights(pose.weights, pose.targets, present, result);
      solve_ms.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
      const FoldReport& r = folds.measure(result.vertices, rig.linear_blend(pose.weights));
      max_stretch = std::max(max_stretch, r.max_edge_stretch * mm_per_rig);
      fold_pins += result.fold_pins;
      flagged += (result.status & kSolvedFolded) != 0;
      if (r.folded == 0) continue;
      ++folded_poses;
      folded_triangles += r.folded;
      for (int g = 0; g < kFaceRegionCount; ++g) region_counts[std::size_t(g)] += r.folded_by_region[std::size_t(g)];
      folded_by_kind[pose.kind] = folded_by_kind.value(pose.kind, 0) + 1;
      if (folded_names.size() < 20) folded_names.push_back(fmt::format("{} ({})", pose.name, r.folded));
      if (r.folded > worst_count) worst_count = r.folded, worst = p;
    }
    for (int g = 0; g < kFaceRegionCount; ++g) by_region[kFaceRegionNames[g]] = region_counts[std::size_t(g)];
    nlohmann::json entry = {{"folded_poses", folded_poses},
                            {"folded_poses_by_kind", folded_by_kind},
                            {"folded_triangles", folded_triangles},
                            {"folded_triangles_by_region", by_region},
                            {"flagged_folded", flagged},
                            {"max_edge_stretch_mm", max_stretch},
                            {"fold_pins_per_pose", double(fold_pins) / double(std::max<std::size_t>(corpus.size(), 1))},
                            {"solve_ms", {{"median", percentile(solve_ms, 50.0)}, {"p99", percentile(solve_ms, 99.0)}}},
                            {"first_folded", folded_names}};
    if (worst_count > 0) entry["worst"] = {{"pose", corpus[worst].name}, {"folded_triangles", worst_count}};
    if (!o.pose.empty()) {
      const auto it = std::find_if(corpus.begin(), corpus.end(), [&](const StressPose& p) { return p.name == o.pose; });
      if (it == corpus.end()) throw Error(fmt::format("--pose '{}': no such pose in the corpus", o.pose));
      worst = std::size_t(it - corpus.begin());
    }
    if (!o.worst_dir.empty() && (worst_count > 0 || !o.pose.empty())) {
      std::filesystem::create_directories(o.worst_dir);
      solver->solve_with_weights(corpus[worst].weights, corpus[worst].targets, present, result);
      const std::string stem = fmt::format("{}/{}-{}", o.worst_dir, rig.name, kSolverMethods.name(method));
      write_obj(stem + ".obj", result.vertices, rig.triangles);
      write_obj(stem + "-linear.obj", rig.linear_blend(corpus[worst].weights), rig.triangles);
      folds.measure(result.vertices, rig.linear_blend(corpus[worst].weights));
      std::ofstream list(stem + "-folded.txt");
      for (const int t : folds.folded_triangles()) list << t << "\n";
      entry["written"] = {{"pose", corpus[worst].name}, {"obj", stem + ".obj"}, {"folded_triangles", folds.report().folded}};
    }
    report["solvers"][std::string(kSolverMethods.name(method))] = entry;
  }
  return report;
}

void print_stress(const nlohmann::json& j) {
  fmt::print("stress corpus on {}: {} poses ({}), {} markers; fold pins at most {}, crease {} degrees\n",
             j["rig"]["name"].get<std::string>(), j["poses"].get<int64_t>(), j["poses_by_kind"].dump(), j["markers"].get<int64_t>(),
             j["fold_max_pins"].get<int>(), j["fold_crease_degrees"].get<double>());
  fmt::print("{:<10} {:>13} {:>17} {:>18} {:>12} {:>10}  {}\n", "solver", "folded poses", "folded triangles", "max stretch mm",
             "pins/pose", "median ms", "worst");
  for (const auto& [name, s] : j["solvers"].items())
    fmt::print("{:<10} {:>13} {:>17} {:>18.2f} {:>12.2f} {:>10.3f}  {}\n", name, s["folded_poses"].get<int64_t>(),
               s["folded_triangles"].get<int64_t>(), s["max_edge_stretch_mm"].get<double>(), s["fold_pins_per_pose"].get<double>(),
               s["solve_ms"]["median"].get<double>(),
               s.contains("worst") ? fmt::format("{} ({})", s["worst"]["pose"].get<std::string>(), s["worst"]["folded_triangles"].get<uint32_t>()) : "-");
}

}  // namespace facecap::tools
