// The v4l2 driver's camera pipeline without cameras: its calibration file, blob detection,
// triangulation (against OpenCV's and against the truth the images were rendered from),
// frame sets matched by time, and the driver itself fed rendered images below V4L2, its
// unlabelled points labelled and solved by the pipeline. And its errors with no camera
// there.
#include <algorithm>
#include <cmath>
#include <random>
#include <thread>

#include <Eigen/Core>
#include <catch2/catch.hpp>
#include <fmt/format.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>
#include <opencv2/imgproc.hpp>

#include "config/config_file.hpp"
#include "core/error.hpp"
#include "core/time.hpp"
#include "drivers/sim/sim_source.hpp"
#include "drivers/v4l2/camera_pipeline.hpp"
#include "drivers/v4l2/v4l2_source.hpp"
#include "pipeline/calibration.hpp"
#include "pipeline/settings.hpp"
#include "pipeline/solve_pipeline.hpp"
#include "solver/builtin_face.hpp"
#include "tests/synthetic_cameras.hpp"
#include "tests/test_support.hpp"

using namespace facecap;
using namespace facecap::drivers::v4l2;
using Catch::Contains;
namespace fs = std::filesystem;

namespace {

std::shared_ptr<const Rig> builtin_rig() {
  return std::shared_ptr<const Rig>(std::shared_ptr<const Rig>(), &BuiltinFace::instance().rig());
}

// The default configuration's sim and marker set (48 face + 4 head markers).
struct SimScene {
  config::DaemonConfig config = config::default_config();
  std::shared_ptr<const Rig> rig = builtin_rig();
  pipeline::Calibration calibration = pipeline::load_calibration(pipeline::calibration_spec(config), *rig);
  drivers::SimSource sim{config.source.sim, rig, pipeline::rest_marker_set(calibration)};
  SimScene() { sim.open(); }
};

drivers::V4l2Options v4l2_options(const fs::path& calibration) {
  drivers::V4l2Options o = config::default_config().source.v4l2;
  o.calibration = calibration.string();
  return o;
}

}  // namespace

TEST_CASE("a calibration written in the cameras layout reads back exactly, and OpenCV's stereo layout reads") {
  const CameraCalibration rig = test::face_cameras({10, 20, 30}, 3);
  const fs::path file = test::scratch_dir("calibration") / "cameras.yaml";
  write_camera_calibration(file, rig);
  const CameraCalibration back = read_camera_calibration(file);
  REQUIRE(back.cameras.size() == 3);
  CHECK(back.units == "mm");
  for (std::size_t c = 0; c < 3; ++c) {
    CHECK(back.cameras[c].name == rig.cameras[c].name);
    CHECK(back.cameras[c].width == 640);
    CHECK((back.cameras[c].camera_matrix - rig.cameras[c].camera_matrix).norm() < 1e-12);
    CHECK(back.cameras[c].distortion == rig.cameras[c].distortion);
    CHECK((back.cameras[c].rotation - rig.cameras[c].rotation).norm() < 1e-12);
    CHECK((back.cameras[c].translation - rig.cameras[c].translation).norm() < 1e-9);
  }

  // As OpenCV's stereo_calib sample writes it (intrinsics and extrinsics in one file), R as
  // a Rodrigues vector, no %YAML line.
  const CameraCalibration stereo = parse_camera_calibration(
      "units: cm\nM1: !!opencv-matrix\n  rows: 3\n  cols: 3\n  dt: d\n  data: [800, 0, 320, 0, 800, 240, 0, 0, 1]\n"
      "D1: [-0.1, 0.01, 0, 0, 0]\nM2: !!opencv-matrix\n  rows: 3\n  cols: 3\n  dt: d\n"
      "  data: [810, 0, 330, 0, 810, 250, 0, 0, 1]\nD2: [-0.1, 0.01, 0, 0]\n"
      "R: !!opencv-matrix\n  rows: 3\n  cols: 1\n  dt: d\n  data: [0, 0.5, 0]\nT: [-25, 0, 3]\n",
      "stereo.yml");
  REQUIRE(stereo.cameras.size() == 2);
  CHECK(stereo.units == "cm");
  CHECK(stereo.cameras[0].rotation.isIdentity());
  CHECK(stereo.cameras[1].camera_matrix(0, 2) == 330);
  CHECK(stereo.cameras[1].distortion.size() == 4);
  CHECK(std::abs(stereo.cameras[1].rotation(0, 2) - std::sin(0.5)) < 1e-12);
  CHECK(stereo.cameras[1].translation == Eigen::Vector3d(-25, 0, 3));
}

