// C3D: read, and what was read written and read again.
#include "formats/c3d.hpp"
#include "fuzz/fuzz_support.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace facecap;
  return fuzz::parse_refusing_errors([&] {
    const formats::MarkerTake take = formats::read_c3d(fuzz::bytes_of(data, size), "fuzz.c3d");
    formats::read_c3d(formats::write_c3d(take), "rewritten.c3d");
  });
}
