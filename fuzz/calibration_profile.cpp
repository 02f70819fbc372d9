// Calibration files as facecapd and the tools read them (pipeline::read_calibration): a
// facecap calibrate profile or a hand-written file, against the built-in face.
#include "fuzz/fuzz_support.hpp"
#include "pipeline/calibration.hpp"
#include "solver/builtin_face.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace facecap;
  static const Rig& rig = BuiltinFace::instance().rig();
  return fuzz::parse_refusing_errors(
      [&] { pipeline::read_calibration(fuzz::text_of(data, size), "fuzz-calibration.toml", rig); });
}