TEST_CASE("a bad calibration is refused naming the file and the line or the key") {
  // OpenCV's YAML wants a sequence indented under its key.
  const std::string k = "    camera_matrix: !!opencv-matrix\n      rows: 3\n      cols: 3\n      dt: d\n"
                        "      data: [800, 0, 320, 0, 800, 240, 0, 0, 1]\n";
  const std::string pose = "    rotation: [0, 0, 0]\n    translation: [0, 0, 0]\n";
  const std::string second = "  - name: b\n" + k + "    rotation: [0, 0.5, 0]\n    translation: [100, 0, 0]\n";
  auto parse = [](const std::string& text) { return parse_camera_calibration(text, "cal.yaml"); };
  CHECK_THROWS_WITH(parse(""), Contains("cal.yaml") && Contains("empty"));
  CHECK_THROWS_WITH(parse("units: mm\ncameras:\n  - name: a\n   bad: [\n"), Contains("cal.yaml:4"));
  CHECK_THROWS_WITH(parse("cameras:\n  - name: a\n" + pose + second),
                    Contains("cal.yaml [cameras[0].camera_matrix]") && Contains("is missing"));
  CHECK_THROWS_WITH(parse("cameras:\n  - name: a\n" + k + "    rotation: [1, 2, 3, 4, 5, 6, 7, 8, 9]\n" +
                          "    translation: [0, 0, 0]\n" + second),
                    Contains("[cameras[0].rotation]") && Contains("not a rotation"));
  CHECK_THROWS_WITH(parse("cameras:\n  - name: a\n" + k + pose + "    distortion_coefficients: [1, 2, 3]\n" + second),
                    Contains("[cameras[0].distortion_coefficients]") && Contains("4, 5, 8, 12 or 14 coefficients, not 3"));
  CHECK_THROWS_WITH(parse("cameras:\n  - name: a\n" + k + pose), Contains("1 camera: triangulation needs at least 2"));
  CHECK_THROWS_WITH(parse("cameras:\n  - name: a\n" + k + pose + "  - name: b\n" + k + pose),
                    Contains("[cameras[1].translation]") && Contains("b sits where a does"));
  // Sizes are checked before OpenCV allocates the matrix.
  CHECK_THROWS_WITH(parse("cameras:\n  - camera_matrix: !!opencv-matrix\n      rows: 100000000\n      cols: 100000000\n"
                          "      dt: d\n      data: [1]\n"),
                    Contains("100000000x100000000 matrix is outside 1x1 to 16x16"));
  CHECK_THROWS_WITH(parse("units: inches\ncameras: []\n"), Contains("[units]"));
  // A key with no name (made OpenCV's reader throw std::length_error: a fuzzer's find).
  CHECK_THROWS_WITH(parse("cameras:\n  - name: left\n    :\n  - name: right\n"),
                    Contains("cal.yaml:3") && Contains("a key with no name"));
  CHECK_THROWS_WITH(read_camera_calibration("/nonexistent/cal.yaml"), Contains("/nonexistent/cal.yaml"));
}

