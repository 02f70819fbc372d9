// Read-time benchmarks of the format readers (not a test: run build/tests/bench_formats).
// Synthetic takes of the 3,000-frame, 38-marker class are read from memory; the largest
// shared files are read from disk when ../shared/data is present.
#include <benchmark/benchmark.h>

#include "core/io.hpp"
#include "drivers/capture/capture_file.hpp"
#include "formats/c3d.hpp"
#include "formats/livelinkface.hpp"
#include "formats/recording.hpp"
#include "formats/trc.hpp"
#include "tests/test_support.hpp"

using namespace facecap;
using namespace facecap::capture;
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

// A facial NatNet frame: 60 labelled markers, the same 60 as a marker set, one head rigid
// body; parsed and encoded at bitstream 3.0 (Motive 2.x) and 4.1 (byte counts).
natnet::Message facial_frame() {
  natnet::FrameOfData frame;
  frame.frame_number = 1000;
  frame.marker_sets.push_back({"Face", {}});
  for (int32_t k = 0; k < 60; ++k) {
    const natnet::Position p{0.01f * float(k), 1.6f + 0.001f * float(k), -0.2f};
    frame.labelled_markers.push_back({1 << 16 | (k + 1), p, 0.003f, 0x0a, 0.0001f});
    frame.marker_sets[0].markers.push_back(p);
  }
  frame.rigid_bodies.push_back({1, {0.f, 1.6f, 0.f}, {0.f, 0.f, 0.f, 1.f}, 0.0002f, 1});
  return {natnet::MessageId::kFrameOfData, frame};
}

void BM_ParseNatNetFrame(benchmark::State& state, natnet::Version bitstream) {
  const auto bytes = natnet::encode_message(facial_frame(), bitstream);
  for (auto _ : state) benchmark::DoNotOptimize(natnet::parse_message(bytes, bitstream, "bench"));
  state.SetBytesProcessed(int64_t(state.iterations() * bytes.size()));
}
BENCHMARK_CAPTURE(BM_ParseNatNetFrame, bitstream_3_0, natnet::kBitstream30)->Unit(benchmark::kMicrosecond);
BENCHMARK_CAPTURE(BM_ParseNatNetFrame, bitstream_4_1, natnet::kBitstream41)->Unit(benchmark::kMicrosecond);

void BM_EncodeNatNetFrame(benchmark::State& state) {
  const natnet::Message frame = facial_frame();
  for (auto _ : state) benchmark::DoNotOptimize(natnet::encode_message(frame, natnet::kBitstream41));
}
BENCHMARK(BM_EncodeNatNetFrame)->Unit(benchmark::kMicrosecond);

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

// The real Motive session: 550 datagrams, 518 frames, through libpcap and the parser.
void BM_ReadNatNetCapture(benchmark::State& state) {
  const auto path = test::shared_data("natnet/traffic.pcapng");
  if (path.empty()) {
    state.SkipWithError(test::missing_shared_data_message("natnet/traffic.pcapng").c_str());
    return;
  }
  for (auto _ : state) benchmark::DoNotOptimize(capture::read_natnet_capture(path));
  state.SetBytesProcessed(int64_t(state.iterations() * std::filesystem::file_size(path)));
}
BENCHMARK(BM_ReadNatNetCapture)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
