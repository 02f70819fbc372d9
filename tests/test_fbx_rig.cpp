// FBX rigs: the ICT face written by a real DCC tool (Blender, driven headless by
// tests/make_ict_fbx.py at test time), read through assimp and welded back to the
// artist's vertices; solving a real take on it matches solving on the OBJ rig.
#include <array>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <set>
#include <sstream>

#include <catch2/catch.hpp>
#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <unistd.h>

#include "core/error.hpp"
#include "formats/recording.hpp"
#include "solver/fbx_rig.hpp"
#include "solver/rig.hpp"
#include "tests/test_support.hpp"

using namespace facecap;
namespace fs = std::filesystem;

namespace {

using test::Run;
using test::run_facecap;

// The Blender-written FBX of the ICT face, made once per build tree (renamed into place,
// so tests running in parallel never read half a file); empty, with a warning saying
// what is missing, when blender or the ICT data is absent.
fs::path blender_ict_fbx() {
  const fs::path ict = test::shared_data("ict-face");
  if (ict.empty()) {
    WARN(test::missing_shared_data_message("ict-face"));
    return {};
  }
  int status = 0;
  test::run_and_capture("command -v blender >/dev/null 2>&1", &status);
  if (status != 0) {
    WARN("blender is not installed (Debian package blender; scripts/quickstart.sh test installs it): no FBX written by a "
         "DCC tool to test with");
    return {};
  }
  const fs::path script = fs::path(FACECAP_SOURCE_DIR) / "tests" / "make_ict_fbx.py";
  const fs::path out = fs::path(FACECAP_BINARY_DIR) / "tests" / "ict_face_blender.fbx";
  if (fs::exists(out) && fs::last_write_time(out) > fs::last_write_time(script)) return out;
  const fs::path partial = out.string() + fmt::format(".{}.fbx", getpid());
  const std::string log = test::run_and_capture(
      fmt::format("blender -b --factory-startup --python '{}' -- '{}' '{}' 2>&1", script.string(), ict.string(),
                  partial.string()),
      &status);
  INFO(log);
  REQUIRE(status == 0);
  REQUIRE(fs::exists(partial));
  fs::rename(partial, out);
  return out;
}

// For each vertex of `a`, the vertex of `b` at the same place (within tol), or -1.
std::vector<Eigen::Index> match_vertices(const Eigen::Matrix3Xd& a, const Eigen::Matrix3Xd& b, double tol) {
  // Sort b by x to search a narrow band.
  std::multimap<double, Eigen::Index> by_x;
  for (Eigen::Index j = 0; j < b.cols(); ++j) by_x.emplace(b(0, j), j);
  std::vector<Eigen::Index> out(std::size_t(a.cols()), -1);
  for (Eigen::Index i = 0; i < a.cols(); ++i) {
    double best = tol;
    for (auto it = by_x.lower_bound(a(0, i) - tol); it != by_x.end() && it->first <= a(0, i) + tol; ++it) {
      const double d = (a.col(i) - b.col(it->second)).norm();
      if (d <= best) {
        best = d;
        out[std::size_t(i)] = it->second;
      }
    }
  }
  return out;
}

}  // namespace

