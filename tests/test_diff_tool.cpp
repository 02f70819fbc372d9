// facecap diff, run as a process on recordings written here with RecordingWriter: the exit
// status, the frame, shape, vertex and flag it reports, and the figures of its JSON.
#include <cmath>
#include <functional>
#include <limits>
#include <numbers>

#include <catch2/catch.hpp>
#include <nlohmann/json.hpp>

#include "core/io.hpp"
#include "formats/recording.hpp"
#include "tests/test_support.hpp"

using namespace facecap;
using namespace facecap::formats;

namespace {

using test::Run;
using test::run_facecap;

constexpr Eigen::Index kShapes = 6;
constexpr Eigen::Index kVertices = 40;
constexpr int64_t kFrames = 12;  // numbered 1..12, so a frame's number is not its index

RecordingHeader diff_header() {
  RecordingHeader h;
  h.rig_name = "diff-rig";
  h.rig_hash = 0x0123456789abcdefull;
  h.source_description = "test_diff_tool";
  h.calibration = "[calibration]\nscale = 1.25\n";
  h.units = "mm";
  h.rate_hz = 60.0;
  h.shape_names = {"jawOpen", "eyeBlink_L", "eyeBlink_R", "browInnerUp_L", "mouthSmile_L", "mouthSmile_R"};
  h.rig_units = "cm";
  h.solver_settings = "method = \"nonlinear\"\nalpha = 0.1\nmu = 0.001\n";
  return h;
}

// Distinct values per frame, shape and vertex, so a wrong frame or element shows.
SolvedFrame diff_frame(int64_t frame_no) {
  SolvedFrame f;
  f.resize(kShapes, kVertices);
  f.frame_no = frame_no;
  f.source_time_ns = frame_no * 16'666'667;
  f.head_rotation =
      Eigen::Quaterniond(Eigen::AngleAxisd(0.01 * double(frame_no), Eigen::Vector3d(1, 2, 3).normalized()));
  f.head_translation = Eigen::Vector3d(0.5, -1.0, 0.25 * double(frame_no));
  for (Eigen::Index s = 0; s < kShapes; ++s) f.weights[s] = float(0.05 * double(s) + 0.03 * double(frame_no));
  for (Eigen::Index v = 0; v < kVertices; ++v)
    f.vertices.col(v) = Eigen::Vector3f(float(v) * 0.25f, 5.0f + 0.01f * float(frame_no), -2.0f);
  return f;
}

// Changes a frame before it is written; false drops it.
using FrameEdit = std::function<bool(SolvedFrame&)>;

std::filesystem::path write_solves(const std::filesystem::path& dir, const std::string& name,
                                   const RecordingHeader& header, const FrameEdit& edit = {}) {
  const auto path = dir / name;
  RecordingWriter writer(path, header);
  for (int64_t frame_no = 1; frame_no <= kFrames; ++frame_no) {
    SolvedFrame f = diff_frame(frame_no);
    if (!edit || edit(f)) writer.append_solved_frame(f);
  }
  writer.close();
  return path;
}

struct Diff {
  Run run;
  nlohmann::json j;  // null unless stdout held JSON
};

Diff run_diff(const std::filesystem::path& dir, const std::filesystem::path& a, const std::filesystem::path& b,
              std::vector<std::string> options = {}) {
  std::vector<std::string> args = {"diff", a.string(), b.string(), "--json"};
  args.insert(args.end(), options.begin(), options.end());
  Diff d{run_facecap(dir, args), nullptr};
  if (!d.run.out.empty()) d.j = nlohmann::json::parse(d.run.out);
  return d;
}

}  // namespace

