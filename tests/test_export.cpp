// facecap export, run as artists run it, its files read back by real consumers: the
// Khronos glTF validator and three.js's GLTFLoader (npm, tests/peers), and PC2 and MDD
// decoders written here from the published layouts (Blender's Mesh Cache modifier reads
// the same fields).
#include <bit>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>

#include <catch2/catch.hpp>
#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "core/units.hpp"
#include "formats/arkit.hpp"
#include "formats/livelinkface.hpp"
#include "formats/recording.hpp"
#include "formats/take.hpp"
#include "solver/gltf_rig.hpp"
#include "solver/obj_mesh.hpp"
#include "tests/align_test_support.hpp"
#include "tests/test_support.hpp"
#include "tools/shape_map.hpp"

using namespace facecap;
namespace fs = std::filesystem;

namespace {

using test::Run;
using test::run_facecap;

const fs::path kSource = FACECAP_SOURCE_DIR;
const fs::path kPeers = kSource / "tests" / "peers";

// A built-in face take solved by facecap calibrate + solve, as take.fcrec (weights only)
// and take_vertices.fcrec (with the solved meshes).
struct SolvedTake {
  fs::path dir, fcrec, fcrec_vertices;
};

SolvedTake solve_builtin_take(const std::string& name) {
  SolvedTake out;
  out.dir = test::scratch_dir(name);
  test::SyntheticTakeOptions o;
  o.seed = 32;
  o.rest_frames = 30;
  o.motion_frames = 60;
  o.head_sway_deg = 4.0;
  const auto synthetic = test::make_synthetic_take(o);
  formats::MarkerTake take;
  take.format = formats::TakeFormat::kTrc;
  take.labels = synthetic.labels;
  take.rate_hz = 60.0;
  take.units = "mm";
  take.first_frame = 1;
  take.frames = synthetic.frames;
  const fs::path trc = out.dir / "take.trc";
  formats::write_take(trc, take);
  const std::string profile = (out.dir / "actor.toml").string();
  Run r = run_facecap(out.dir, {"calibrate", "--rig", "builtin", "--take", trc.string(), "--auto-neutral", "-o", profile});
  INFO(r.out << r.err);
  REQUIRE(r.exit_code == 0);
  out.fcrec = out.dir / "take.fcrec";
  out.fcrec_vertices = out.dir / "take_vertices.fcrec";
  r = run_facecap(out.dir, {"solve", "--rig", "builtin", "--calib", profile, "--take", trc.string(), "-o",
                            out.fcrec.string(), "-q"});
  REQUIRE(r.exit_code == 0);
  r = run_facecap(out.dir, {"solve", "--rig", "builtin", "--calib", profile, "--take", trc.string(), "-o",
                            out.fcrec_vertices.string(), "--vertices", "-q"});
  REQUIRE(r.exit_code == 0);
  return out;
}

std::vector<SolvedFrame> solved_frames(const fs::path& fcrec) {
  const formats::RecordingReader reader(fcrec);
  std::vector<SolvedFrame> frames(reader.solved_frame_count());
  for (std::size_t i = 0; i < frames.size(); ++i) reader.read_solved_frame(i, frames[i]);
  return frames;
}

bool peers_installed() {
  if (fs::exists(kPeers / "node_modules" / "gltf-validator") && fs::exists(kPeers / "node_modules" / "three")) return true;
  WARN("gltf-validator and three are not installed in tests/peers (scripts/quickstart.sh test runs npm ci): the glTF "
       "is not checked by them");
  return false;
}

// What the validator and three.js's GLTFLoader make of a glTF file.
nlohmann::json read_with_peers(const fs::path& gltf) {
  int status = 0;
  const std::string out =
      test::run_and_capture(fmt::format("node '{}' '{}' 2>&1", (kPeers / "gltf_check.mjs").string(), gltf.string()), &status);
  INFO(out.substr(0, 2000));
  REQUIRE(status == 0);
  return nlohmann::json::parse(out);
}

const nlohmann::json& track(const nlohmann::json& animation, const std::string& property) {
  for (const auto& t : animation["tracks"])
    if (t["name"].get<std::string>().ends_with("." + property)) return t;
  FAIL("no track of " << property);
  static const nlohmann::json none;
  return none;
}

// The acceptance check of a glTF export against its recording: 0 errors and 0 warnings
// from the Khronos validator; in three.js the target names, and at every frame the key
// time (as float32), the influences (to 1e-6) and the head track (to 1e-6, metres).
void check_gltf_against_recording(const fs::path& gltf, const fs::path& fcrec, std::size_t expected_vertices) {
  const nlohmann::json peers = read_with_peers(gltf);
  INFO(gltf.filename().string() << ": " << peers["validator"]["messages"].dump());
  CHECK(peers["validator"]["errors"] == 0);
  CHECK(peers["validator"]["warnings"] == 0);

  const formats::RecordingReader reader(fcrec);
  const auto& h = reader.header();
  const std::vector<SolvedFrame> frames = solved_frames(fcrec);
  const std::size_t shapes = h.shape_names.size();
  const double metres = *millimetres_per_unit(h.rig_units) / 1000.0;
  const auto& three = peers["three"];
  REQUIRE(three["meshes"].size() == 1);
  CHECK(three["meshes"][0]["targetNames"].get<std::vector<std::string>>() == h.shape_names);
  CHECK(three["meshes"][0]["vertices"] == expected_vertices);
  REQUIRE(three["animations"].size() == 1);
  const auto& animation = three["animations"][0];
  const auto& influences = track(animation, "morphTargetInfluences");
  const auto& rotation = track(animation, "quaternion");
  const auto& position = track(animation, "position");
  REQUIRE(influences["times"].size() == frames.size());
  REQUIRE(influences["values"].size() == frames.size() * shapes);
  REQUIRE(rotation["values"].size() == frames.size() * 4);
  REQUIRE(position["values"].size() == frames.size() * 3);
  double worst_time = 0, worst_weight = 0, worst_rotation = 0, worst_position = 0;
  float largest_weight = 0;
  for (std::size_t f = 0; f < frames.size(); ++f) {
    // glTF key times are float32 seconds: compared with the recorded time so rounded.
    const float t = float(double(frames[f].source_time_ns - frames[0].source_time_ns) * 1e-9);
    worst_time = std::max(worst_time, std::abs(influences["times"][f].get<double>() - double(t)));
    for (std::size_t s = 0; s < shapes; ++s) {
      worst_weight = std::max(worst_weight, std::abs(influences["values"][f * shapes + s].get<double>() -
                                                     double(frames[f].weights[Eigen::Index(s)])));
      largest_weight = std::max(largest_weight, frames[f].weights[Eigen::Index(s)]);
    }
    const Eigen::Quaterniond& q = frames[f].head_rotation;
    const double expected_q[4] = {q.x(), q.y(), q.z(), q.w()};
    for (int k = 0; k < 4; ++k)
      worst_rotation = std::max(worst_rotation, std::abs(rotation["values"][f * 4 + std::size_t(k)].get<double>() - expected_q[k]));
    for (int k = 0; k < 3; ++k)
      worst_position = std::max(worst_position, std::abs(position["values"][f * 3 + std::size_t(k)].get<double>() -
                                                         frames[f].head_translation[k] * metres));
  }
  WARN(gltf.filename().string() << ": validator " << peers["validator"]["errors"] << " errors, "
                                 << peers["validator"]["warnings"] << " warnings; three.js vs the recording over "
                                 << frames.size() << " frames, largest differences: time " << worst_time << " s, weight "
                                 << worst_weight << ", rotation " << worst_rotation << ", position " << worst_position
                                 << " m");
  CHECK(worst_time < 1e-9);
  CHECK(worst_weight < 1e-6);
  CHECK(worst_rotation < 1e-6);
  CHECK(worst_position < 1e-6);
  CHECK(largest_weight > 0.3f);  // the take moves: a comparison of zeros proves nothing
}

// A point cache decoded from the published layouts, independently of the writer.
struct PointCache {
  int32_t points = 0;
  std::vector<float> times;     // MDD only
  float start = 0, rate = 0;    // PC2 only
  std::vector<std::vector<float>> frames;  // each points x 3
};

// A 32-bit value at offset, which the caller has checked lies in bytes.
template <typename T>
T load(const std::string& bytes, std::size_t offset, bool big_endian) {
  uint32_t raw = 0;
  std::memcpy(&raw, bytes.data() + offset, 4);
  if (big_endian) raw = __builtin_bswap32(raw);
  return std::bit_cast<T>(raw);
}

PointCache decode_pc2(const fs::path& path) {
  const std::string bytes = test::slurp(path);
  REQUIRE(bytes.size() >= 32);
  CHECK(std::memcmp(bytes.data(), "POINTCACHE2\0", 12) == 0);
  CHECK(load<int32_t>(bytes, 12, false) == 1);
  PointCache c;
  c.points = load<int32_t>(bytes, 16, false);
  c.start = load<float>(bytes, 20, false);
  c.rate = load<float>(bytes, 24, false);
  const int32_t samples = load<int32_t>(bytes, 28, false);
  REQUIRE(bytes.size() == 32 + std::size_t(samples) * std::size_t(c.points) * 12);
  for (int32_t f = 0; f < samples; ++f) {
    c.frames.emplace_back();
    for (int32_t i = 0; i < 3 * c.points; ++i)
      c.frames.back().push_back(load<float>(bytes, 32 + (std::size_t(f) * std::size_t(c.points) * 3 + std::size_t(i)) * 4, false));
  }
  return c;
}

PointCache decode_mdd(const fs::path& path) {
  const std::string bytes = test::slurp(path);
  REQUIRE(bytes.size() >= 8);
  const int32_t frames = load<int32_t>(bytes, 0, true);
  PointCache c;
  c.points = load<int32_t>(bytes, 4, true);
  const std::size_t data = 8 + std::size_t(frames) * 4;
  REQUIRE(bytes.size() == data + std::size_t(frames) * std::size_t(c.points) * 12);
  for (int32_t f = 0; f < frames; ++f) c.times.push_back(load<float>(bytes, 8 + std::size_t(f) * 4, true));
  for (int32_t f = 0; f < frames; ++f) {
    c.frames.emplace_back();
    for (int32_t i = 0; i < 3 * c.points; ++i)
      c.frames.back().push_back(load<float>(bytes, data + (std::size_t(f) * std::size_t(c.points) * 3 + std::size_t(i)) * 4, true));
  }
  return c;
}

// How many of a cache's floats differ from the recording's vertices times scale (compared
// with ==: a difference a - b * c could be fused into one rounding by the compiler).
std::size_t cache_mismatches(const PointCache& cache, const std::vector<SolvedFrame>& frames, float scale) {
  REQUIRE(cache.frames.size() == frames.size());
  std::size_t mismatches = 0;
  for (std::size_t f = 0; f < frames.size(); ++f) {
    REQUIRE(cache.points == frames[f].vertices.cols());
    for (Eigen::Index i = 0; i < frames[f].vertices.size(); ++i)
      mismatches += cache.frames[f][std::size_t(i)] != frames[f].vertices.data()[i] * scale;
  }
  return mismatches;
}

// The largest difference between a cache's frames and the recording's vertices.
double cache_error(const PointCache& cache, const std::vector<SolvedFrame>& frames) {
  REQUIRE(cache.frames.size() == frames.size());
  double worst = 0;
  for (std::size_t f = 0; f < frames.size(); ++f) {
    REQUIRE(cache.points == frames[f].vertices.cols());
    for (Eigen::Index i = 0; i < frames[f].vertices.size(); ++i)
      worst = std::max(worst, std::abs(double(cache.frames[f][std::size_t(i)]) - double(frames[f].vertices.data()[i])));
  }
  return worst;
}

// A recording of hand-made solved frames on a rig whose shape names are not ARKit's.
fs::path write_renamed_recording(const fs::path& dir, const std::vector<std::string>& names, bool all_zero,
                                 bool nan_in_frame_7 = false) {
  formats::RecordingHeader header;
  header.rig_name = "cc4_head";
  header.rig_units = "cm";
  header.rate_hz = 60.0;
  header.shape_names = names;
  const fs::path path = dir / (nan_in_frame_7 ? "nan.fcrec" : all_zero ? "zeros.fcrec" : "renamed.fcrec");
  formats::RecordingWriter writer(path, header);
  SolvedFrame frame;
  frame.resize(Eigen::Index(names.size()), 0);
  for (int f = 0; f < 30; ++f) {
    frame.frame_no = f;
    frame.source_time_ns = int64_t(f) * 1'000'000'000 / 60;
    for (Eigen::Index s = 0; s < frame.weights.size(); ++s)
      frame.weights[s] = all_zero ? 0.0f : float(0.5 + 0.45 * std::sin(0.2 * f + double(s)));
    if (nan_in_frame_7 && f == 7) frame.weights[0] = std::numeric_limits<float>::quiet_NaN();
    writer.append_solved_frame(frame);
  }
  writer.close();
  return path;
}

}  // namespace

