// The v4l2 driver's work per frame set (CameraPipeline): two 640x480 IR images of the sim's
// 52 markers rendered as Gaussian dots (~50 blobs each, tests/synthetic_cameras.hpp), blobs
// found and triangulated. Counters p50_us and p99_us are over single sets.
//   build/bench/bench_cameras [--benchmark_filter=...]
#include <algorithm>
#include <chrono>
#include <memory>
#include <vector>

#include <benchmark/benchmark.h>

#include "config/config_file.hpp"
#include "drivers/sim/sim_source.hpp"
#include "drivers/v4l2/camera_pipeline.hpp"
#include "pipeline/calibration.hpp"
#include "pipeline/settings.hpp"
#include "solver/builtin_face.hpp"
#include "tests/synthetic_cameras.hpp"

namespace {

using namespace facecap;
using namespace facecap::drivers::v4l2;

constexpr int kSets = 64;  // distinct rendered sets, cycled

struct Scene {
  config::DaemonConfig config = config::default_config();
  std::shared_ptr<const Rig> rig{std::shared_ptr<const Rig>(), &BuiltinFace::instance().rig()};
  pipeline::Calibration calibration = pipeline::load_calibration(pipeline::calibration_spec(config), *rig);
  drivers::SimSource sim{config.source.sim, rig, pipeline::rest_marker_set(calibration)};
  std::unique_ptr<test::MarkerRenderer> renderer;
  std::vector<test::RenderedSet> sets;

  Scene() {
    sim.open();
    renderer = std::make_unique<test::MarkerRenderer>(test::face_cameras(test::sim_marker_centre_mm(sim)), sim,
                                                      test::RenderOptions{}, 7);
    for (int i = 0; i < kSets; ++i) sets.push_back(renderer->render(2 * i));
  }
  static Scene& instance() {
    static Scene scene;
    return scene;
  }
};

// Times each iteration of `work(set)` and reports the median and the 99th percentile.
template <typename Work>
void timed(benchmark::State& state, Work&& work) {
  const Scene& scene = Scene::instance();
  std::vector<double> us;
  us.reserve(1 << 16);
  std::size_t i = 0;
  for (auto _ : state) {
    const auto start = std::chrono::steady_clock::now();
    work(scene.sets[i++ % scene.sets.size()]);
    us.push_back(std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - start).count());
  }
  std::sort(us.begin(), us.end());
  state.counters["p50_us"] = us[us.size() / 2];
  state.counters["p99_us"] = us[std::min(us.size() - 1, us.size() * 99 / 100)];
}

CameraPipeline make_pipeline() {
  const drivers::V4l2Options o = config::default_config().source.v4l2;
  return CameraPipeline(Scene::instance().renderer->cameras(),
                        {.threshold = int(o.threshold), .min_area_px = int(o.min_blob_area_px),
                         .max_area_px = int(o.max_blob_area_px), .min_roundness = o.min_roundness},
                        {.epipolar_tolerance_px = o.epipolar_tolerance_px,
                         .max_reprojection_px = 1.5 * o.epipolar_tolerance_px});
}

// The whole set: blobs in both images, then triangulation.
void BM_FrameSet(benchmark::State& state) {
  CameraPipeline pipeline = make_pipeline();
  std::vector<Eigen::Vector3d> points;
  int blobs = 0;
  timed(state, [&](const test::RenderedSet& set) {
    for (std::size_t c = 0; c < set.images.size(); ++c) {
      pipeline.detect(c, set.images[c]);
      blobs = int(pipeline.blobs()[c].size());
    }
    pipeline.triangulate(points);
    benchmark::DoNotOptimize(points.data());
  });
  state.counters["blobs_per_image"] = blobs;
  state.counters["points"] = double(points.size());
}
BENCHMARK(BM_FrameSet)->Unit(benchmark::kMicrosecond);

// One image's blobs.
void BM_BlobsOneImage(benchmark::State& state) {
  BlobDetector detector;
  std::vector<Blob> blobs;
  timed(state, [&](const test::RenderedSet& set) { detector.detect(set.images[0], blobs); });
  state.counters["blobs"] = double(blobs.size());
}
BENCHMARK(BM_BlobsOneImage)->Unit(benchmark::kMicrosecond);

// Triangulation of a set's blobs, found beforehand.
void BM_Triangulate(benchmark::State& state) {
  const Scene& scene = Scene::instance();
  std::vector<std::vector<std::vector<Blob>>> found(scene.sets.size(), std::vector<std::vector<Blob>>(2));
  BlobDetector detector;
  for (std::size_t s = 0; s < scene.sets.size(); ++s)
    for (std::size_t c = 0; c < 2; ++c) detector.detect(scene.sets[s].images[c], found[s][c]);
  Triangulator triangulator(scene.renderer->cameras());
  std::vector<Eigen::Vector3d> points;
  std::size_t i = 0;
  timed(state, [&](const test::RenderedSet&) { triangulator.triangulate(found[i++ % found.size()], points); });
  state.counters["points"] = double(points.size());
}
BENCHMARK(BM_Triangulate)->Unit(benchmark::kMicrosecond);

}  // namespace

BENCHMARK_MAIN();