TEST_CASE("facecap diff: identical recordings are within even the golden tolerances", "[tools][diff]") {
  const auto dir = test::scratch_dir("diff-identical");
  const auto a = write_solves(dir, "a.fcrec", diff_header());
  const auto b = write_solves(dir, "b.fcrec", diff_header());
  const Diff d = run_diff(dir, a, b, {"--tolerance-weight", "1e-9", "--tolerance-mm", "1e-8"});
  INFO(d.run.err);
  REQUIRE(d.run.exit_code == 0);
  CHECK(d.j["exit_status"] == 0);
  CHECK(d.j["beyond"].empty());
  CHECK(d.j["frames"]["compared"] == kFrames);
  CHECK(d.j["frames"]["only_in_a"]["count"] == 0);
  CHECK(d.j["a"]["rig_hash"] == "0x0123456789abcdef");
  CHECK(d.j["a"]["rig_units"] == "cm");
  for (const char* channel : {"weights", "head_rotation_degrees", "head_translation_mm", "vertices_mm"}) {
    INFO(channel);
    CHECK(d.j[channel]["max"] == 0.0);
    CHECK(d.j[channel]["largest"].is_null());
    CHECK(d.j[channel]["frames"] == kFrames);
    CHECK(d.j[channel]["worst"].empty());
  }
  CHECK(d.j["weights"]["tolerance"] == 1e-9);
  CHECK(d.j["vertices_mm"]["tolerance"] == 1e-8);
  CHECK(d.j["flags"]["frames_differ"] == 0);
  CHECK(d.j["solver_settings"]["differ"] == false);
  CHECK(d.j["calibration"]["differ"] == false);

  const Run table = run_facecap(dir, {"diff", a.string(), b.string()});
  CHECK(table.exit_code == 0);
  CHECK(table.out.find("frames: 12 compared, only in A: 0, only in B: 0") != std::string::npos);
  CHECK(table.out.find("within tolerance") != std::string::npos);
  CHECK(table.err.empty());  // no terminal: no progress bar
}

TEST_CASE("facecap diff: one weight 2e-6 off in frame 7, shape 3", "[tools][diff]") {
  const auto dir = test::scratch_dir("diff-weight");
  float before = 0, after = 0;
  const auto a = write_solves(dir, "a.fcrec", diff_header());
  const auto b = write_solves(dir, "b.fcrec", diff_header(), [&](SolvedFrame& f) {
    if (f.frame_no == 7) {
      before = f.weights[3];
      f.weights[3] += 2e-6f;
      after = f.weights[3];
    }
    return true;
  });
  const double moved = double(after) - double(before);  // 2e-6 to float precision
  REQUIRE(moved == Approx(2e-6).margin(1e-7));

  const Diff d = run_diff(dir, a, b);
  INFO(d.run.err);
  REQUIRE(d.run.exit_code == 1);
  CHECK(d.j["beyond"] == std::vector<std::string>{"weights"});
  const auto& w = d.j["weights"];
  CHECK(w["max"].get<double>() == Approx(moved).epsilon(1e-12));
  CHECK(w["largest"]["frame"] == 7);
  CHECK(w["largest"]["shape"] == 3);
  CHECK(w["largest"]["shape_name"] == "browInnerUp_L");
  CHECK(w["largest"]["a"].get<double>() == double(before));
  CHECK(w["largest"]["b"].get<double>() == double(after));
  CHECK(w["frames_beyond"] == 1);
  CHECK(w["values_beyond"] == 1);
  CHECK(w["rms"].get<double>() == Approx(moved / std::sqrt(double(kShapes * kFrames))).epsilon(1e-9));
  REQUIRE(w["worst"].size() == 1);
  CHECK(w["worst"][0]["frame"] == 7);
  CHECK(d.j["vertices_mm"]["max"] == 0.0);

  const Run table = run_facecap(dir, {"diff", a.string(), b.string()});
  CHECK(table.exit_code == 1);
  CHECK(table.out.find("frame 7, shape 3 browInnerUp_L") != std::string::npos);
  CHECK(table.out.find("beyond tolerance: weights") != std::string::npos);

  CHECK(run_diff(dir, a, b, {"--tolerance-weight", "3e-6"}).run.exit_code == 0);
}

