#include <cstdio>
#include <fstream>

#include <catch2/catch.hpp>
#include <Eigen/Geometry>
#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "core/error.hpp"
#include "solver/builtin_face.hpp"
#include "solver/solver_model.hpp"
#include "solver/gltf_rig.hpp"
#include "solver/obj_mesh.hpp"
#include "solver/rig.hpp"
#include "solver/rig_cache.hpp"
#include "tests/test_support.hpp"

using namespace facecap;
namespace fs = std::filesystem;
using Catch::Contains;

namespace {

// A tiny two-quad rig written as an ICT-layout directory.
const char* kNeutral =
    "# neutral\n"
    "v 0 0 0\nv 1 0 0\nv 2 0 0\nv 0 1 0\nv 1 1 0\nv 2 1 0\n"
    "vt 0 0\n"
    "f 1/1 2/1 5/1 4/1\n"
    "f 2 3 6 5\n";

std::string shape_text(double lift) {
  return "v 0 0 0\nv 1 0 0\nv 2 0 0\nv 0 1 " + std::to_string(lift) + "\nv 1 1 " + std::to_string(lift) +
         "\nv 2 1 0\nf 1 2 5 4\nf 2 3 6 5\n";
}

fs::path write_small_rig(const std::string& name) {
  const auto dir = test::scratch_dir(name);
  test::write_text(dir / "generic_neutral_mesh.obj", kNeutral);
  test::write_text(dir / "jawOpen.obj", shape_text(0.5));
  test::write_text(dir / "mouthClose.obj", shape_text(-0.25));
  return dir;
}

RigLoadOptions no_cache() {
  RigLoadOptions o;
  o.use_cache = false;
  return o;
}

using test::run_and_capture;

}  // namespace

TEST_CASE("an OBJ directory loads with quads triangulated and shapes named by file") {
  const auto dir = write_small_rig("obj-dir");
  const Rig rig = load_rig(dir.string(), no_cache());
  CHECK(rig.vertex_count() == 6);
  CHECK(rig.triangle_count() == 4);
  REQUIRE(rig.shape_names == std::vector<std::string>{"jawOpen", "mouthClose"});
  CHECK(rig.deltas(3 * 4 + 2, 0) == Approx(0.5));
  CHECK(rig.deltas(3 * 4 + 2, 1) == Approx(-0.25));
  CHECK(rig.deltas.col(0).cwiseAbs().sum() == Approx(1.0));  // vertices 3 and 4 move 0.5 each
}

TEST_CASE("a TOML manifest names the neutral and the shapes") {
  const auto dir = write_small_rig("manifest");
  test::write_text(dir / "face.toml", "name = \"tiny\"\nneutral = \"generic_neutral_mesh.obj\"\n[shapes]\nopen = \"jawOpen.obj\"\n");
  const Rig rig = load_rig((dir / "face.toml").string(), no_cache());
  CHECK(rig.name == "tiny");
  CHECK(rig.shape_names == std::vector<std::string>{"open"});
  CHECK_FALSE(rig.hinged);
}

TEST_CASE("a manifest says a rig is hinged, and the cache keeps it") {
  const auto dir = write_small_rig("manifest-hinged");
  test::write_text(dir / "rig.toml", "hinged = true\nneutral = \"generic_neutral_mesh.obj\"\n[shapes]\nopen = \"jawOpen.obj\"\n");
  RigLoadOptions options;
  options.cache_dir = test::scratch_dir("manifest-hinged-cache");
  RigLoadReport first, second;
  CHECK(load_rig(dir.string(), options, &first).hinged);
  CHECK(load_rig(dir.string(), options, &second).hinged);
  CHECK(second.from_cache);
  // The solver's kByRig settings follow it (SolverParams).
  const Rig hinged = load_rig(dir.string(), no_cache());
  const std::vector<MarkerBinding> markers{MarkerBinding::at_vertex("a", 0), MarkerBinding::at_vertex("b", 4),
                                           MarkerBinding::at_vertex("c", 5)};
  SolverParams by_rig;
  by_rig.collision_region = CollisionRegion::kNone;  // this strip has no lips to find
  CHECK(build_solver_model(hinged, markers, by_rig)->params.weight_refinements == 2);

  test::write_text(dir / "rig.toml", "hinged = \"yes\"\nneutral = \"generic_neutral_mesh.obj\"\n[shapes]\nopen = \"jawOpen.obj\"\n");
  CHECK_THROWS_WITH(load_rig(dir.string(), no_cache()), Contains("rig.toml:1:") && Contains("hinged must be true or false"));
}

