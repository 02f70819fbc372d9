// rig.toml manifests (the OBJ files they name are not read).
#include "fuzz/fuzz_support.hpp"
#include "solver/rig.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace facecap;
  return fuzz::parse_refusing_errors([&] { parse_rig_manifest(fuzz::text_of(data, size), "/fuzz/rig.toml"); });
}
