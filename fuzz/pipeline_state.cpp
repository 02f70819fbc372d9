// A recording's start state (its STAT chunk's payload): pipeline::decode_pipeline_state.
#include "fuzz/fuzz_support.hpp"
#include "pipeline/pipeline_state.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace facecap;
  return fuzz::parse_refusing_errors([&] {
    pipeline::decode_pipeline_state(std::span(reinterpret_cast<const char*>(data), size), "fuzz.state");
  });
}