TEST_CASE("a small FBX rig written by Blender welds its 24 seam-split corners back to the cube's 8 vertices", "[fbx]") {
  // tests/data/tiny_rig_blender.fbx, written by tests/make_tiny_fbx.py: a 10 cm cube whose
  // jawOpen moves the four bottom vertices down (Blender z < 0, FBX y < 0) each by its own
  // 2 + 0.25 i cm, and mouthSmile_L the four at x > 0 along Blender y (FBX -z).
  const fs::path fbx = fs::path(FACECAP_SOURCE_DIR) / "tests" / "data" / "tiny_rig_blender.fbx";
  FbxContents contents;
  const Rig rig = load_fbx_rig(fbx.string(), &contents);
  CHECK(contents.vertices_before_weld == 24);
  CHECK(contents.vertices_after_weld == 8);
  CHECK(rig.vertex_count() == 8);
  CHECK(rig.triangle_count() == 12);
  CHECK(rig.shape_names == std::vector<std::string>{"jawOpen", "mouthSmile_L"});
  REQUIRE(rig.file_vertex_of.size() == 24);
  std::vector<int> corners(8, 0);
  for (const int v : rig.file_vertex_of) ++corners[std::size_t(v)];
  CHECK(corners == std::vector<int>(8, 3));  // each cube corner touches three faces
  CHECK((rig.neutral.cwiseAbs().array() - 5.0).abs().maxCoeff() < 1e-6);
  std::set<double> jaw_drops;
  for (Eigen::Index v = 0; v < 8; ++v) {
    const Eigen::Vector3d jaw = rig.deltas.col(0).segment<3>(3 * v), smile = rig.deltas.col(1).segment<3>(3 * v);
    if (rig.neutral(1, v) < 0) {
      CHECK(std::abs(jaw.x()) + std::abs(jaw.z()) < 1e-6);
      jaw_drops.insert(std::round(-jaw.y() * 1000.0) / 1000.0);
    } else {
      CHECK(jaw.norm() < 1e-6);
    }
    if (rig.neutral(0, v) > 0) CHECK(smile.z() < -0.9);
    else CHECK(smile.norm() < 1e-6);
  }
  CHECK(jaw_drops.size() == 4);  // four distinct displacements: no vertex welded to another
  CHECK(*jaw_drops.begin() >= 2.0);
  CHECK(*jaw_drops.rbegin() <= 3.75);
  // load_rig picks the FBX loader by extension, and the cache keeps the corner map.
  const fs::path cache = test::scratch_dir("fbx-cache");
  const Rig first = load_rig(fbx.string(), {.use_cache = true, .cache_dir = cache});
  RigLoadReport report;
  const Rig again = load_rig(fbx.string(), {.use_cache = true, .cache_dir = cache}, &report);
  CHECK(report.from_cache);
  CHECK(again.file_vertex_of == rig.file_vertex_of);
  CHECK(again.content_hash() == rig.content_hash());
}

TEST_CASE("an FBX of the ICT face written by Blender loads as a rig of 6,706 welded vertices with ICT's shapes",
          "[fbx][data]") {
  const fs::path fbx = blender_ict_fbx();
  if (fbx.empty()) return;
  FbxContents contents;
  const Rig rig = load_fbx_rig(fbx.string(), &contents);
  const Rig obj = load_rig(test::shared_data("ict-face").string(), {.use_cache = false});
  INFO("assimp delivered " << contents.vertices_before_weld << " vertices, welded to " << contents.vertices_after_weld);
  CHECK(rig.vertex_count() == 6706);
  CHECK(contents.vertices_after_weld == 6706);
  CHECK(contents.vertices_before_weld > 6706);  // split at the UV seams and per face corner
  CHECK(rig.file_vertex_of.size() == contents.vertices_before_weld);
  CHECK(rig.shape_names == obj.shape_names);
  CHECK(rig.triangle_count() == obj.triangle_count());
  // The same geometry: every welded vertex is one OBJ vertex (a permutation), to float
  // precision (Blender keeps float32), and so is every shape.
  const auto to_obj = match_vertices(rig.neutral, obj.neutral, 1e-4);
  std::vector<bool> used(std::size_t(obj.vertex_count()), false);
  for (const Eigen::Index j : to_obj) {
    REQUIRE(j >= 0);
    CHECK_FALSE(used[std::size_t(j)]);
    used[std::size_t(j)] = true;
  }
  double worst = 0;
  for (Eigen::Index s = 0; s < rig.shape_count(); ++s)
    for (Eigen::Index v = 0; v < rig.vertex_count(); ++v)
      worst = std::max(worst, (rig.deltas.col(s).segment<3>(3 * v) - obj.deltas.col(s).segment<3>(3 * to_obj[std::size_t(v)])).norm());
  INFO("largest shape difference " << worst << " cm");
  CHECK(worst < 1e-4);
  // The triangles are ICT's, through the permutation.
  std::set<std::array<Eigen::Index, 3>> obj_triangles;
  for (Eigen::Index t = 0; t < obj.triangle_count(); ++t)
    obj_triangles.insert({obj.triangles(0, t), obj.triangles(1, t), obj.triangles(2, t)});
  std::size_t same = 0;
  for (Eigen::Index t = 0; t < rig.triangle_count(); ++t)
    same += obj_triangles.count({to_obj[std::size_t(rig.triangles(0, t))], to_obj[std::size_t(rig.triangles(1, t))],
                                 to_obj[std::size_t(rig.triangles(2, t))]});
  CHECK(same == std::size_t(rig.triangle_count()));

  // inspect-rig says what the file held and what welding did.
  const fs::path dir = test::scratch_dir("fbx-inspect");
  Run r = run_facecap(dir, {"inspect-rig", fbx.string(), "--json"});
  INFO(r.err);
  REQUIRE(r.exit_code == 0);
  const auto j = nlohmann::json::parse(r.out);
  CHECK(j["vertices"] == 6706);
  CHECK(j["shapes"] == 57);
  REQUIRE(j["fbx"]["meshes"].size() == 1);
  CHECK(j["fbx"]["meshes"][0]["channels"] == 57);
  CHECK(j["fbx"]["vertices_before_weld"] == contents.vertices_before_weld);
  CHECK(j["fbx"]["vertices_after_weld"] == 6706);
  r = run_facecap(dir, {"inspect-rig", fbx.string()});
  CHECK(r.out.find(fmt::format("welded     {} vertices split at seams -> 6706", contents.vertices_before_weld)) !=
        std::string::npos);
}

