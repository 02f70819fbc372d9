// Shape-name maps (facecap export --map): rig shape = ARKit name, then bound to a rig's
// names.
#include <array>
#include <string>

#include "fuzz/fuzz_support.hpp"
#include "tools/shape_map.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace facecap;
  static const std::array<std::string, 4> kRigShapes = {"Jaw_Open", "Eye_Blink_L", "Eye_Blink_R", "jawOpen"};
  return fuzz::parse_refusing_errors([&] {
    const tools::ShapeMap map = tools::parse_shape_map(fuzz::text_of(data, size), "fuzz.toml");
    tools::bind_shape_map(map, kRigShapes);
  });
}
