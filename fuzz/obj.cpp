// OBJ meshes, and a shape checked against a neutral: the input up to a line "#shape" is
// the neutral, the rest the shape (as load_obj_rig pairs two files).
#include "fuzz/fuzz_support.hpp"
#include "solver/obj_mesh.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace facecap;
  const std::string_view text = fuzz::text_of(data, size);
  constexpr std::string_view kSeparator = "#shape\n";
  const auto split = text.find(kSeparator);
  return fuzz::parse_refusing_errors([&] {
    const ObjMesh neutral = parse_obj(text.substr(0, split), "neutral.obj");
    if (split == std::string_view::npos) return;
    const ObjMesh shape = parse_obj(text.substr(split + kSeparator.size()), "shape.obj");
    check_shape_matches_neutral(shape, "shape.obj", neutral, "neutral.obj");
  });
}