TEST_CASE("malformed rigs fail with the file and line") {
  const auto dir = write_small_rig("malformed");
  SECTION("non-numeric value") {
    test::write_text(dir / "jawOpen.obj", "v 0 0 0\nv 1 0 abc\n");
    CHECK_THROWS_WITH(load_rig(dir.string(), no_cache()),
                      Contains("jawOpen.obj:2:") && Contains("'abc' is not a number"));
  }
  SECTION("truncated file: a vertex cut short") {
    std::string text = shape_text(0.5);
    test::write_text(dir / "jawOpen.obj", text.substr(0, text.find("v 0 1")) + "v 0 1");
    CHECK_THROWS_WITH(load_rig(dir.string(), no_cache()),
                      Contains("jawOpen.obj:4:") && Contains("truncated"));
  }
  SECTION("truncated file: vertices missing at the end") {
    test::write_text(dir / "mouthClose.obj", "v 0 0 0\nv 1 0 0\nv 2 0 0\n");
    CHECK_THROWS_WITH(load_rig(dir.string(), no_cache()),
                      Contains("mouthClose.obj:3:") && Contains("ends after 3 vertices") && Contains("has 6"));
  }
  SECTION("face index out of range") {
    test::write_text(dir / "generic_neutral_mesh.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\n\nf 1 2 9\n");
    CHECK_THROWS_WITH(load_rig(dir.string(), no_cache()),
                      Contains("generic_neutral_mesh.obj:5:") && Contains("face index 9 out of range"));
  }
  SECTION("vertex count differs between shapes") {
    test::write_text(dir / "jawOpen.obj", shape_text(0.5) + "v 3 3 3\n");
    CHECK_THROWS_WITH(load_rig(dir.string(), no_cache()),
                      Contains("jawOpen.obj:9:") && Contains("all shapes must share its vertices"));
  }
  SECTION("topology differs between shapes") {
    std::string text = shape_text(0.5);
    text.replace(text.find("f 2 3 6 5"), 9, "f 2 3 6 4");
    test::write_text(dir / "jawOpen.obj", text);
    CHECK_THROWS_WITH(load_rig(dir.string(), no_cache()), Contains("jawOpen.obj:8:") && Contains("topology"));
  }
  SECTION("duplicate shape names in a manifest") {
    test::write_text(dir / "rig.toml",
                     "neutral = \"generic_neutral_mesh.obj\"\n[shapes]\njawOpen = \"jawOpen.obj\"\njawOpen = \"mouthClose.obj\"\n");
    CHECK_THROWS_WITH(load_rig(dir.string(), no_cache()), Contains("rig.toml:4:") && Contains("jawOpen"));
  }
  SECTION("duplicate shape names in glTF") {
    Rig rig = load_rig(dir.string(), no_cache());
    rig.shape_names[1] = rig.shape_names[0];
    save_gltf_rig(rig, (dir / "dup.gltf").string());
    CHECK_THROWS_WITH(load_rig((dir / "dup.gltf").string(), no_cache()),
                      Contains("dup.gltf") && Contains("duplicate shape name 'jawOpen'"));
  }
  SECTION("no neutral mesh") {
    fs::remove(dir / "generic_neutral_mesh.obj");
    CHECK_THROWS_WITH(load_rig(dir.string(), no_cache()), Contains("no neutral mesh"));
  }
}