TEST_CASE("calibration YAML: our reader takes what OpenCV writes and refuses the rest of YAML at its line, in linear time") {
  auto parse = [](const std::string& text) { return parse_camera_calibration(text, "cal.yaml"); };
  // As OpenCV's writer lays it out: `-` alone, quoted names, data lists over several lines.
  const std::string camera = "      camera_matrix: !!opencv-matrix\n         rows: 3\n         cols: 3\n         dt: d\n"
                             "         data: [ 8.2e+02, 0., 320.,\n             0., 820., 2.4e+02, 0., 0.,\n"
                             "             1. ]\n";
  const CameraCalibration rig = parse("%YAML:1.0\n---\nunits: \"cm\"   # a comment\ncameras:\n   -\n      name: \"left: # 1\"\n" +
                                      camera + "      rotation: [ 0, 0, 0 ]\n      translation: [0, 0, 0]\n   -\n"
                                      "      name: 'right''s'\n" + camera +
                                      "      rotation: [0, 0.1, 0]\n      translation: [-60, 0, 0]\n");
  REQUIRE(rig.cameras.size() == 2);
  CHECK(rig.units == "cm");
  CHECK(rig.cameras[0].name == "left: # 1");
  CHECK(rig.cameras[1].name == "right's");
  CHECK(rig.cameras[1].camera_matrix(1, 2) == 240);
  CHECK(rig.cameras[1].translation.x() == -60);
  // OpenCV 4.6's reader spins forever on these 48 bytes (JSON, a base64 header of zeros).
  CHECK_THROWS_WITH(parse("{\"a\":\"$base64$AAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAA\"}"),
                    Contains("cal.yaml:1") && Contains("flow mappings"));
  CHECK_THROWS_WITH(parse("<?xml version=\"1.0\"?>\n<opencv_storage>\n"), Contains("cal.yaml:1"));
  CHECK_THROWS_WITH(parse("units: mm\ncameras: [1, 2\n"), Contains("cal.yaml:2") && Contains("does not close"));
  CHECK_THROWS_WITH(parse("units: mm\n\tcameras: []\n"), Contains("cal.yaml:2") && Contains("tab"));
  CHECK_THROWS_WITH(parse("units: mm\nunits: cm\n"), Contains("cal.yaml:2") && Contains("given twice"));
  CHECK_THROWS_WITH(parse("units: &u mm\n"), Contains("anchors"));
  CHECK_THROWS_WITH(parse("notes: |\n  text\n"), Contains("block scalars"));
  CHECK_THROWS_WITH(parse("units: \"mm\ncameras: []\n"), Contains("cal.yaml:1") && Contains("does not end"));
  // Deep nesting is refused at a fixed depth, not followed down the stack.
  std::string deep = "cameras: " + std::string(100000, '[') + "\n";
  CHECK_THROWS_WITH(parse(deep), Contains("nested deeper than 32 levels"));
  deep.clear();
  for (int i = 0; i < 5000; ++i) deep += std::string(std::size_t(2 * i), ' ') + "- \n";
  CHECK_THROWS_WITH(parse("cameras:\n" + deep), Contains("nested deeper than 32 levels"));
}

TEST_CASE("blobs: sub-pixel centroids of Gaussian dots, and streaks, specks and floods left out") {
  cv::Mat image(480, 640, CV_32FC1, cv::Scalar(12));
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> fraction(0, 1);
  std::vector<cv::Point2d> truth;
  for (int i = 0; i < 40; ++i) {
    const cv::Point2d at(40 + 60 * (i % 10) + fraction(rng), 60 + 90 * (i / 10) + fraction(rng));
    truth.push_back(at);
    for (int y = int(at.y) - 6; y <= int(at.y) + 6; ++y)
      for (int x = int(at.x) - 6; x <= int(at.x) + 6; ++x)
        image.at<float>(y, x) += float(200 * std::exp(-((x - at.x) * (x - at.x) + (y - at.y) * (y - at.y)) / (2 * 1.2 * 1.2)));
  }
  cv::line(image, {100, 440}, {130, 452}, cv::Scalar(230), 2);  // a streak
  image.at<float>(470, 600) = 250;                              // a one-pixel speck
  cv::circle(image, {560, 430}, 20, cv::Scalar(240), -1);       // a lamp
  cv::Mat grain(image.size(), CV_32FC1);
  cv::RNG(5).fill(grain, cv::RNG::NORMAL, 0.0, 2.0);
  cv::Mat grey;
  cv::Mat(image + grain).convertTo(grey, CV_8UC1);

  BlobDetector detector;
  std::vector<Blob> blobs;
  detector.detect(grey, blobs);
  REQUIRE(blobs.size() == truth.size());
  CHECK(detector.rejected_shape() == 1);
  CHECK(detector.rejected_size() == 2);
  double worst = 0;
  for (const cv::Point2d& t : truth) {
    double best = INFINITY;
    for (const Blob& b : blobs) best = std::min(best, std::hypot(b.x - t.x, b.y - t.y));
    worst = std::max(worst, best);
  }
  INFO("worst centroid error " << worst << " px");
  CHECK(worst < 0.1);  // noise of 2 grey levels on a 200-level peak
  for (const Blob& b : blobs) CHECK(b.roundness > 0.9);
}

