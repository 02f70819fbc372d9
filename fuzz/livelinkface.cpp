// Live Link Face CSV: read, and what was read written and read again.
#include "formats/livelinkface.hpp"
#include "fuzz/fuzz_support.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace facecap;
  return fuzz::parse_refusing_errors([&] {
    const formats::FaceTake take = formats::read_livelinkface(fuzz::text_of(data, size), "fuzz.csv");
    formats::read_livelinkface(formats::write_livelinkface(take), "rewritten.csv");
  });
}
