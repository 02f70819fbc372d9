// The one solve path (pipeline/): where calibrations come from, the marker mapper, and
// SolvePipeline's status bits.
#include <catch2/catch.hpp>
#include <fmt/format.h>

#include "core/error.hpp"
#include "pipeline/calibration.hpp"
#include "pipeline/marker_mapper.hpp"
#include "pipeline/solve_pipeline.hpp"
#include "solver/align/calibrate_take.hpp"
#include "solver/align/profile.hpp"
#include "solver/builtin_face.hpp"
#include "tests/align_test_support.hpp"
#include "tests/test_support.hpp"

using namespace facecap;
using Catch::Contains;
namespace fs = std::filesystem;

namespace {

// Every marker of a frame present, at `position(k)`.
template <typename Position>
MarkerFrame frame_at(const std::vector<std::string>& labels, Position position) {
  MarkerFrame frame = make_marker_frame(labels);
  for (std::size_t k = 0; k < labels.size(); ++k) {
    frame.markers[k].position = position(k);
    frame.markers[k].flags = 0;
  }
  return frame;
}

std::vector<std::string> labels_of(const pipeline::Calibration& c) {
  std::vector<std::string> labels;
  for (const auto& m : c.markers) labels.push_back(m.label);
  for (const auto& h : c.head_markers) labels.push_back(h.label);
  return labels;
}

}  // namespace