TEST_CASE("blobs: the run labelling finds the components OpenCV's connectedComponentsWithStats does") {
  // Random speckle with touching, diagonal and U-shaped regions; every filter open.
  cv::Mat grey(120, 160, CV_8UC1);
  cv::RNG(9).fill(grey, cv::RNG::UNIFORM, 0, 256);
  cv::Mat binary, labels, stats, centroids;
  cv::threshold(grey, binary, 200, 255, cv::THRESH_BINARY);
  const int count = cv::connectedComponentsWithStats(binary, labels, stats, centroids, 8, CV_32S);
  BlobDetector detector({.threshold = 200, .min_area_px = 1, .max_area_px = 1 << 20, .min_roundness = 0, .max_blobs = 1 << 20});
  std::vector<Blob> blobs;
  detector.detect(grey, blobs);
  REQUIRE(detector.components() == count - 1);
  REQUIRE(int(blobs.size()) == count - 1);
  std::vector<int> ours, theirs;
  for (const Blob& b : blobs) ours.push_back(b.area_px);
  for (int label = 1; label < count; ++label) theirs.push_back(stats.at<int>(label, cv::CC_STAT_AREA));
  std::sort(ours.begin(), ours.end());
  std::sort(theirs.begin(), theirs.end());
  CHECK(ours == theirs);
}

TEST_CASE("the DLT agrees with cv::triangulatePoints on two views") {
  const CameraCalibration rig = test::face_cameras({0, 0, 0});
  Triangulator triangulator(rig);
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-80, 80), jitter(-1e-4, 1e-4);  // mm; normalised (0.08 px)
  cv::Mat p0, p1;
  Eigen::Matrix<double, 3, 4> e0, e1;
  e0 << rig.cameras[0].rotation, rig.cameras[0].translation;
  e1 << rig.cameras[1].rotation, rig.cameras[1].translation;
  cv::eigen2cv(e0, p0);
  cv::eigen2cv(e1, p1);
  for (int i = 0; i < 50; ++i) {
    const Eigen::Vector3d x(u(rng), u(rng), u(rng));
    // Noisy views, so the two methods must agree on a least-squares answer, not only on exact data.
    const Eigen::Vector2d a = triangulator.project_normalised(0, x) + Eigen::Vector2d(jitter(rng), jitter(rng));
    const Eigen::Vector2d b = triangulator.project_normalised(1, x) + Eigen::Vector2d(jitter(rng), jitter(rng));
    const PointView views[] = {{e0, a}, {e1, b}};
    const Eigen::Vector3d ours = triangulate_dlt(views);
    cv::Mat homogeneous;
    cv::triangulatePoints(p0, p1, cv::Mat(cv::Point2d(a.x(), a.y())), cv::Mat(cv::Point2d(b.x(), b.y())), homogeneous);
    const Eigen::Vector3d theirs(homogeneous.at<double>(0) / homogeneous.at<double>(3),
                                 homogeneous.at<double>(1) / homogeneous.at<double>(3),
                                 homogeneous.at<double>(2) / homogeneous.at<double>(3));
    CHECK((ours - theirs).norm() < 1e-6);
    // 0.08 px of noise at 500 mm over a 260 mm baseline: depth to z^2 / (f b) * 0.1 px ~ 0.12 mm.
    CHECK((ours - x).norm() < 0.3);
  }
}

TEST_CASE("48 face markers through two 640x480 cameras: all but 1 in 1000 points within 0.5 mm of the truth, and no ghosts") {
  SimScene scene;
  test::MarkerRenderer renderer(test::face_cameras(test::sim_marker_centre_mm(scene.sim)), scene.sim, {}, 17);
  const drivers::V4l2Options o = config::default_config().source.v4l2;
  CameraPipeline cameras(renderer.cameras(), {.threshold = int(o.threshold), .min_area_px = int(o.min_blob_area_px),
                                              .max_area_px = int(o.max_blob_area_px), .min_roundness = o.min_roundness},
                         {.epipolar_tolerance_px = o.epipolar_tolerance_px,
                          .max_reprojection_px = 1.5 * o.epipolar_tolerance_px});
  test::PointErrors errors;
  int seen_by_both = 0, rejected_shape = 0;
  std::vector<Eigen::Vector3d> points;
  for (int64_t frame = 0; frame < 240; frame += 2) {  // 2 s of the performance, head swaying
    const test::RenderedSet set = renderer.render(frame);
    cameras.process(set.images, points);
    // The first set gives no two-view point (each is new: held until the next set has it).
    if (frame > 0)
      for (std::size_t m = 0; m < set.truth.size(); ++m) seen_by_both += set.visible[0][m] && set.visible[1][m];
    CHECK((frame > 0 || points.empty()));
    rejected_shape += cameras.detector(0).rejected_shape();
    errors.add(points, set.truth);
  }
  WARN(fmt::format("two cameras, 52 markers, 120 frame sets: {} points within {:.3f} mm (median {:.3f} mm, {} beyond "
                   "0.5 mm) of the truth, {} of the {} markers both cameras saw after the first set, {} ghosts",
                   errors.count(), errors.worst_mm(), errors.median_mm(), errors.count_above(0.5), errors.count(),
                   seen_by_both, errors.ghosts()));
  CHECK(errors.count_above(0.5) <= test::PointErrors::kMispairedShare * double(errors.count()));
  CHECK(errors.worst_mm() < test::PointErrors::kMispairedWorstMm);
  CHECK(errors.median_mm() < 0.1);
  CHECK(errors.ghosts() == 0);
  CHECK(rejected_shape == 120);                                  // every frame's streak
  // Left out: pairs on one epipolar plane, until the head's motion or the memory tells them apart.
  CHECK(double(errors.count()) >= 0.99 * double(seen_by_both));
}

