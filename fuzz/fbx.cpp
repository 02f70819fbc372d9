// FBX rigs: assimp's FBX reader (Debian's library, not instrumented) through our adapter:
// the mesh and channel checks, welding, triangulation.
#include "fuzz/fuzz_support.hpp"
#include "solver/fbx_rig.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace facecap;
  return fuzz::parse_refusing_errors([&] { parse_fbx_rig(fuzz::bytes_of(data, size), "fuzz.fbx"); });
}
