// .fcrec recordings: the header, index or scan, every frame decoded, and the take view
// (the start state's bytes are fuzzed on their own: pipeline_state.cpp).
// The fuzz build skips chunk checksums (FUZZING_BUILD_MODE_UNSAFE_FOR_PRODUCTION), so
// mutations reach the decoders behind them.
#include "formats/recording.hpp"
#include "fuzz/fuzz_support.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace facecap;
  // As read normally, and salvaged (a HEAD that does not decode or is not first: its copy,
  // or the damaged payload, then the scan).
  for (const bool salvage : {false, true}) {
    fuzz::parse_refusing_errors([&] {
      const formats::RecordingReader reader(fuzz::bytes_of(data, size), "fuzz.fcrec", {.salvage = salvage});
      MarkerFrame markers;
      for (std::size_t i = 0; i < reader.marker_frame_count(); ++i) reader.read_marker_frame(i, markers);
      SolvedFrame solved;
      for (std::size_t i = 0; i < reader.solved_frame_count(); ++i) reader.read_solved_frame(i, solved);
      formats::take_from_recording(reader);
    });
  }
  return 0;
}