TEST_CASE("hostile OBJ rigs and manifests fail with an Error naming the file and line") {
  const auto dir = write_small_rig("hostile");
  SECTION("a manifest shape path that names a directory") {
    fs::create_directories(dir / "shapes_dir");
    test::write_text(dir / "rig.toml", "neutral = \"generic_neutral_mesh.obj\"\n[shapes]\njawOpen = \"shapes_dir\"\n");
    CHECK_THROWS_WITH(load_rig(dir.string(), no_cache()), Contains("shapes_dir") && Contains("is a directory"));
  }
  SECTION("a neutral with more faces than a shape") {
    std::string text = shape_text(0.5);
    test::write_text(dir / "jawOpen.obj", text.substr(0, text.find("f 2 3 6 5")));
    CHECK_THROWS_WITH(load_rig(dir.string(), no_cache()),
                      Contains("jawOpen.obj:7:") && Contains("ends after 2 triangles") && Contains("has 4"));
  }
  SECTION("a shape with more faces than the neutral") {
    test::write_text(dir / "jawOpen.obj", shape_text(0.5) + "f 1 2 4\n");
    CHECK_THROWS_WITH(load_rig(dir.string(), no_cache()),
                      Contains("jawOpen.obj:9:") && Contains("triangle 5 is one more than the neutral"));
  }
  SECTION("nan and inf coordinates") {
    for (const char* bad : {"nan", "inf", "-infinity", "NaN"}) {
      test::write_text(dir / "mouthClose.obj", fmt::format("v 0 0 0\nv 1 {} 0\n", bad));
      CHECK_THROWS_WITH(load_rig(dir.string(), no_cache()),
                        Contains("mouthClose.obj:2:") && Contains(fmt::format("'{}' is not a finite number", bad)));
    }
  }
  SECTION("a manifest with an unknown key") {
    test::write_text(dir / "rig.toml", "neutral = \"generic_neutral_mesh.obj\"\nshape = 1\n[shapes]\njawOpen = \"jawOpen.obj\"\n");
    CHECK_THROWS_WITH(load_rig(dir.string(), no_cache()), Contains("rig.toml:2:") && Contains("unknown key 'shape'"));
  }
  SECTION("a manifest that is not UTF-8") {
    test::write_text(dir / "rig.toml", "neutral = \"generic_neutral_mesh.obj\"\nname = \"a\xff\"\n");
    CHECK_THROWS_WITH(load_rig(dir.string(), no_cache()), Contains("rig.toml:2:10") && Contains("0xff") && Contains("not valid UTF-8"));
  }
}

TEST_CASE("hostile glTF rigs and cache entries fail with an Error before anything large is allocated") {
  const Rig& builtin = BuiltinFace::instance().rig();
  const auto dir = test::scratch_dir("hostile-gltf");
  save_gltf_rig(builtin, (dir / "face.gltf").string());
  const std::string json = test::slurp(dir / "face.gltf");
  auto parse = [](const std::string& text) { return parse_gltf_rig(std::span<const char>(text.data(), text.size()), "x.gltf", false); };
  CHECK(parse(json).shape_count() == builtin.shape_count());
  auto replaced = [&](const std::string& from, const std::string& to) {
    std::string text = json;
    const auto at = text.find(from);
    REQUIRE(at != std::string::npos);
    return text.replace(at, from.size(), to);
  };
  // An accessor count the buffer cannot hold: it was allocated before the range check,
  // and count * stride could wrap.
  const std::string count = fmt::format("\"count\": {}", builtin.vertex_count());
  CHECK_THROWS_WITH(parse(replaced(count, "\"count\": 2305843009213693952")),
                    Contains("x.gltf [meshes[0].primitives[0].attributes.POSITION]") && Contains("do not fit in bufferView"));
  // A buffer given as a file is not read from bytes (the fuzzers pass no directory).
  {
    std::string external = json;
    const auto uri = external.find("data:application/octet-stream;base64,");
    external.replace(uri, external.find('"', uri) - uri, "face.bin");
    CHECK_THROWS_WITH(parse(external), Contains("external file 'face.bin' not read"));
  }
  // Target names that are not strings.
  CHECK_THROWS_WITH(parse(replaced("\"targetNames\": [", "\"targetNames\": [7,")), Contains("must be a string"));

  // A cache entry naming 100,000 shapes and holding no deltas for them: 6174 x 3 x 100,000
  // doubles (15 GB) were allocated before the read failed.
  Rig wide = builtin;
  wide.deltas.resize(wide.deltas.rows(), 0);
  wide.shape_names.clear();
  for (int s = 0; s < 100000; ++s) wide.shape_names.push_back(fmt::format("s{}", s));
  CHECK_THROWS_WITH(deserialize_rig(serialize_rig(wide, RigCacheKey{3}), RigCacheKey{3}, "wide.fcrig"),
                    Contains("wide.fcrig") && Contains("100000 shapes of 6174 vertices do not fit"));
}