TEST_CASE("a built-in face take exports to .glb and .gltf that the Khronos validator passes and three.js reads back "
          "frame by frame", "[export]") {
  const SolvedTake take = solve_builtin_take("export-gltf");
  const std::size_t rig_vertices = std::size_t(BuiltinFace::instance().rig().vertex_count());
  for (const char* name : {"take.glb", "take.gltf"}) {
    const fs::path out = take.dir / name;
    Run r = run_facecap(take.dir, {"export", take.fcrec.string(), out.string(), "--rig", "builtin"});
    INFO(r.out << r.err);
    REQUIRE(r.exit_code == 0);
    if (peers_installed()) check_gltf_against_recording(out, take.fcrec, rig_vertices);
  }
  // Weights only: no geometry (one point), names and tracks kept; no --rig needed.
  const fs::path weights = take.dir / "weights.glb";
  Run r = run_facecap(take.dir, {"export", take.fcrec.string(), weights.string(), "--weights-only"});
  INFO(r.out << r.err);
  REQUIRE(r.exit_code == 0);
  CHECK(fs::file_size(weights) < fs::file_size(take.dir / "take.glb") / 10);
  if (peers_installed()) check_gltf_against_recording(weights, take.fcrec, 1);
  // Geometry needs the rig, and the right one.
  r = run_facecap(take.dir, {"export", take.fcrec.string(), (take.dir / "x.glb").string()});
  CHECK(r.exit_code == 1);
  CHECK(r.err.find("pass --rig") != std::string::npos);
  const fs::path other_rig = take.dir / "other.glb";
  Rig other = BuiltinFace::instance().rig();
  other.neutral(0, 0) += 1.0;
  save_gltf_rig(other, other_rig.string());
  r = run_facecap(take.dir, {"export", take.fcrec.string(), (take.dir / "x.glb").string(), "--rig", other_rig.string()});
  CHECK(r.exit_code == 1);
  CHECK(r.err.find("is not the rig") != std::string::npos);
  CHECK_FALSE(fs::exists(take.dir / "x.glb"));
}

