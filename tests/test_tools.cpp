// facecap synth, bench and eval, run as processes on the built-in rig, plus the pieces
// they share (truth files, mesh checks) called directly.
#include <array>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <string>

#include <catch2/catch.hpp>
#include <Eigen/Geometry>
#include <nlohmann/json.hpp>

#include "formats/take.hpp"
#include "pipeline/calibration.hpp"
#include "solver/builtin_face.hpp"
#include "tests/test_support.hpp"
#include "tools/synth_truth.hpp"
#include "tools/tool_support.hpp"

using namespace facecap;

namespace {

struct Run {
  int exit_code = -1;
  std::string out;
};

// Runs the facecap binary with arguments (a shell fragment), capturing stdout; stderr
// goes to the test log.
Run facecap_run(const std::string& arguments) {
  const std::string command = std::string(FACECAP_BINARY_DIR "/tools/facecap ") + arguments;
  Run run;
  FILE* pipe = popen(command.c_str(), "r");
  REQUIRE(pipe != nullptr);
  std::array<char, 4096> buffer{};
  std::size_t n = 0;
  while ((n = std::fread(buffer.data(), 1, buffer.size(), pipe)) > 0) run.out.append(buffer.data(), n);
  const int status = pclose(pipe);
  run.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return run;
}

nlohmann::json facecap_json(const std::string& arguments) {
  const Run run = facecap_run(arguments);
  INFO("facecap " << arguments << "\n" << run.out);
  REQUIRE(run.exit_code == 0);
  return nlohmann::json::parse(run.out);
}

std::string read_bytes(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

}  // namespace

TEST_CASE("synth writes a take that reads back with the right marker and frame counts") {
  const auto dir = test::scratch_dir("synth");
  const Run run = facecap_run("synth --rig builtin --frames 12 --markers 20 -o " + (dir / "take.trc").string());
  INFO(run.out);
  REQUIRE(run.exit_code == 0);
  const auto take = formats::read_take(dir / "take.trc");
  CHECK(take.marker_count() == 20);
  CHECK(take.frames.size() == 12);
  CHECK(take.rate_hz == 60.0);
  CHECK(take.units == "cm");

  const tools::SynthTruth truth = tools::read_synth_truth(dir / "take.truth.json");
  CHECK(truth.frame_count() == 12);
  CHECK(truth.marker_labels == take.labels);
  CHECK(truth.vertices_file == "take.truth.vertices");
  tools::TruthVerticesReader vertices(dir / truth.vertices_file);
  const BuiltinFace& face = BuiltinFace::instance();
  CHECK(vertices.vertex_count() == face.rig().vertex_count());
  CHECK(vertices.frame_count() == 12);

  // Noise-free markers sit on their vertices of the truth pose (float32 in the files).
  Eigen::Matrix3Xd pose;
  vertices.read(5, pose);
  CHECK((pose - face.articulated_pose(truth.weights[5])).cwiseAbs().maxCoeff() < 1e-5);
  for (std::size_t k = 0; k < 20; ++k) {
    const Marker& m = take.frames[5].markers[k];
    REQUIRE(m.present());
    CHECK((m.position - pose.col(truth.marker_vertices[k])).norm() < 1e-5);
  }

  // The markers are where facecapd's default calibration binds 20 face markers without a
  // head rig (the benchmark scripts replay synth's takes with no profile): same labels,
  // same vertices.
  const auto defaults = pipeline::default_calibration(face.rig(), 20, 0);
  REQUIRE(defaults.markers.size() == 20);
  for (std::size_t k = 0; k < 20; ++k) {
    CHECK(defaults.markers[k].label == truth.marker_labels[k]);
    CHECK(defaults.markers[k].binding.vertices[0] == truth.marker_vertices[k]);
  }
}

TEST_CASE("synth is deterministic for a seed and adds dropouts noise and head motion") {
  const auto dir = test::scratch_dir("synth_seed");
  const std::string common = "synth --rig builtin --frames 30 --markers 25 --noise 0.3 --dropout 0.2 --head-motion --units mm ";
  REQUIRE(facecap_run(common + "--seed 5 -o " + (dir / "a.c3d").string()).exit_code == 0);
  REQUIRE(facecap_run(common + "--seed 5 -o " + (dir / "b.c3d").string()).exit_code == 0);
  REQUIRE(facecap_run(common + "--seed 6 -o " + (dir / "c.c3d").string()).exit_code == 0);
  CHECK(read_bytes(dir / "a.c3d") == read_bytes(dir / "b.c3d"));
  CHECK(read_bytes(dir / "a.c3d") != read_bytes(dir / "c.c3d"));

  const auto take = formats::read_take(dir / "a.c3d");
  REQUIRE(take.frames.size() == 30);
  CHECK(take.units == "mm");
  const auto gaps = formats::count_gaps(take);
  const double missing = double(gaps.missing_samples) / (30.0 * 25.0);
  INFO("missing fraction " << missing);
  CHECK(missing > 0.05);
  CHECK(missing < 0.45);

  // Undoing the recorded head pose brings the markers back within the noise of the truth.
  const tools::SynthTruth truth = tools::read_synth_truth(dir / "a.truth.json");
  CHECK(truth.head_motion);
  CHECK(truth.head_rotation[10].norm() > 1e-3);
  tools::TruthVerticesReader vertices(dir / truth.vertices_file);
  Eigen::Matrix3Xd pose;
  double worst_mm = 0;
  for (std::size_t f = 0; f < 30; ++f) {
    vertices.read(int64_t(f), pose);
    const Eigen::Matrix3d R = Eigen::AngleAxisd(truth.head_rotation[f].norm(), truth.head_rotation[f].normalized())
                                  .toRotationMatrix();
    for (std::size_t k = 0; k < 25; ++k) {
      const Marker& m = take.frames[f].markers[k];
      if (!m.present()) continue;
      const Eigen::Vector3d rig_space = R.transpose() * (m.position / 10.0 - truth.head_translation[f]);
      worst_mm = std::max(worst_mm, 10.0 * (rig_space - pose.col(truth.marker_vertices[k])).norm());
    }
  }
  INFO("largest marker offset from truth " << worst_mm << " mm");
  CHECK(worst_mm > 0.3);  // the noise is there
  CHECK(worst_mm < 2.5);  // and nothing else: 0.3 mm sigma per axis
}

TEST_CASE("bench json has every field and zero allocations per frame for nonlinear and linear") {
  const auto report = facecap_json("bench --rig builtin --frames 30 --meshik-frames 2 --solver all --json");
  CHECK(report["rig"]["vertices"] == BuiltinFace::instance().rig().vertex_count());
  CHECK(report["rig"]["triangles"] == BuiltinFace::instance().rig().triangle_count());
  CHECK(report["rig"]["shapes"] == BuiltinFace::instance().rig().shape_count());
  CHECK(report["markers"] == 60);
  CHECK(report["frames"] == 30);
  for (const char* key : {"rig_load", "gradients", "factor", "modifications", "total"}) {
    INFO(key);
    CHECK(report["setup_s"][key].is_number());
  }
  for (const char* name : {"nonlinear", "linear", "dt", "meshik"}) {
    INFO(name);
    const auto& s = report["solvers"][name];
    REQUIRE(s.is_object());
    CHECK(s["total_us"]["median"].get<double>() > 0);
    CHECK(s["total_us"]["p99"].get<double>() >= s["total_us"]["median"].get<double>());
    CHECK(s["fps"].get<double>() > 0);
    REQUIRE(s["allocations_per_frame"].is_number());
    CHECK(s["stages_us"]["weights"]["median"].is_number());
  }
  for (const char* stage : {"weights", "blend", "rhs", "backsolve", "collide"}) {
    INFO(stage);
    CHECK(report["solvers"]["nonlinear"]["stages_us"][stage]["median"].is_number());
    CHECK(report["solvers"]["nonlinear"]["stages_us"][stage]["p99"].is_number());
  }
  CHECK(report["solvers"]["nonlinear"]["allocations_per_frame"] == 0.0);
  CHECK(report["solvers"]["linear"]["allocations_per_frame"] == 0.0);
  CHECK(report["solvers"]["meshik"]["frames"] == 2);
  // meshik allocates: seeing it counted shows the counter is live.
  CHECK(report["solvers"]["meshik"]["allocations_per_frame"].get<double>() > 0);
}

TEST_CASE("eval json reports every field for every solver") {
  const auto dir = test::scratch_dir("eval_fields");
  REQUIRE(facecap_run("synth --rig builtin --frames 6 --dropout 0.1 --noise 0.1 --head-motion -o " + (dir / "t.trc").string())
              .exit_code == 0);
  const auto report = facecap_json("eval --rig builtin --take " + (dir / "t.trc").string() + " --solver all --json");
  CHECK(report["frames"] == 6);
  CHECK(report["markers"] == 60);
  CHECK(report["truth"] == "articulated vertices");
  for (const char* name : {"nonlinear", "linear", "dt", "meshik"}) {
    INFO(name);
    const auto& s = report["solvers"][name];
    REQUIRE(s.is_object());
    CHECK(s["truth_vertex_mm"]["mean"].get<double>() > 0);
    CHECK(s["truth_vertex_mm"]["p95"].get<double>() >= 0);
    CHECK(s["truth_vertex_mm"]["mean"].get<double>() < 5.0);  // head motion was undone
    CHECK(s["jitter_mm"].get<double>() >= 0);
    CHECK(s["intersections"].is_number_integer());
    CHECK(s["flipped_triangles"].is_number_integer());
  }
}

TEST_CASE("eval on a jaw and blink take reports nonlinear truth error below linear") {
  const auto dir = test::scratch_dir("eval_jaw");
  // 90 frames of the built-in motion at 60 Hz: a blink (0 - 0.3 s) and the jaw opening
  // to about 0.55, with smiles, brows and lips moving.
  REQUIRE(facecap_run("synth --rig builtin --frames 90 -o " + (dir / "jaw.trc").string()).exit_code == 0);
  const auto report =
      facecap_json("eval --rig builtin --take " + (dir / "jaw.trc").string() + " --solver nonlinear,linear --json");
  const double nonlinear = report["solvers"]["nonlinear"]["truth_vertex_mm"]["mean"].get<double>();
  const double linear = report["solvers"]["linear"]["truth_vertex_mm"]["mean"].get<double>();
  INFO("mean truth vertex error: nonlinear " << nonlinear << " mm, linear " << linear << " mm");
  CHECK(nonlinear < linear);
}

TEST_CASE("Live Link Face weights drive the ICT rig by ARKit name") {
  FACECAP_REQUIRE_SHARED_DATA(csv, "livelinkface/jmtechart_MySlate_3_Jason_Millers_iPhone.csv");
  FACECAP_REQUIRE_SHARED_DATA(ict, "ict-face");
  const Rig rig = load_rig(ict.string());
  const auto curves = tools::livelinkface_curves(csv, rig, 0.0, -1);
  CHECK(curves.rate_hz == Approx(60.0).epsilon(0.02));
  CHECK(curves.frames.size() > 300);
  CHECK(curves.driven_shapes.size() >= 51);  // every ARKit shape but TongueOut, split brow and cheek shapes
  const auto jaw = rig.shape_index("jawOpen");
  REQUIRE(jaw);
  double largest = 0;
  for (const auto& w : curves.frames) {
    CHECK(w.minCoeff() >= 0.0);
    CHECK(w.maxCoeff() <= 1.0);
    largest = std::max(largest, w[*jaw]);
  }
  CHECK(largest > 0.05);
  // Resampling to 30 Hz halves the frames.
  const auto half = tools::livelinkface_curves(csv, rig, 30.0, -1);
  CHECK(std::abs(double(half.frames.size()) - double(curves.frames.size()) / 2.0) <= 1.0);
}

TEST_CASE("loopcheck accounts for every slot of its grid and refuses work longer than the period") {
  // 0.5 s at 500 Hz with 0.2 ms of computation a tick.
  const auto report = facecap_json("loopcheck --rate 500 --work-ms 0.2 --seconds 0.5 --json");
  const auto ticks = report["ticks"].get<uint64_t>();
  const auto skipped = report["skipped_ticks"].get<uint64_t>();
  CHECK(ticks > 0);
  CHECK(ticks + skipped == report["slots"].get<uint64_t>());
  CHECK(report["slots"].get<uint64_t>() >= 250);
  CHECK(report["late_start_misses"].get<uint64_t>() <= report["missed_deadlines"].get<uint64_t>());
  // The calibrated work takes its 0.2 ms (more on a loaded machine, never much less).
  CHECK(report["tick_ms"]["p50"].get<double>() >= 0.15);
  CHECK(report["wake_late_ms"]["max"].get<double>() >= report["wake_late_ms"]["p50"].get<double>());

  const Run too_long = facecap_run("loopcheck --rate 240 --work-ms 5 --seconds 1 2>&1");
  CHECK(too_long.exit_code == 1);
  CHECK_THAT(too_long.out, Catch::Matchers::Contains("--work-ms 5: allowed 0 up to the period, 4.167 ms at 240 Hz"));
}
