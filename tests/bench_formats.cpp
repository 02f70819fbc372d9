// Read-time benchmarks of the format readers (not a test: run build/tests/bench_formats).
// Synthetic takes of the 3,000-frame, 38-marker class are read from memory; the largest
// shared files are read from disk when ../shared/data is present.
#include <benchmark/benchmark.h>

#include "core/io.hpp"
#include "formats/c3d.hpp"
#include "formats/livelinkface.hpp"
#include "formats/recording.hpp"
#include "formats/trc.hpp"
#include "tests/test_support.hpp"

using namespace facecap;
using namespace facecap::formats;

namespace {

constexpr std::size_t kFrames = 3000;
constexpr std::size_t kMarkers = 38;

MarkerTake class_take() {
  MarkerTake take;
  take.rate_hz = 120.0;
  take.units = "mm";
  for (std::size_t k = 0; k < kMarkers; ++k) take.labels.push_back("Marker_" + std::to_string(k));
  for (std::size_t f = 0; f < kFrames; ++f) {
    auto& frame = append_empty_frame(take, int64_t(f) + 1, int64_t(f) * 8'333'333);
    for (std::size_t k = 0; k < kMarkers; ++k) {
      if ((f + k) % 50 == 0) continue;  // 2% missing
      frame.markers[k].flags = 0;
      frame.markers[k].position =
          Eigen::Vector3d(100.0 + double(k) + 0.01 * double(f), 1500.25 - double(k), 42.0 * std::sin(0.01 * double(f)));
    }
  }
  return take;
}

void BM_ReadC3d(benchmark::State& state) {
  const auto bytes = write_c3d(class_take());
  for (auto _ : state) benchmark::DoNotOptimize(read_c3d(bytes, "bench.c3d"));
  state.SetBytesProcessed(int64_t(state.iterations() * bytes.size()));
}
BENCHMARK(BM_ReadC3d)->Unit(benchmark::kMillisecond);

void BM_ReadTrc(benchmark::State& state) {
  const std::string text = write_trc(class_take(), "bench.trc");
  for (auto _ : state) benchmark::DoNotOptimize(read_trc(text, "bench.trc"));
  state.SetBytesProcessed(int64_t(state.iterations() * text.size()));
}
BENCHMARK(BM_ReadTrc)->Unit(benchmark::kMillisecond);

void BM_ReadRecording(benchmark::State& state) {
  const auto path = test::scratch_dir("bench-recording") / "bench.fcrec";
  write_recording(path, class_take(), "bench");
  const auto bytes = read_file_bytes(path);
  for (auto _ : state) benchmark::DoNotOptimize(take_from_recording(RecordingReader(bytes, "bench.fcrec")));
  state.SetBytesProcessed(int64_t(state.iterations() * bytes.size()));
}
BENCHMARK(BM_ReadRecording)->Unit(benchmark::kMillisecond);

// The largest shared files of each kind, from disk (page cache warm after the first read).
void BM_ReadSharedFile(benchmark::State& state, const char* relative) {
  const auto path = test::shared_data(relative);
  if (path.empty()) {
    state.SkipWithError(test::missing_shared_data_message(relative).c_str());
    return;
  }
  const bool csv = path.extension() == ".csv";
  for (auto _ : state) {
    if (csv)
      benchmark::DoNotOptimize(read_livelinkface(path));
    else
      benchmark::DoNotOptimize(read_take(path));
  }
  state.SetBytesProcessed(int64_t(state.iterations() * std::filesystem::file_size(path)));
}
BENCHMARK_CAPTURE(BM_ReadSharedFile, livelinkface_alex_rom_3, "livelinkface/alexdjulin_alex_rom_3.csv")
    ->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_ReadSharedFile, trc_JawMoCap, "markers/animface/JawMoCap.trc")->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_ReadSharedFile, c3d_s20_phasespace, "c3d/c3dorg_s20_phasespace_sample.c3d")
    ->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