// The ICT OBJs with every coordinate rounded to float32, as Blender holds them: the
// reference that tells the FBX path's own error from float32's.
fs::path float32_ict(const fs::path& ict, const fs::path& dir) {
  fs::create_directories(dir);
  for (const auto& entry : fs::directory_iterator(ict)) {
    if (entry.path().extension() != ".obj") continue;
    std::istringstream in(test::slurp(entry.path()));
    std::string text;
    for (std::string line; std::getline(in, line);) {
      if (line.starts_with("v ")) {
        std::istringstream v(line.substr(2));
        double x = 0, y = 0, z = 0;
        v >> x >> y >> z;
        line = fmt::format("v {:.9g} {:.9g} {:.9g}", double(float(x)), double(float(y)), double(float(z)));
      }
      text += line + "\n";
    }
    test::write_text(dir / entry.path().filename(), text);
  }
  return dir;
}

TEST_CASE("solving JawMoCap on the Blender FBX of ICT matches solving on the OBJ rig as closely as float32 geometry "
          "allows", "[fbx][data]") {
  const fs::path fbx = blender_ict_fbx();
  if (fbx.empty()) return;
  FACECAP_REQUIRE_SHARED_DATA(jaw, "markers/animface/JawMoCap.trc");
  const fs::path dir = test::scratch_dir("fbx-solve");
  const fs::path ict = test::shared_data("ict-face");
  // Each rig calibrated on the take and solved, as an operator would.
  std::vector<std::vector<SolvedFrame>> solves;
  for (const fs::path& rig : {ict, fbx, float32_ict(ict, dir / "ict_float32")}) {
    const std::string name = rig.stem().string();
    const std::string profile = (dir / (name + ".toml")).string(), fcrec = (dir / (name + ".fcrec")).string();
    Run r = run_facecap(dir, {"calibrate", "--rig", rig.string(), "--take", jaw.string(), "-o", profile});
    INFO(r.out << r.err);
    REQUIRE(r.exit_code == 0);
    r = run_facecap(dir, {"solve", "--rig", rig.string(), "--calib", profile, "--take", jaw.string(), "-o", fcrec, "-q"});
    REQUIRE(r.exit_code == 0);
    const formats::RecordingReader reader(fcrec);
    solves.emplace_back(reader.solved_frame_count());
    for (std::size_t i = 0; i < reader.solved_frame_count(); ++i) reader.read_solved_frame(i, solves.back()[i]);
  }
  REQUIRE(solves[0].size() > 900);
  auto largest_difference = [&](const std::vector<SolvedFrame>& a, const std::vector<SolvedFrame>& b) {
    REQUIRE(a.size() == b.size());
    double worst = 0;
    for (std::size_t f = 0; f < a.size(); ++f)
      worst = std::max(worst, double((a[f].weights - b[f].weights).cwiseAbs().maxCoeff()));
    return worst;
  };
  double largest = 0;
  for (const auto& frame : solves[0]) largest = std::max(largest, double(frame.weights.maxCoeff()));
  const double fbx_vs_obj = largest_difference(solves[1], solves[0]);
  const double float32_vs_obj = largest_difference(solves[2], solves[0]);
  const double fbx_vs_float32 = largest_difference(solves[1], solves[2]);
  WARN("JawMoCap, " << solves[0].size() << " frames, largest weight difference from the OBJ rig: the Blender FBX "
                    << fbx_vs_obj << ", the OBJs rounded to float32 " << float32_vs_obj
                    << "; the FBX from the float32 OBJs " << fbx_vs_float32);
  CHECK(largest > 0.3);  // the jaw opens: not a comparison of zeros
  // Blender keeps positions as float32 (7 digits), so 1e-6 from the double OBJ rig is out of
  // reach of any float32 file: rounding the OBJs alone moves the weights (1.3e-5 before the
  // calibration's and solve's per-frame decisions of issues 29 and 30, 0.037 since: they
  // amplify it, docs/rigs.md). The FBX path adds no error of its own: it solves as the
  // same geometry read from OBJ files.
  CHECK(fbx_vs_float32 < 5e-5);
  CHECK(fbx_vs_obj <= float32_vs_obj * 1.01 + 5e-5);
}