TEST_CASE("a real AnimFace take solved on ICT exports to a .glb that the Khronos validator passes and three.js reads "
          "back frame by frame", "[export][data]") {
  FACECAP_REQUIRE_SHARED_DATA(ict, "ict-face");
  FACECAP_REQUIRE_SHARED_DATA(jaw, "markers/animface/JawMoCap.trc");
  const fs::path dir = test::scratch_dir("export-ict");
  const std::string profile = (dir / "actor.toml").string();
  Run r = run_facecap(dir, {"calibrate", "--rig", ict.string(), "--take", jaw.string(), "-o", profile});
  INFO(r.out << r.err);
  REQUIRE(r.exit_code == 0);
  const fs::path fcrec = dir / "jaw.fcrec";
  r = run_facecap(dir, {"solve", "--rig", ict.string(), "--calib", profile, "--take", jaw.string(), "-o", fcrec.string(), "-q"});
  REQUIRE(r.exit_code == 0);
  const fs::path glb = dir / "jaw.glb";
  r = run_facecap(dir, {"export", fcrec.string(), glb.string(), "--rig", ict.string()});
  REQUIRE(r.exit_code == 0);
  WARN(r.out);
  if (peers_installed()) check_gltf_against_recording(glb, fcrec, 6706);
}

TEST_CASE("PC2 and MDD point caches read back by decoders of the published layouts give the recording's vertices",
          "[export]") {
  const SolvedTake take = solve_builtin_take("export-caches");
  const std::vector<SolvedFrame> frames = solved_frames(take.fcrec_vertices);
  REQUIRE(frames.front().vertices.cols() == BuiltinFace::instance().rig().vertex_count());
  for (const float scale : {1.0f, 10.0f}) {
    const std::string suffix = scale == 1.0f ? "" : "_x10";
    const fs::path pc2 = take.dir / ("take" + suffix + ".pc2"), mdd = take.dir / ("take" + suffix + ".mdd");
    for (const fs::path& out : {pc2, mdd}) {
      Run r = run_facecap(take.dir, {"export", take.fcrec_vertices.string(), out.string(), "--scale", fmt::format("{:g}", scale)});
      INFO(r.out << r.err);
      REQUIRE(r.exit_code == 0);
    }
    const PointCache a = decode_pc2(pc2);
    CHECK(a.start == 0.0f);
    CHECK(a.rate == 1.0f);
    CHECK(cache_mismatches(a, frames, scale) == 0);  // the same float32s
    const PointCache b = decode_mdd(mdd);
    CHECK(cache_mismatches(b, frames, scale) == 0);
    REQUIRE(b.times.size() == frames.size());
    for (std::size_t f = 0; f < frames.size(); ++f)
      CHECK(b.times[f] == Approx(double(frames[f].source_time_ns - frames[0].source_time_ns) * 1e-9).margin(1e-6));
  }
  // A recording without vertices is solved again, with a progress bar, to the same meshes.
  const fs::path resolved = take.dir / "resolved.pc2";
  Run r = run_facecap(take.dir, {"export", take.fcrec.string(), resolved.string(), "--rig", "builtin"});
  INFO(r.out << r.err);
  REQUIRE(r.exit_code == 0);
  CHECK(r.err.find("solving") != std::string::npos);
  const double resolve_error = cache_error(decode_pc2(resolved), frames);
  INFO("re-solved vs recorded vertices: " << resolve_error << " rig units");
  CHECK(resolve_error < 1e-5);
  // ... which needs the rig.
  r = run_facecap(take.dir, {"export", take.fcrec.string(), (take.dir / "x.mdd").string()});
  CHECK(r.exit_code == 1);
  CHECK(r.err.find("pass --rig") != std::string::npos);
  CHECK_FALSE(fs::exists(take.dir / "x.mdd"));

  // One frame as OBJ: the recording's vertices (9 significant digits hold a float) on the
  // rig's triangles.
  const fs::path obj = take.dir / "frame.obj";
  r = run_facecap(take.dir, {"export", take.fcrec_vertices.string(), obj.string(), "--frame", "45", "--rig", "builtin"});
  INFO(r.out << r.err);
  REQUIRE(r.exit_code == 0);
  const ObjMesh mesh = read_obj(obj.string());
  CHECK((mesh.vertices.cast<float>().array() == frames[45].vertices.array()).all());
  CHECK(mesh.triangles == BuiltinFace::instance().rig().triangles);
  r = run_facecap(take.dir, {"export", take.fcrec_vertices.string(), (take.dir / "late.obj").string(), "--frame", "9999",
                             "--rig", "builtin"});
  CHECK(r.exit_code == 1);
  CHECK(r.err.find("--frame 9999") != std::string::npos);
  r = run_facecap(take.dir, {"export", take.fcrec_vertices.string(), (take.dir / "noframe.obj").string(), "--rig", "builtin"});
  CHECK(r.exit_code == 1);
  CHECK(r.err.find("--frame N") != std::string::npos);
}

