// TRC: read, and what was read written and read again.
#include "formats/trc.hpp"
#include "fuzz/fuzz_support.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace facecap;
  return fuzz::parse_refusing_errors([&] {
    const formats::MarkerTake take = formats::read_trc(fuzz::text_of(data, size), "fuzz.trc");
    formats::read_trc(formats::write_trc(take, "rewritten.trc"), "rewritten.trc");
  });
}