TEST_CASE("three cameras: markers seen by all three are triangulated from all three views") {
  SimScene scene;
  test::MarkerRenderer renderer(test::face_cameras(test::sim_marker_centre_mm(scene.sim), 3), scene.sim, {}, 23);
  CameraPipeline cameras(renderer.cameras(), {}, {});
  test::PointErrors errors;
  int multi = 0;
  std::vector<Eigen::Vector3d> points;
  for (int64_t frame = 0; frame < 40; ++frame) {
    const test::RenderedSet set = renderer.render(frame);
    cameras.process(set.images, points);
    multi += cameras.triangulator().stats().multi_view_points;
    errors.add(points, set.truth);
  }
  WARN(fmt::format("three cameras: {} points, {} from three views, worst {:.3f} mm, median {:.3f} mm", errors.count(),
                   multi, errors.worst_mm(), errors.median_mm()));
  CHECK(multi > int(errors.count()) * 3 / 4);
  CHECK(errors.count_above(0.5) <= test::PointErrors::kMispairedShare * double(errors.count()));
  CHECK(errors.worst_mm() < test::PointErrors::kMispairedWorstMm);
  CHECK(errors.ghosts() == 0);
}

TEST_CASE("frames of several cameras are matched into sets by their timestamps") {
  FrameSetMatcher matcher(2, 2 * kNsPerMs);
  CHECK_FALSE(matcher.add(0, 1000 * kNsPerMs));
  CHECK(matcher.add(1, 1001 * kNsPerMs));
  CHECK(matcher.set_time_ns() == 1000 * kNsPerMs);
  CHECK_FALSE(matcher.add(1, 1010 * kNsPerMs));  // camera 0's frame of this moment was lost
  CHECK_FALSE(matcher.add(1, 1020 * kNsPerMs));  // so camera 1's frame waits, then is replaced
  CHECK(matcher.unmatched() == 1);
  CHECK(matcher.add(0, 1019 * kNsPerMs));
  CHECK_FALSE(matcher.add(0, 1030 * kNsPerMs));
  CHECK_FALSE(matcher.add(1, 1040 * kNsPerMs));  // too late for camera 0's: that one is dropped
  CHECK(matcher.unmatched() == 2);
  CHECK(matcher.add(0, 1040 * kNsPerMs + 500 * kNsPerUs));
}

