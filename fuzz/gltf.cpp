// glTF rigs: GLB when the input starts with its magic, else glTF JSON. External buffers
// are refused (no base directory), images never decoded.
#include "fuzz/fuzz_support.hpp"
#include "solver/gltf_rig.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace facecap;
  const bool binary = fuzz::text_of(data, size).starts_with("glTF");
  return fuzz::parse_refusing_errors([&] { parse_gltf_rig(fuzz::bytes_of(data, size), "fuzz.gltf", binary); });
}