TEST_CASE("facecap diff: a vertex moved 0.01 mm, in centimetre rig units", "[tools][diff]") {
  const auto dir = test::scratch_dir("diff-vertex");
  double moved_mm = 0;
  const auto a = write_solves(dir, "a.fcrec", diff_header());
  const auto b = write_solves(dir, "b.fcrec", diff_header(), [&](SolvedFrame& f) {
    if (f.frame_no == 3) {
      const float x = f.vertices(0, 17);
      f.vertices(0, 17) += 0.001f;  // cm
      moved_mm = (double(f.vertices(0, 17)) - double(x)) * 10.0;
    }
    return true;
  });
  REQUIRE(moved_mm == Approx(0.01).margin(1e-5));

  const Diff d = run_diff(dir, a, b);
  INFO(d.run.err);
  REQUIRE(d.run.exit_code == 1);
  CHECK(d.j["beyond"] == std::vector<std::string>{"vertices"});
  const auto& v = d.j["vertices_mm"];
  CHECK(v["max"].get<double>() == Approx(moved_mm).epsilon(1e-9));
  CHECK(v["largest"]["frame"] == 3);
  CHECK(v["largest"]["vertex"] == 17);
  CHECK(v["values_beyond"] == 1);
  CHECK(v["frames_beyond"] == 1);
  CHECK(v["mean"].get<double>() == Approx(moved_mm / double(kVertices * kFrames)).epsilon(1e-9));
  CHECK(d.j["weights"]["max"] == 0.0);

  const Run table = run_facecap(dir, {"diff", a.string(), b.string()});
  CHECK(table.out.find("frame 3, vertex 17") != std::string::npos);
  CHECK(run_diff(dir, a, b, {"--tolerance-mm", "0.02"}).run.exit_code == 0);
}

TEST_CASE("facecap diff: the same solve stored in cm and in mm is the same", "[tools][diff]") {
  const auto dir = test::scratch_dir("diff-units");
  RecordingHeader in_mm = diff_header();
  in_mm.rig_units = "mm";
  const auto a = write_solves(dir, "cm.fcrec", diff_header());
  const auto b = write_solves(dir, "mm.fcrec", in_mm, [](SolvedFrame& f) {
    f.vertices *= 10.0f;
    f.head_translation *= 10.0;
    return true;
  });
  const Diff d = run_diff(dir, a, b);
  INFO(d.run.err);
  CHECK(d.run.exit_code == 0);
  CHECK(d.j["vertices_mm"]["max"].get<double>() < 1e-5);  // float rounding of x10 only
  CHECK(d.j["head_translation_mm"]["max"].get<double>() < 1e-12);
}

TEST_CASE("facecap diff: a status flag set in one file, named", "[tools][diff]") {
  const auto dir = test::scratch_dir("diff-flags");
  const auto a = write_solves(dir, "a.fcrec", diff_header());
  const auto b = write_solves(dir, "b.fcrec", diff_header(), [](SolvedFrame& f) {
    if (f.frame_no == 4) f.flags |= kSolvedQpIterationCap;
    return true;
  });
  const Diff d = run_diff(dir, a, b);
  INFO(d.run.err);
  REQUIRE(d.run.exit_code == 1);
  CHECK(d.j["beyond"] == std::vector<std::string>{"flags"});
  CHECK(d.j["flags"]["frames_differ"] == 1);
  CHECK(d.j["flags"]["bits"]["qp_iteration_cap"]["b_only"] == 1);
  CHECK(d.j["flags"]["bits"]["qp_iteration_cap"]["a_only"] == 0);
  CHECK(d.j["flags"]["bits"].size() == 1);
  REQUIRE(d.j["flags"]["first"].size() == 1);
  CHECK(d.j["flags"]["first"][0]["frame"] == 4);
  CHECK(d.j["flags"]["first"][0]["b_only"] == std::vector<std::string>{"qp_iteration_cap"});
  CHECK(d.j["flags"]["first"][0]["a_only"].empty());

  const Run table = run_facecap(dir, {"diff", a.string(), b.string()});
  CHECK(table.out.find("B only: qp_iteration_cap") != std::string::npos);
}