TEST_CASE("bad FBX files are refused naming the file and what is wrong", "[fbx]") {
  const fs::path dir = test::scratch_dir("fbx-bad");
  test::write_text(dir / "text.fbx", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
  auto message = [](const fs::path& path) {
    try {
      load_fbx_rig(path.string());
    } catch (const Error& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  CHECK(message(dir / "text.fbx").find(dir.string() + "/text.fbx") != std::string::npos);
  CHECK(message(dir / "text.fbx").find("not an FBX file") != std::string::npos);
  test::write_text(dir / "empty.fbx", "");
  CHECK(message(dir / "empty.fbx").find("empty file") != std::string::npos);
  // A binary FBX header and nothing after it: assimp's own complaint, with the file.
  test::write_text(dir / "cut.fbx", std::string("Kaydara FBX Binary  \0\x1a\0\xe8\x1c\0\0", 27));
  const std::string cut = message(dir / "cut.fbx");
  CHECK(cut.find("cut.fbx") != std::string::npos);
  CHECK(cut.find("assimp cannot read it") != std::string::npos);
  // Through load_rig and the command line, as an operator meets it.
  Run r = run_facecap(dir, {"inspect-rig", (dir / "cut.fbx").string()});
  CHECK(r.exit_code == 1);
  CHECK(r.err.find("cut.fbx") != std::string::npos);

  const fs::path fbx = blender_ict_fbx();
  if (fbx.empty()) return;
  // The real file cut in half, and with its vertex data damaged.
  const std::string bytes = test::slurp(fbx);
  test::write_text(dir / "half.fbx", bytes.substr(0, bytes.size() / 2));
  const std::string half = message(dir / "half.fbx");
  CHECK(half.find("half.fbx") != std::string::npos);
  CHECK(half != "no error");
}

// Found by the fbx fuzz target: tests/make_tiny_fbx.py's cube with one array's length set
// to 0x12ffffff doubles (2.55 GB) over 41 stored bytes. assimp allocated what the header
// claimed (inspect-rig took 8 s and 3.75 GB before refusing the file); the records are now
// walked first and the file refused at that array, before assimp reads it.
TEST_CASE("a binary FBX whose array claims far more values than it stores is refused at that byte, before assimp",
          "[fbx][hostile]") {
  const fs::path fbx = fs::path(FACECAP_SOURCE_DIR) / "tests" / "data" / "hostile_array_length.fbx";
  try {
    load_fbx_rig(fbx.string());
    FAIL("the file was read");
  } catch (const Error& e) {
    CHECK_THAT(std::string(e.what()), Catch::Contains("hostile_array_length.fbx @ byte 9726") &&
                                          Catch::Contains("an FBX array claims 318767103 values in 41 stored bytes"));
  }
  // The same file with a header we did not damage reads (the walk refuses nothing valid).
  CHECK_NOTHROW(load_fbx_rig((fs::path(FACECAP_SOURCE_DIR) / "tests" / "data" / "tiny_rig_blender.fbx").string()));
}
