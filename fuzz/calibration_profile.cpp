// Calibration profiles (facecap calibrate's TOML).
#include "fuzz/fuzz_support.hpp"
#include "solver/align/profile.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace facecap;
  return fuzz::parse_refusing_errors(
      [&] { align::read_calibration_profile(fuzz::text_of(data, size), "fuzz-profile.toml"); });
}