TEST_CASE("facecap diff: a frame missing from one file fails unless --allow-missing", "[tools][diff]") {
  const auto dir = test::scratch_dir("diff-missing");
  const auto a = write_solves(dir, "a.fcrec", diff_header());
  const auto b = write_solves(dir, "b.fcrec", diff_header(), [](SolvedFrame& f) { return f.frame_no != 5; });
  const Diff d = run_diff(dir, a, b);
  INFO(d.run.err);
  REQUIRE(d.run.exit_code == 1);
  CHECK(d.j["beyond"] == std::vector<std::string>{"missing_frames"});
  CHECK(d.j["frames"]["compared"] == kFrames - 1);
  CHECK(d.j["frames"]["only_in_a"]["count"] == 1);
  CHECK(d.j["frames"]["only_in_a"]["first"] == std::vector<int64_t>{5});
  CHECK(d.j["frames"]["only_in_b"]["count"] == 0);
  CHECK(d.j["weights"]["max"] == 0.0);  // frames 6.. matched by number, not by position

  const Diff allowed = run_diff(dir, a, b, {"--allow-missing"});
  CHECK(allowed.run.exit_code == 0);
  CHECK(allowed.j["beyond"].empty());
  CHECK(allowed.j["frames"]["only_in_a"]["count"] == 1);

  const Run table = run_facecap(dir, {"diff", b.string(), a.string()});
  CHECK(table.out.find("only in B: 1 (5)") != std::string::npos);
  CHECK(table.out.find("beyond tolerance: missing frames") != std::string::npos);
}

TEST_CASE("facecap diff: --top lists each channel's worst frames, largest first", "[tools][diff]") {
  const auto dir = test::scratch_dir("diff-top");
  const auto a = write_solves(dir, "a.fcrec", diff_header());
  const auto b = write_solves(dir, "b.fcrec", diff_header(), [](SolvedFrame& f) {
    // frame n's head moves n/10 mm (cm rig units)
    if (f.frame_no % 3 == 0) f.head_translation.x() += 0.01 * double(f.frame_no);
    return true;
  });
  const Diff d = run_diff(dir, a, b, {"--top", "2"});
  INFO(d.run.err);
  REQUIRE(d.run.exit_code == 1);
  const auto& t = d.j["head_translation_mm"];
  CHECK(t["frames_beyond"] == 4);  // frames 3, 6, 9, 12
  REQUIRE(t["worst"].size() == 2);
  CHECK(t["worst"][0]["frame"] == 12);
  CHECK(t["worst"][0]["difference"].get<double>() == Approx(1.2).epsilon(1e-9));
  CHECK(t["worst"][1]["frame"] == 9);
  CHECK(t["worst"][1]["difference"].get<double>() == Approx(0.9).epsilon(1e-9));
  CHECK(t["mean"].get<double>() == Approx((0.3 + 0.6 + 0.9 + 1.2) / double(kFrames)).epsilon(1e-9));
}

TEST_CASE("facecap diff: head rotation compared as the angle between the poses", "[tools][diff]") {
  const auto dir = test::scratch_dir("diff-rotation");
  const auto a = write_solves(dir, "a.fcrec", diff_header());
  const auto b = write_solves(dir, "b.fcrec", diff_header(), [](SolvedFrame& f) {
    if (f.frame_no == 2)
      f.head_rotation = f.head_rotation * Eigen::AngleAxisd(0.5 * std::numbers::pi / 180.0, Eigen::Vector3d::UnitZ());
    if (f.frame_no == 8) f.head_rotation.coeffs() *= -1.0;  // the same rotation
    return true;
  });
  const Diff d = run_diff(dir, a, b);
  INFO(d.run.err);
  REQUIRE(d.run.exit_code == 1);
  CHECK(d.j["beyond"] == std::vector<std::string>{"head_rotation"});
  CHECK(d.j["head_rotation_degrees"]["max"].get<double>() == Approx(0.5).epsilon(1e-9));
  CHECK(d.j["head_rotation_degrees"]["largest"]["frame"] == 2);
  CHECK(d.j["head_rotation_degrees"]["frames_beyond"] == 1);
}

TEST_CASE("facecap diff: a weight that is NaN on one side only is beyond any tolerance", "[tools][diff]") {
  const auto dir = test::scratch_dir("diff-nan");
  const auto a = write_solves(dir, "a.fcrec", diff_header());
  const auto b = write_solves(dir, "b.fcrec", diff_header(), [](SolvedFrame& f) {
    if (f.frame_no == 10) f.weights[5] = std::numeric_limits<float>::quiet_NaN();
    return true;
  });
  const Diff d = run_diff(dir, a, b, {"--tolerance-weight", "1e30"});
  INFO(d.run.err);
  REQUIRE(d.run.exit_code == 1);
  CHECK(d.j["weights"]["max"].is_null());  // infinite
  CHECK(d.j["weights"]["largest"]["frame"] == 10);
  CHECK(d.j["weights"]["largest"]["shape"] == 5);
  CHECK(run_diff(dir, b, b).run.exit_code == 0);  // NaN on both sides is the same value
}