TEST_CASE("head stabilisation undoes a known rigid motion exactly and holds the pose with too few head markers") {
  const Rig& rig = BuiltinFace::instance().rig();
  const pipeline::Calibration calibration = pipeline::default_calibration(rig, 6, 4);
  REQUIRE(calibration.head_markers.size() == 4);
  CHECK(calibration.stable_markers == std::vector<std::string>{"H0", "H1", "H2", "H3"});
  const std::vector<std::string> labels = labels_of(calibration);
  pipeline::MarkerMapper mapper(calibration, labels, "cm");
  REQUIRE(mapper.stabilising());
  Eigen::Isometry3d motion = Eigen::Isometry3d::Identity();
  motion.linear() = Eigen::AngleAxisd(0.3, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  motion.translation() = Eigen::Vector3d(1.5, -2, 0.7);
  const MarkerSet rest = pipeline::rest_marker_set(calibration);
  MarkerFrame frame = frame_at(labels, [&](std::size_t k) {
    return motion * (k < 6 ? binding_point(rest.face[k], rig.neutral) : rest.head[k - 6].position);
  });
  frame.markers[2].flags = kMarkerMissing;
  pipeline::MappedFrame mapped = mapper.make_output();
  mapper.process(frame, mapped);
  CHECK(mapped.markers_present == 5);
  CHECK_FALSE(mapped.head_held);
  CHECK(mapped.present == std::vector<uint8_t>{1, 1, 0, 1, 1, 1});
  CHECK(mapped.head_rotation.toRotationMatrix().isApprox(motion.linear(), 1e-12));
  CHECK((mapped.head_translation - motion.translation()).norm() < 1e-9);
  CHECK((mapped.targets.col(0) - calibration.markers[0].bound_point).norm() < 1e-9);
  // Two head markers lost: the pose is held, not refitted from too little.
  frame.markers[6].flags = frame.markers[7].flags = kMarkerMissing;
  mapper.process(frame, mapped);
  CHECK(mapped.head_held);
  CHECK((mapped.head_translation - motion.translation()).norm() < 1e-9);
}

TEST_CASE("a source with fewer than 3 of the calibration's markers is refused, naming both sides") {
  const pipeline::Calibration calibration = pipeline::default_calibration(BuiltinFace::instance().rig(), 4, 0);
  CHECK_THROWS_WITH(pipeline::MarkerMapper(calibration, std::vector<std::string>{"LeftCheek", "M000", "Chin"}, ""),
                    Contains("only 1 of the calibration's 4 markers (M000, ...) are among the source's 3 markers (LeftCheek, ...)"));
}

TEST_CASE("a hand-written calibration binds markers and moves them into rig space, in the source's units") {
  const fs::path file = test::scratch_dir("calibration") / "cal.toml";
  test::write_text(file, "version = 1\nmarker_units = \"mm\"\ntranslation = [0, 0, 1]\n"
                         "[[face]]\nlabel = \"a\"\nvertex = 10\n[[face]]\nlabel = \"b\"\nvertex = 20\n"
                         "[[face]]\nlabel = \"c\"\nvertices = [30, 31, 32]\nbarycentric = [0.5, 0.25, 0.25]\n");
  const Rig& rig = BuiltinFace::instance().rig();  // in cm
  const pipeline::Calibration calibration = pipeline::load_calibration({.file = file.string()}, rig);
  REQUIRE(calibration.markers.size() == 3);
  CHECK(calibration.markers[2].binding.vertices == std::array<int, 3>{30, 31, 32});
  CHECK(calibration.take_to_rig.scale == Approx(0.1));  // mm markers on a cm rig
  CHECK(calibration.stable_markers.empty());
  const std::vector<std::string> labels{"c", "a", "b"};
  // A marker at the bound point carried back into marker space gives its bound point ...
  const Eigen::Vector3d a_mm = calibration.markers[0].neutral;  // "a", in frame slot 1
  MarkerFrame frame = frame_at(labels, [&](std::size_t k) { return calibration.markers[(k + 2) % 3].neutral; });
  pipeline::MarkerMapper in_mm(calibration, labels, "mm");
  CHECK_FALSE(in_mm.stabilising());
  pipeline::MappedFrame mapped = in_mm.make_output();
  in_mm.process(frame, mapped);
  for (Eigen::Index k = 0; k < 3; ++k) CHECK((mapped.targets.col(k) - calibration.markers[std::size_t(k)].bound_point).norm() < 1e-12);
  // ... and 10 mm along x moves the target 1 cm (0.1 * p + (0, 0, 1)).
  frame.markers[1].position = a_mm + Eigen::Vector3d(10, 0, 0);
  in_mm.process(frame, mapped);
  CHECK((mapped.targets.col(0) - calibration.markers[0].bound_point - Eigen::Vector3d(1, 0, 0)).norm() < 1e-12);
  // The same frame from a source in cm: converted into the calibration's mm on the way in.
  pipeline::MarkerMapper in_cm(calibration, labels, "cm");
  CHECK(in_cm.source_to_take() == 10.0);
  for (auto& m : frame.markers) m.position /= 10.0;
  in_cm.process(frame, mapped);
  CHECK((mapped.targets.col(0) - calibration.markers[0].bound_point - Eigen::Vector3d(1, 0, 0)).norm() < 1e-12);

  test::write_text(file, "version = 1\n[[face]]\nlabel = \"a\"\nvertex = 999999\n");
  CHECK_THROWS_WITH(pipeline::load_calibration({.file = file.string()}, rig),
                    Contains(file.string() + ":4:10") && Contains("vertex 999999 is not in the rig"));
  test::write_text(file, "version = 1\nrotation_wxyz = [nan, 0, 0, 0]\n");
  CHECK_THROWS_WITH(pipeline::load_calibration({.file = file.string()}, rig),
                    Contains(file.string() + ":2:17") && Contains("finite"));
  test::write_text(file, "version = 1\n[[face]]\nlabel = \"a\"\nvertex = 1\n[[face]]\nlabel = \"a\"\nvertex = 2\n"
                         "[[face]]\nlabel = \"b\"\nvertex = 3\n");
  CHECK_THROWS_WITH(pipeline::load_calibration({.file = file.string()}, rig), Contains("marker 'a' is given twice"));
}

TEST_CASE("a calibration file with nan, inf or out-of-range numbers is refused where they are") {
  const fs::path file = test::scratch_dir("calibration-nan") / "cal.toml";
  const Rig& rig = BuiltinFace::instance().rig();
  const std::string faces = "[[face]]\nlabel = \"a\"\nvertex = 10\n[[face]]\nlabel = \"b\"\nvertex = 20\n"
                            "[[face]]\nlabel = \"c\"\nvertex = 30\n";
  // rotation_wxyz = [nan, 0, 0, 0] was accepted (a NaN rotation for every marker).
  for (const char* bad : {"rotation_wxyz = [nan, 0, 0, 0]", "rotation_wxyz = [1, 0, inf, 0]", "translation = [0, -inf, 0]"}) {
    INFO(bad);
    test::write_text(file, fmt::format("version = 1\n{}\n{}", bad, faces));
    CHECK_THROWS_WITH(pipeline::load_calibration({.file = file.string()}, rig),
                      Contains(file.string() + ":2:") && Contains("finite numbers"));
  }
  // A vertex number no integer holds (its conversion was undefined behaviour).
  test::write_text(file, "version = 1\n[[face]]\nlabel = \"a\"\nvertices = [1e300, 1, 2]\nbarycentric = [1, 0, 0]\n" + faces);
  CHECK_THROWS_WITH(pipeline::load_calibration({.file = file.string()}, rig),
                    Contains(file.string() + ":4:") && Contains("vertex 1e+300 is not in the rig"));
  test::write_text(file, "version = 1\n[[face]]\nlabel = \"\xc3\x28\"\nvertex = 1\n" + faces);
  CHECK_THROWS_WITH(pipeline::load_calibration({.file = file.string()}, rig),
                    Contains(file.string() + ":3:10") && Contains("not valid UTF-8"));
}

TEST_CASE("a calibration with head-rig markers round-trips through the profile and stabilises from them alone") {
  const Rig& rig = BuiltinFace::instance().rig();
  const pipeline::Calibration calibration = pipeline::default_calibration(rig, 8, 4);
  const std::string text = align::write_calibration_profile(calibration);
  CHECK(text.find("version = 2") != std::string::npos);  // head markers need version 2
  const pipeline::Calibration back = pipeline::read_calibration(text, "embedded", rig);
  REQUIRE(back.head_markers.size() == 4);
  CHECK(back.head_markers[3].label == calibration.head_markers[3].label);
  CHECK(back.head_markers[3].neutral == calibration.head_markers[3].neutral);
  CHECK(back.stable_markers == calibration.stable_markers);
  CHECK(align::write_calibration_profile(back) == text);
  // Without head markers a profile stays version 1, which older readers read.
  const std::string plain = align::write_calibration_profile(pipeline::default_calibration(rig, 8, 0));
  CHECK(plain.find("version = 1") != std::string::npos);
}

// `facecap calibrate` then facecapd: the profile the tool writes is the calibration the
// daemon loads; one made for another rig is refused, naming the file.
TEST_CASE("a facecap calibrate profile loads as the calibration and another rig's is refused") {
  test::SyntheticTakeOptions options;
  options.head_sway_deg = 4.0;
  const test::SyntheticTake take = test::make_synthetic_take(options);
  const Rig& rig = BuiltinFace::instance().rig();
  align::TakeCalibrationOptions calibrate_options;
  calibrate_options.neutral.rate_hz = 60.0;
  calibrate_options.neutral.take_mm_per_unit = 1.0;
  const align::Calibration profile = align::calibrate_take(rig, take.labels, take.frames, calibrate_options).calibration;
  REQUIRE(profile.stable_markers.size() >= 3);
  const fs::path file = test::scratch_dir("calibration") / "actor.toml";
  align::save_calibration_profile(file, profile);
  const pipeline::Calibration loaded = pipeline::load_calibration({.file = file.string()}, rig);
  CHECK(align::write_calibration_profile(loaded) == align::write_calibration_profile(profile));
  const pipeline::MarkerMapper mapper(loaded, take.labels, "mm");
  CHECK(mapper.stabilising());
  CHECK(mapper.markers_found() == profile.markers.size());

  auto other = profile;
  other.rig_hash ^= 1;
  align::save_calibration_profile(file, other);
  CHECK_THROWS_WITH(pipeline::load_calibration({.file = file.string()}, rig), Contains(file.string()));
}

TEST_CASE("a solved frame carries the mapper's head-held and the solver's too-few-markers status") {
  const Rig& rig = BuiltinFace::instance().rig();
  const pipeline::Calibration calibration = pipeline::default_calibration(rig, 12, 4);
  const std::vector<std::string> labels = labels_of(calibration);
  pipeline::SolvePipeline solve(rig, calibration, {labels, "cm"}, {});
  SolvedFrame solved = solve.make_solved_frame(false);
  const MarkerSet rest = pipeline::rest_marker_set(calibration);
  MarkerFrame frame = frame_at(labels, [&](std::size_t k) {
    return k < 12 ? binding_point(rest.face[k], rig.neutral) : rest.head[k - 12].position;
  });
  solve.process(frame, solved);
  CHECK(solved.flags == 0);
  CHECK(solved.markers_used == 12);
  for (auto& m : frame.markers) m.flags = kMarkerMissing;
  solve.process(frame, solved);
  CHECK(solved.flags == (kSolvedHeadPoseHeld | kSolvedTooFewMarkers));
}