TEST_CASE("a rig with non-ARKit names exports to Live Link Face CSV through a name map, and without one exits 1 "
          "saying why", "[export]") {
  const fs::path dir = test::scratch_dir("export-map");
  const std::vector<std::string> names = {"Jaw_Open", "Eye_Blink_L", "Eye_Blink_R", "Cheek_Puff_L", "Cheek_Puff_R",
                                          "Custom_Sneer"};
  const fs::path fcrec = write_renamed_recording(dir, names, false);
  const fs::path csv = dir / "take.csv";
  Run r = run_facecap(dir, {"export", fcrec.string(), csv.string()});
  CHECK(r.exit_code == 1);
  CHECK(r.err.find("none of the rig's 6 shapes (Jaw_Open, Eye_Blink_L") != std::string::npos);
  CHECK(r.err.find("--map") != std::string::npos);
  CHECK_FALSE(fs::exists(csv));
  // convert writes Live Link Face by the same path: the same refusal.
  r = run_facecap(dir, {"convert", fcrec.string(), csv.string()});
  CHECK(r.exit_code == 1);
  CHECK(r.err.find("none of the rig's 6 shapes") != std::string::npos);

  test::write_text(dir / "map.toml", "# CC4-style names\nJaw_Open = \"JawOpen\"\nEye_Blink_L = \"EyeBlinkLeft\"\n"
                                     "Eye_Blink_R = \"eyeBlinkRight\"\nCheek_Puff_L = \"CheekPuff\"\nCheek_Puff_R = \"CheekPuff\"\n");
  r = run_facecap(dir, {"export", fcrec.string(), csv.string(), "--map", (dir / "map.toml").string()});
  INFO(r.out << r.err);
  REQUIRE(r.exit_code == 0);
  CHECK(r.out.find("4 of 52 ARKit shapes") != std::string::npos);
  const formats::FaceTake face = formats::read_livelinkface(csv);
  const std::vector<SolvedFrame> frames = solved_frames(fcrec);
  REQUIRE(face.frames.size() == frames.size());
  const auto a = [](const char* arkit) { return *formats::arkit_shape_index(arkit); };
  for (std::size_t f = 0; f < frames.size(); ++f) {
    const Eigen::VectorXf& w = frames[f].weights;
    CHECK(face.frames[f].weights[a("JawOpen")] == Approx(w[0]).margin(1e-6));
    CHECK(face.frames[f].weights[a("EyeBlinkLeft")] == Approx(w[1]).margin(1e-6));
    CHECK(face.frames[f].weights[a("EyeBlinkRight")] == Approx(w[2]).margin(1e-6));
    CHECK(face.frames[f].weights[a("CheekPuff")] == Approx(0.5 * (w[3] + w[4])).margin(1e-6));
    CHECK(face.frames[f].weights[a("NoseSneerLeft")] == 0.0f);
  }

  // Bad maps name the file, line and what is wrong.
  test::write_text(dir / "typo.toml", "Jaw_Open = \"JawOpn\"\n");
  r = run_facecap(dir, {"export", fcrec.string(), (dir / "typo.csv").string(), "--map", (dir / "typo.toml").string()});
  CHECK(r.exit_code == 1);
  CHECK(r.err.find("typo.toml:1:") != std::string::npos);
  CHECK(r.err.find("did you mean 'JawOpen'") != std::string::npos);
  test::write_text(dir / "absent.toml", "Jaw_Open = \"JawOpen\"\nJaw_Opn = \"JawOpen\"\n");
  r = run_facecap(dir, {"export", fcrec.string(), (dir / "absent.csv").string(), "--map", (dir / "absent.toml").string()});
  CHECK(r.exit_code == 1);
  CHECK(r.err.find("absent.toml:2:") != std::string::npos);
  CHECK(r.err.find("the rig has no shape 'Jaw_Opn'") != std::string::npos);

  // The rig's own names, any rig: one column per shape, the recorded float32s.
  const fs::path own = dir / "own.csv";
  r = run_facecap(dir, {"export", fcrec.string(), own.string(), "--rig-names"});
  INFO(r.out << r.err);
  REQUIRE(r.exit_code == 0);
  std::ifstream in(own);
  std::string line;
  std::getline(in, line);
  CHECK(line == "Timecode,Seconds,Jaw_Open,Eye_Blink_L,Eye_Blink_R,Cheek_Puff_L,Cheek_Puff_R,Custom_Sneer");
  std::size_t rows = 0;
  while (std::getline(in, line)) {
    std::vector<std::string> fields;
    std::stringstream ss(line);
    for (std::string field; std::getline(ss, field, ',');) fields.push_back(field);
    REQUIRE(fields.size() == 2 + names.size());
    CHECK(std::stod(fields[1]) == Approx(double(rows) / 60.0).margin(1e-6));
    for (std::size_t s = 0; s < names.size(); ++s) CHECK(std::stof(fields[2 + s]) == frames[rows].weights[Eigen::Index(s)]);
    ++rows;
  }
  CHECK(rows == frames.size());

  // A take in which nothing moves would export nothing animated: exit 1, naming why.
  const fs::path zeros = write_renamed_recording(dir, names, true);
  r = run_facecap(dir, {"export", zeros.string(), (dir / "zeros.csv").string(), "--rig-names"});
  CHECK(r.exit_code == 1);
  CHECK(r.err.find("stays at 0 in all 30 frames") != std::string::npos);
}