TEST_CASE("facecap diff: changed solver settings are shown as a unified diff, not a failure", "[tools][diff]") {
  const auto dir = test::scratch_dir("diff-settings");
  RecordingHeader changed = diff_header();
  changed.solver_settings = "method = \"nonlinear\"\nalpha = 0.2\nmu = 0.001\n";
  const auto a = write_solves(dir, "a.fcrec", diff_header());
  const auto b = write_solves(dir, "b.fcrec", changed);
  const Diff d = run_diff(dir, a, b);
  INFO(d.run.err);
  CHECK(d.run.exit_code == 0);
  CHECK(d.j["solver_settings"]["differ"] == true);
  CHECK(d.j["solver_settings"]["diff"] ==
        "@@ -1,3 +1,3 @@\n method = \"nonlinear\"\n-alpha = 0.1\n+alpha = 0.2\n mu = 0.001\n");
  CHECK(d.j["calibration"]["differ"] == false);
  const Run table = run_facecap(dir, {"diff", a.string(), b.string()});
  CHECK(table.out.find("solver settings        differ:\n  @@ -1,3 +1,3 @@\n") != std::string::npos);
  CHECK(table.out.find("  +alpha = 0.2\n") != std::string::npos);
}

TEST_CASE("facecap diff: vertices in one file only are not compared and say so", "[tools][diff]") {
  const auto dir = test::scratch_dir("diff-no-vertices");
  const auto a = write_solves(dir, "a.fcrec", diff_header());
  const auto b = write_solves(dir, "b.fcrec", diff_header(), [](SolvedFrame& f) {
    f.vertices.resize(3, 0);
    return true;
  });
  const Diff d = run_diff(dir, a, b);
  INFO(d.run.err);
  CHECK(d.run.exit_code == 0);
  CHECK(d.j["vertices_mm"]["frames"] == 0);
  CHECK(d.j["vertices_mm"]["frames_with_vertices_only_in_a"] == kFrames);
  const Run table = run_facecap(dir, {"diff", a.string(), b.string()});
  CHECK(table.out.find("frames with vertices in one file only: A 12, B 0") != std::string::npos);
}

TEST_CASE("facecap diff: a recording cut short compares up to its last whole frame, with a warning", "[tools][diff]") {
  const auto dir = test::scratch_dir("diff-cut");
  const auto a = write_solves(dir, "a.fcrec", diff_header());
  std::vector<char> bytes = read_file_bytes(a);
  bytes.resize(bytes.size() / 2);  // a recorder killed mid-take
  write_file_atomically(dir / "cut.fcrec", bytes);
  const Diff d = run_diff(dir, a, dir / "cut.fcrec", {"--allow-missing"});
  INFO(d.run.err);
  REQUIRE(d.run.exit_code == 0);
  CHECK(d.j["b"]["truncated"] == true);
  CHECK(d.run.err.find("facecap: warning: " + (dir / "cut.fcrec").string()) != std::string::npos);
  const int64_t kept = d.j["b"]["solved_frames"].get<int64_t>();
  CHECK(kept > 0);
  CHECK(kept < kFrames);
  CHECK(d.j["frames"]["compared"] == kept);
  CHECK(d.j["frames"]["only_in_a"]["count"] == kFrames - kept);
  CHECK(d.j["frames"]["only_in_a"]["first"][0] == kept + 1);
}

