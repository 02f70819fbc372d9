// Rig cache entries. The key expected is the one the header carries, and the fuzz build
// skips the payload checksum, so mutations reach the payload decoder.
#include <cstring>

#include "fuzz/fuzz_support.hpp"
#include "solver/rig_cache.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace facecap;
  RigCacheKey key;
  if (size >= 24) std::memcpy(&key.value, data + 16, sizeof key.value);
  const std::vector<char> bytes(data, data + size);
  return fuzz::parse_refusing_errors([&] { deserialize_rig(bytes, key, "fuzz.fcrig"); });
}