TEST_CASE("the shipped shape-name maps parse, and the ICT FaceKit map binds as ICT's names match by themselves",
          "[export]") {
  std::size_t maps = 0;
  for (const auto& entry : fs::directory_iterator(kSource / "config" / "shape-maps")) {
    INFO(entry.path().string());
    const tools::ShapeMap map = tools::read_shape_map(entry.path());
    CHECK(map.entries.size() >= 50);
    ++maps;
  }
  CHECK(maps >= 3);
  const tools::ShapeMap ict = tools::read_shape_map(kSource / "config" / "shape-maps" / "ict-facekit.toml");
  std::vector<std::string> ict_names;
  for (const auto& e : ict.entries) ict_names.push_back(e.rig_shape);
  CHECK(tools::bind_shape_map(ict, ict_names) == formats::match_arkit_to_rig(ict_names));
}

TEST_CASE("export refuses what it cannot write, naming the file and why", "[export]") {
  const fs::path dir = test::scratch_dir("export-errors");
  test::write_text(dir / "take.trc", "not a recording\n");
  Run r = run_facecap(dir, {"export", (dir / "take.trc").string(), (dir / "out.glb").string()});
  CHECK(r.exit_code == 1);
  CHECK(r.err.find("take.trc: a glTF is written from a .fcrec recording's solved frames") != std::string::npos);
  const fs::path fcrec = write_renamed_recording(dir, {"a", "b"}, false);
  r = run_facecap(dir, {"export", fcrec.string(), (dir / "out.fbx").string()});
  CHECK(r.exit_code == 1);
  CHECK(r.err.find("output must end in .glb, .gltf, .pc2, .mdd, .obj or .csv") != std::string::npos);
  r = run_facecap(dir, {"export", fcrec.string(), (dir / "out.pc2").string()});
  CHECK(r.exit_code == 1);  // no vertices, no markers to solve
  CHECK(r.err.find("no solved vertices and no marker frames") != std::string::npos);
  const fs::path nan = write_renamed_recording(dir, {"a", "b"}, false, true);
  r = run_facecap(dir, {"export", nan.string(), (dir / "nan.glb").string(), "--weights-only"});
  CHECK(r.exit_code == 1);
  CHECK(r.err.find("nan.fcrec: solved frame 7 has a weight or head pose that is not a finite number") != std::string::npos);
  CHECK_FALSE(fs::exists(dir / "nan.glb"));
  r = run_facecap(dir, {"export", fcrec.string(), (dir / "out.glb").string(), "--scale", "2", "--weights-only"});
  CHECK(r.exit_code == 1);
  CHECK(r.err.find("--scale applies to .pc2, .mdd and .obj only") != std::string::npos);
}