TEST_CASE("facecap diff refuses different rigs and shape lists with their names (exit 2)", "[tools][diff]") {
  const auto dir = test::scratch_dir("diff-rigs");
  RecordingHeader other_rig = diff_header();
  other_rig.rig_name = "other-rig";
  other_rig.rig_hash = 0xfedcba9876543210ull;
  RecordingHeader other_shapes = diff_header();
  other_shapes.shape_names[2] = "eyeSquint_R";
  const auto a = write_solves(dir, "a.fcrec", diff_header());
  const auto b = write_solves(dir, "rig.fcrec", other_rig);
  const auto c = write_solves(dir, "shapes.fcrec", other_shapes);

  const Diff rig = run_diff(dir, a, b);
  CHECK(rig.run.exit_code == 2);
  CHECK(rig.run.out.empty());
  CHECK(rig.run.err.find("different rigs: 'diff-rig' (rig hash 0x0123456789abcdef) and 'other-rig' (rig hash "
                         "0xfedcba9876543210)") != std::string::npos);
  const Diff shapes = run_diff(dir, a, c);
  CHECK(shapes.run.exit_code == 2);
  CHECK(shapes.run.err.find("list different shapes (6 and 6): shape 2 is 'eyeBlink_R' and 'eyeSquint_R'") !=
        std::string::npos);
}

TEST_CASE("facecap diff: a version 1 recording needs --rig-units", "[tools][diff]") {
  const auto dir = test::scratch_dir("diff-v1");
  RecordingHeader v1 = diff_header();
  v1.rig_units.clear();
  v1.solver_settings.clear();
  const auto written = write_solves(dir, "v1.fcrec", v1);
  std::vector<char> bytes = read_file_bytes(written);
  bytes[8] = 1;  // format_version 1: HEAD without rig_units, as version 1 writers wrote it
  write_file_atomically(dir / "v1.fcrec", bytes);
  const auto a = write_solves(dir, "a.fcrec", diff_header());

  const Diff refused = run_diff(dir, a, dir / "v1.fcrec");
  CHECK(refused.run.exit_code == 2);
  CHECK(refused.run.err.find("v1.fcrec: HEAD names no rig_units (format version 1): pass --rig-units mm|cm|m") !=
        std::string::npos);

  const Diff given = run_diff(dir, a, dir / "v1.fcrec", {"--rig-units", "cm"});
  INFO(given.run.err);
  CHECK(given.run.exit_code == 0);
  CHECK(given.j["b"]["format_version"] == 1);
  CHECK(given.j["b"]["rig_units_from_option"] == true);
  CHECK(given.j["solver_settings"]["differ"] == true);

  // The wrong unit for the version 1 file: every vertex and head position is off.
  CHECK(run_diff(dir, a, dir / "v1.fcrec", {"--rig-units", "mm"}).run.exit_code == 1);
}

TEST_CASE("facecap diff: unreadable input and usage errors exit 2", "[tools][diff]") {
  const auto dir = test::scratch_dir("diff-trouble");
  const auto a = write_solves(dir, "a.fcrec", diff_header());
  MarkerFrame markers;
  markers.frame_no = 1;
  {
    RecordingWriter writer(dir / "markers.fcrec", diff_header());
    writer.append_marker_frame(markers);
  }
  const Diff marker_only = run_diff(dir, a, dir / "markers.fcrec");
  CHECK(marker_only.run.exit_code == 2);
  CHECK(marker_only.run.err.find("markers.fcrec: has no solved frames") != std::string::npos);

  const Diff absent = run_diff(dir, a, dir / "absent.fcrec");
  CHECK(absent.run.exit_code == 2);
  CHECK(absent.run.err.find("absent.fcrec") != std::string::npos);

  const auto repeated = write_solves(dir, "repeated.fcrec", diff_header(), [](SolvedFrame& f) {
    if (f.frame_no == 9) f.frame_no = 8;
    return true;
  });
  const Diff twice = run_diff(dir, a, repeated);
  CHECK(twice.run.exit_code == 2);
  CHECK(twice.run.err.find("repeated.fcrec: frame number 8 repeats (solved frames #7 and #8, counting from 0)") !=
        std::string::npos);

  test::write_text(dir / "text.fcrec", "not a recording\n");
  CHECK(run_diff(dir, a, dir / "text.fcrec").run.exit_code == 2);

  CHECK(run_diff(dir, a, a, {"--tolerance-mm", "-1"}).run.exit_code == 2);
  CHECK(run_diff(dir, a, a, {"--rig-units", "inch"}).run.exit_code == 2);
  CHECK(run_facecap(dir, {"diff", a.string()}).exit_code == 2);
}