TEST_CASE("glTF morph targets round-trip through .gltf and .glb") {
  const Rig& builtin = BuiltinFace::instance().rig();
  const auto dir = test::scratch_dir("gltf");
  for (const char* name : {"face.gltf", "face.glb"}) {
    save_gltf_rig(builtin, (dir / name).string());
    const Rig back = load_rig((dir / name).string(), no_cache());
    CHECK(back.shape_names == builtin.shape_names);
    CHECK(back.triangles == builtin.triangles);
    CHECK((back.neutral - builtin.neutral).cwiseAbs().maxCoeff() < 1e-5);
    CHECK((back.deltas - builtin.deltas).cwiseAbs().maxCoeff() < 1e-5);
  }
}

TEST_CASE("the binary cache returns the same rig and survives damage") {
  const auto dir = write_small_rig("cache");
  RigLoadOptions options;
  options.cache_dir = test::scratch_dir("cache-store");
  RigLoadReport first, second, third;
  const Rig a = load_rig(dir.string(), options, &first);
  const Rig b = load_rig(dir.string(), options, &second);
  CHECK_FALSE(first.from_cache);
  CHECK(second.from_cache);
  CHECK(a.content_hash() == b.content_hash());
  CHECK(a.shape_names == b.shape_names);

  // Flip one payload byte: the checksum rejects it and the rig is parsed again.
  {
    std::fstream f(second.cache_file, std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(100);
    char c = 0;
    f.read(&c, 1);
    f.seekp(100);
    c = char(c ^ 0x5a);
    f.write(&c, 1);
  }
  const Rig c = load_rig(dir.string(), options, &third);
  CHECK_FALSE(third.from_cache);
  CHECK(c.content_hash() == a.content_hash());

  // Editing a source file changes the key: no stale cache hit.
  test::write_text(dir / "jawOpen.obj", shape_text(0.75));
  RigLoadReport fourth;
  const Rig d = load_rig(dir.string(), options, &fourth);
  CHECK_FALSE(fourth.from_cache);
  CHECK(d.deltas(3 * 4 + 2, 0) == Approx(0.75));

  // An empty rig round-trips (its null data() pointers never reach memcpy: a UBSan finding).
  const Rig empty = deserialize_rig(serialize_rig(Rig{}, RigCacheKey{5}), RigCacheKey{5}, "empty.fcrig");
  CHECK(empty.vertex_count() == 0);
  CHECK(empty.shape_count() == 0);

  const auto bytes = serialize_rig(a, RigCacheKey{7});
  CHECK_THROWS_WITH(deserialize_rig(bytes, RigCacheKey{8}, "x.fcrig"), Contains("x.fcrig") && Contains("key"));
  auto truncated = bytes;
  truncated.resize(bytes.size() / 2);
  CHECK_THROWS_WITH(deserialize_rig(truncated, RigCacheKey{7}, "x.fcrig"), Contains("x.fcrig @ byte"));
}

TEST_CASE("the built-in face has the size and names asked for and shapes equal to the articulated pose") {
  const BuiltinFace& face = BuiltinFace::instance();
  const Rig& rig = face.rig();
  CHECK(rig.vertex_count() >= 5000);
  CHECK(rig.shape_count() >= 24);
  for (const char* name : {"jawOpen", "mouthPucker", "mouthFunnel", "mouthSmile_L", "mouthSmile_R", "eyeBlink_L",
                           "eyeBlink_R", "browInnerUp_L", "browInnerUp_R", "mouthClose", "cheekPuff_L"})
    CHECK(rig.shape_index(name).has_value());
  CHECK(guess_face_units(bounding_box(rig.neutral)) == "cm");
  CHECK(face.upper_lip_vertices().size() >= 20);
  CHECK(face.upper_lip_vertices().size() == face.lower_lip_vertices().size());
  // Every triangle is used and faces +Z (towards the viewer) in the neutral.
  int facing_viewer = 0;
  for (Eigen::Index t = 0; t < rig.triangle_count(); ++t) {
    const Eigen::Vector3d a = rig.neutral.col(rig.triangles(0, t)), b = rig.neutral.col(rig.triangles(1, t)),
                          c = rig.neutral.col(rig.triangles(2, t));
    facing_viewer += (b - a).cross(c - a).z() > 0 ? 1 : 0;
  }
  CHECK(facing_viewer == rig.triangle_count());
  // At one-hot weights the articulated pose is the stored shape.
  for (Eigen::Index s = 0; s < rig.shape_count(); ++s) {
    Eigen::VectorXd w = Eigen::VectorXd::Zero(rig.shape_count());
    w[s] = 1.0;
    CHECK((face.articulated_pose(w) - rig.shape_positions(s)).cwiseAbs().maxCoeff() < 1e-12);
  }
}

TEST_CASE("at jawOpen 0.5 the linear blend shortens the chin's hinge radius and the articulated pose keeps it") {
  const BuiltinFace& face = BuiltinFace::instance();
  const Rig& rig = face.rig();
  Eigen::VectorXd w = Eigen::VectorXd::Zero(rig.shape_count());
  w[*rig.shape_index("jawOpen")] = 0.5;
  const int chin = face.chin_vertex();
  auto radius = [&](const Eigen::Matrix3Xd& pose) {
    Eigen::Vector3d r = pose.col(chin) - face.jaw_hinge_point();
    r.x() = 0.0;  // distance to the hinge line along +X
    return r.norm();
  };
  const double rest = radius(rig.neutral);
  const double linear = radius(rig.linear_blend(w));
  const double articulated = radius(face.articulated_pose(w));
  INFO("chin radius rest " << rest << " cm, linear " << linear << " cm, articulated " << articulated << " cm");
  CHECK(articulated == Approx(rest).margin(1e-9));
  // Chord midpoint of a 25 degree arc: r (1 - cos 12.5 deg), about 2.4% of the radius.
  CHECK(rest - linear == Approx(rest * (1.0 - std::cos(face.jaw_open_radians() / 2))).epsilon(1e-6));
  CHECK(rest - linear > 0.1);  // more than a millimetre
}

TEST_CASE("the built-in motion stays in the unit box and moves the jaw and the lids") {
  const BuiltinFace& face = BuiltinFace::instance();
  const auto jaw = *face.rig().shape_index("jawOpen");
  const auto blink = *face.rig().shape_index("eyeBlink_L");
  double max_jaw = 0, max_blink = 0;
  for (double t = 0; t < 10.0; t += 1.0 / 120) {
    const Eigen::VectorXd w = face.motion_weights(t);
    REQUIRE(w.minCoeff() >= 0.0);
    REQUIRE(w.maxCoeff() <= 1.0);
    max_jaw = std::max(max_jaw, w[jaw]);
    max_blink = std::max(max_blink, w[blink]);
  }
  CHECK(max_jaw > 0.5);
  CHECK(max_blink > 0.9);
}

TEST_CASE("ICT FaceKit has 6706 vertices and 13120 triangles and 57 shapes") {
  FACECAP_REQUIRE_SHARED_DATA(dir, "ict-face");
  const Rig rig = load_rig(dir.string(), no_cache());
  CHECK(rig.vertex_count() == 6706);
  CHECK(rig.triangle_count() == 13120);
  CHECK(rig.shape_count() == 57);
  CHECK(guess_face_units(bounding_box(rig.neutral)) == "cm");
  CHECK(max_shape_displacement(rig)[*rig.shape_index("PupilDilate_L")] < 1e-5);  // moves nothing but rounding
}

TEST_CASE("facecap inspect-rig --json on the ICT rig and the built-in face") {
  const std::string tool = std::string(FACECAP_BINARY_DIR) + "/tools/facecap";
  int status = -1;
  const auto cache = test::scratch_dir("inspect-cache");
  const nlohmann::json builtin = nlohmann::json::parse(run_and_capture(tool + " inspect-rig builtin --json", &status));
  CHECK(status == 0);
  CHECK(builtin["vertices"].get<int>() >= 5000);
  CHECK(builtin["shape_names"].size() == builtin["shapes"].get<std::size_t>());
  CHECK(builtin["bbox"]["max"].size() == 3);

  run_and_capture(tool + " inspect-rig /nonexistent/rig 2>&1", &status);
  CHECK(WEXITSTATUS(status) == 1);

  FACECAP_REQUIRE_SHARED_DATA(dir, "ict-face");
  const std::string command = "FACECAP_CACHE_DIR=" + cache.string() + " " + tool + " inspect-rig " + dir.string() + " --json";
  const nlohmann::json ict = nlohmann::json::parse(run_and_capture(command, &status));
  CHECK(status == 0);
  CHECK(ict["vertices"] == 6706);
  CHECK(ict["triangles"] == 13120);
  CHECK(ict["shapes"] == 57);
  CHECK(ict["units_guess"] == "cm");
  const nlohmann::json again = nlohmann::json::parse(run_and_capture(command, &status));
  CHECK(again["load"]["from_cache"] == true);
  CHECK(again["content_hash"] == ict["content_hash"]);
}
