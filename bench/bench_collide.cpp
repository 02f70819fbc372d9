// Per-frame collision detection (TriangleCollider::detect) and the evaluation metrics.
//   build/bench/bench_collide [--benchmark_filter=...]
// ICT cases run when ../shared/data/ict-face exists (FACECAP_SHARED_DATA overrides).
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <benchmark/benchmark.h>

#include "solver/builtin_face.hpp"
#include "solver/collide/collider.hpp"
#include "solver/collide/lip_region.hpp"
#include "solver/collide/metrics.hpp"
#include "solver/rig.hpp"

namespace {

using namespace facecap;

std::filesystem::path shared_data_dir() {
  if (const char* env = std::getenv("FACECAP_SHARED_DATA"); env && *env) return env;
  return FACECAP_SHARED_DATA_DIR;
}

Eigen::Matrix3Xd blend(const Rig& rig, const std::vector<std::pair<std::string, double>>& weights) {
  Eigen::VectorXd w = Eigen::VectorXd::Zero(rig.shape_count());
  for (const auto& [name, value] : weights)
    if (const auto index = rig.shape_index(name)) w[*index] = value;
  return rig.linear_blend(w);
}

struct Region {
  const char* name;
  bool whole_face;
};

// One detect() per iteration on a fixed pose; counters: triangles, pairs, vertices.
void run_detect(benchmark::State& state, const Rig& rig, const std::vector<int>& candidates,
                const Eigen::Matrix3Xd& positions, double epsilon, bool ignore_rest_contacts) {
  TriangleCollider collider;
  ColliderConfig config;
  config.epsilon = epsilon;
  config.max_pairs = 1 << 16;
  config.ignore_rest_contacts = ignore_rest_contacts;
  collider.configure(rig.triangles, rig.neutral, candidates, config);
  CollisionResult result = collider.make_result();
  for (auto _ : state) {
    collider.detect(positions, result);
    benchmark::DoNotOptimize(result.pairs_found);
  }
  state.counters["triangles"] = double(candidates.size());
  state.counters["pairs"] = result.pairs_found;
  state.counters["vertices"] = result.vertices_found;
  state.counters["depth"] = collider.tree_depth();
}

void register_rig(const std::string& label, std::shared_ptr<const Rig> rig,
                  const std::vector<std::pair<std::string, std::vector<std::pair<std::string, double>>>>& poses,
                  bool with_whole_face) {
  auto lips = std::make_shared<const std::vector<int>>(lip_region_triangles(*rig));
  auto every = std::make_shared<const std::vector<int>>(all_triangles(rig->triangle_count()));
  for (const auto& [pose_name, weights] : poses) {
    auto positions = std::make_shared<const Eigen::Matrix3Xd>(blend(*rig, weights));
    for (bool ignore_rest : {false, true}) {
      const std::string suffix = ignore_rest ? "/ignore_rest_contacts" : "";
      benchmark::RegisterBenchmark((label + "/lips/" + pose_name + suffix).c_str(),
                                   [=](benchmark::State& s) { run_detect(s, *rig, *lips, *positions, 0.01, ignore_rest); })
          ->Unit(benchmark::kMicrosecond);
    }
    if (with_whole_face)
      benchmark::RegisterBenchmark((label + "/face/" + pose_name).c_str(),
                                   [=](benchmark::State& s) { run_detect(s, *rig, *every, *positions, 0.01, false); })
          ->Unit(benchmark::kMicrosecond);
  }
  // Configuration (lip region + tree build), off the real-time path.
  benchmark::RegisterBenchmark((label + "/configure_lips").c_str(), [=](benchmark::State& s) {
    for (auto _ : s) {
      TriangleCollider collider;
      collider.configure(rig->triangles, rig->neutral, lip_region_triangles(*rig), ColliderConfig{});
      benchmark::DoNotOptimize(collider.tree_depth());
    }
  })->Unit(benchmark::kMillisecond);
  // The evaluation metric over the whole mesh, per pose: a counter configured once
  // (as facecap eval would per take), then one count per frame.
  for (const auto& [pose_name, weights] : poses) {
    auto positions = std::make_shared<const Eigen::Matrix3Xd>(blend(*rig, weights));
    benchmark::RegisterBenchmark((label + "/intersection_counter/" + pose_name).c_str(), [=](benchmark::State& s) {
      IntersectionCounter counter;
      counter.configure(rig->triangles, rig->neutral);
      int64_t count = 0;
      for (auto _ : s) benchmark::DoNotOptimize(count = counter.count(*positions));
      s.counters["intersecting"] = double(count);
      s.counters["new_vs_neutral"] = double(count_new_intersecting_pairs(rig->triangles, rig->neutral, *positions));
    })->Unit(benchmark::kMillisecond);
  }
  benchmark::RegisterBenchmark((label + "/intersection_counter/configure").c_str(), [=](benchmark::State& s) {
    for (auto _ : s) {
      IntersectionCounter counter;
      counter.configure(rig->triangles, rig->neutral);
    }
  })->Unit(benchmark::kMillisecond);
}

}  // namespace

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  auto builtin = std::make_shared<const Rig>(BuiltinFace::instance().rig());
  register_rig("builtin", builtin,
               {{"neutral", {}},
                {"mouthClose", {{"mouthClose", 1.0}}},
                {"mouthClose+mouthShrugLower", {{"mouthClose", 1.0}, {"mouthShrugLower", 1.0}}}},
               true);
  const auto ict_dir = shared_data_dir() / "ict-face";
  if (std::filesystem::exists(ict_dir)) {
    auto ict = std::make_shared<const Rig>(load_rig(ict_dir.string()));
    register_rig("ict", ict,
                 {{"neutral", {}},
                  {"jawOpen=0.3", {{"jawOpen", 0.3}}},
                  {"mouthClose=1", {{"mouthClose", 1.0}}},
                  {"mouthRollLower=1", {{"mouthRollLower", 1.0}}},
                  {"mouthRollUpper=1", {{"mouthRollUpper", 1.0}}},
                  {"jawOpen=0.3+mouthClose=0.3", {{"jawOpen", 0.3}, {"mouthClose", 0.3}}},
                  {"jawOpen=1+mouthClose=1", {{"jawOpen", 1.0}, {"mouthClose", 1.0}}}},
                 true);
  } else {
    std::fprintf(stderr, "bench_collide: %s absent, ICT cases skipped\n", ict_dir.string().c_str());
  }
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