TEST_CASE("the v4l2 driver fed rendered images below V4L2: sets by time, unlabelled points, labelled and solved") {
  SimScene scene;
  const fs::path dir = test::scratch_dir("v4l2-driver");
  test::MarkerRenderer renderer(test::face_cameras(test::sim_marker_centre_mm(scene.sim)), scene.sim, {}, 31);
  write_camera_calibration(dir / "cameras.yaml", renderer.cameras());
  // 60 Hz, the right camera's frames 0.4 ms after the left's; frame 30's right image lost.
  const int64_t frames = 150, period_ns = kNsPerSecond / 60;
  auto feed = std::make_unique<test::SyntheticFeed>(renderer, frames, period_ns, 400 * kNsPerUs,
                                                    std::vector<std::pair<int64_t, std::size_t>>{{30, 1}});
  test::SyntheticFeed& images = *feed;
  drivers::V4l2Source source(v4l2_options(dir / "cameras.yaml"), std::move(feed));
  source.open();
  CHECK(source.info().labels.size() == 64);
  CHECK(source.info().labels[0] == "unlabelled_1");
  CHECK(source.info().units == "mm");

  // The pipeline labels the unlabelled points from the calibration's markers, as facecapd
  // does with calibration.label_markers (test_v4l2_device runs facecapd itself).
  pipeline::SolveSettings settings = pipeline::solve_settings(scene.config, pipeline::SolveContext::kLive);
  settings.label_markers = true;
  pipeline::SolvePipeline solve(*scene.rig, scene.calibration, {source.info().labels, source.info().units}, settings);
  SolvedFrame solved = solve.make_solved_frame(false);

  source.start({.epoch_ns = monotonic_now_ns()});
  MarkerFrame frame = make_marker_frame(source.info().labels);
  test::PointErrors points;
  double weight_error = 0, jaw_error = 0;
  int solved_frames = 0;
  const Eigen::Index jaw = *scene.rig->shape_index("jawOpen");
  const int64_t give_up = monotonic_now_ns() + 60 * kNsPerSecond;
  int64_t last_frame_ns = monotonic_now_ns();
  while (monotonic_now_ns() < give_up) {
    if (!source.take_frame(monotonic_now_ns(), frame)) {
      if (images.finished() && monotonic_now_ns() - last_frame_ns > 300 * kNsPerMs) break;
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
      continue;
    }
    last_frame_ns = monotonic_now_ns();
    // Which rendered frame this set is: by its time (a set can be missing; none is renumbered).
    const int64_t rendered = (frame.source_time_ns - images.start_ns() + period_ns / 2) / period_ns;
    for (const Marker& m : frame.markers)
      if (m.present()) CHECK(m.flags == kMarkerUnlabelled);
    points.add(frame, images.truth(rendered));
    solve.process(frame, solved);
    if (rendered < 30) continue;  // the temporal prior settles
    const Eigen::VectorXd truth = scene.sim.weights_at(rendered);
    weight_error += (solved.weights.cast<double>() - truth).cwiseAbs().mean();
    jaw_error += std::abs(solved.weights[jaw] - truth[jaw]);
    ++solved_frames;
  }
  source.stop();
  REQUIRE(solved_frames > 0);
  weight_error /= solved_frames;
  jaw_error /= solved_frames;
  WARN(fmt::format("v4l2 driver, 2 cameras at 60 Hz: {} sets of {} frames, {} images unmatched, {} points within {:.3f} mm "
                   "({} beyond 0.5 mm), {} ghosts; solved from them: mean |w - w_true| {:.4f}, jawOpen {:.4f}",
                   source.frame_sets(), frames, source.images_unmatched(), points.count(), points.worst_mm(), points.count_above(0.5),
                   points.ghosts(), weight_error,
                   jaw_error));
  CHECK(source.frame_sets() == uint64_t(frames - 1));  // the set whose right image was lost
  CHECK(source.images_unmatched() == 1);
  CHECK(points.count_above(0.5) <= test::PointErrors::kMispairedShare * double(points.count()));
  CHECK(points.worst_mm() < test::PointErrors::kMispairedWorstMm);
  CHECK(points.ghosts() <= test::PointErrors::kGhostShare * double(points.count()));
  CHECK(weight_error < 0.06);
  CHECK(jaw_error < 0.03);
}

TEST_CASE("with no V4L2 device the driver fails at start naming the device and what it needs") {
  const fs::path dir = test::scratch_dir("v4l2-absent");
  write_camera_calibration(dir / "cameras.yaml", test::face_cameras({0, 0, 0}));
  drivers::V4l2Options o = v4l2_options(dir / "cameras.yaml");
  o.devices = "/dev/video-absent-0, /dev/video-absent-1";
  CHECK_THROWS_WITH(drivers::V4l2Source(o).open(),
                    Contains("camera 0 (left) at /dev/video-absent-0: does not exist") &&
                        Contains("needs one V4L2 capture device per calibrated camera") &&
                        Contains("v4l2-ctl --list-devices"));
  o.devices = "/dev/video-absent-0";
  CHECK_THROWS_WITH(drivers::V4l2Source(o).open(), Contains("names 1 device(s) for the 2 cameras"));
  o.devices = "/dev/null,/dev/null";  // exists, but is no camera
  CHECK_THROWS_WITH(drivers::V4l2Source(o).open(), Contains("camera 0 (left) at /dev/null: is not a V4L2 device"));
  o.calibration.clear();
  CHECK_THROWS_WITH(drivers::V4l2Source(o).open(), Contains("needs the cameras' calibration"));
}
