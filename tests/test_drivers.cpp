// Marker sources: the driver table, the simulated capture and replay pacing.
#include <cmath>
#include <thread>

#include <catch2/catch.hpp>

#include "core/error.hpp"
#include "core/time.hpp"
#include "drivers/table.hpp"
#include "drivers/replay/replay_source.hpp"
#include "drivers/sim/sim_source.hpp"
#include "formats/take.hpp"
#include "solver/builtin_face.hpp"
#include "tests/test_support.hpp"

using namespace facecap;
using namespace facecap::drivers;
using Catch::Contains;

namespace {

std::shared_ptr<const Rig> builtin_rig() {
  return std::shared_ptr<const Rig>(std::shared_ptr<const Rig>(), &BuiltinFace::instance().rig());
}

SimOptions sim_options() {
  SimOptions o;
  o.rate_hz = 120.0;
  o.motion = "builtin";
  o.noise_mm = 0.1;
  o.dropout_probability = 0.01;
  o.head_motion_degrees = 4.0;
  o.head_motion_mm = 8.0;
  o.seed = 1;
  return o;
}

// 3 markers, `frames` frames at 10 Hz, marker k of frame i at (i, k, 0), each with `flags`.
std::filesystem::path write_small_take(const std::string& name, int frames, uint32_t flags = 0) {
  formats::MarkerTake take;
  take.format = formats::TakeFormat::kRecording;
  take.labels = {"A", "B", "C"};
  take.rate_hz = 10.0;
  take.units = "mm";
  for (int i = 0; i < frames; ++i) {
    MarkerFrame& f = formats::append_empty_frame(take, i, int64_t(i) * 100 * kNsPerMs);
    for (int k = 0; k < 3; ++k) {
      f.markers[std::size_t(k)].position = Eigen::Vector3d(i, k, 0);
      f.markers[std::size_t(k)].flags = flags;
    }
  }
  const auto path = test::scratch_dir("replay") / name;
  formats::write_take(path, take);
  return path;
}

ReplayOptions replay_options(const std::filesystem::path& file) {
  ReplayOptions o;
  o.file = file.string();
  return o;
}

}  // namespace

TEST_CASE("the driver table holds the built drivers in the order of their ids and knows which can lockstep") {
  const auto table = driver_table();
  REQUIRE(table.size() == std::size_t(FACECAP_WITH_SIM + FACECAP_WITH_REPLAY + FACECAP_WITH_NATNET + FACECAP_WITH_USB + FACECAP_WITH_HID +
                                      FACECAP_WITH_V4L2));
  for (std::size_t i = 1; i < table.size(); ++i) CHECK(table[i - 1].id < table[i].id);
  for (const auto& entry : kDriverIds.entries()) {
    CHECK((find_driver(entry.value) != nullptr) == driver_built(entry.value));
    if (const DriverEntry* row = find_driver(entry.value)) CHECK(row->name() == entry.name);
  }
  CHECK(kDriverIds.parse("sim") == DriverId::kSim);
  CHECK_FALSE(supports_lockstep(DriverId::kSim));
  CHECK(supports_lockstep(DriverId::kReplay));
  CHECK(kDriverIds.parse("natnet") == DriverId::kNatNet);
  CHECK_FALSE(supports_lockstep(DriverId::kNatNet));
  CHECK_FALSE(kDriverIds.parse("motive"));
  CHECK_FALSE(supports_lockstep(DriverId::kUsb));
  CHECK(kDriverIds.parse("v4l2") == DriverId::kV4l2);
}

TEST_CASE("the sim is deterministic per frame and seed") {
  const MarkerSet markers = default_marker_set(BuiltinFace::instance().rig(), 32, 4);
  SimSource a(sim_options(), builtin_rig(), markers), b(sim_options(), builtin_rig(), markers);
  SimOptions other_seed = sim_options();
  other_seed.seed = 2;
  SimSource c(other_seed, builtin_rig(), markers);
  a.open();
  b.open();
  c.open();
  REQUIRE(a.info().labels.size() == 36);
  CHECK(a.info().labels[32] == "H0");
  MarkerFrame fa = make_marker_frame(a.info().labels), fb = fa, fc = fa;
  a.render_frame(500, fa);
  b.render_frame(500, fb);
  c.render_frame(500, fc);
  double same = 0, different = 0;
  for (std::size_t k = 0; k < fa.markers.size(); ++k) {
    if (!fa.markers[k].present() || !fc.markers[k].present()) continue;
    same = std::max(same, (fa.markers[k].position - fb.markers[k].position).norm());
    different = std::max(different, (fa.markers[k].position - fc.markers[k].position).norm());
  }
  CHECK(same == 0.0);
  CHECK(different > 0.001);  // 0.1 mm noise in a rig in cm
  CHECK(fa.frame_no == 500);
  CHECK(fa.source_time_ns == int64_t{500} * 8'333'333);
}

TEST_CASE("sim markers sit on the posed face moved by the head pose within the noise") {
  SimOptions options = sim_options();
  options.dropout_probability = 0.0;
  const Rig& rig = BuiltinFace::instance().rig();
  const MarkerSet markers = default_marker_set(rig, 16, 4);
  SimSource sim(options, builtin_rig(), markers);
  sim.open();
  MarkerFrame frame = make_marker_frame(sim.info().labels);
  const int64_t n = 333;
  sim.render_frame(n, frame);
  const Eigen::Matrix3Xd pose = BuiltinFace::instance().articulated_pose(sim.weights_at(n));
  const Eigen::Isometry3d head = sim.head_pose_at(n);
  CHECK(Eigen::AngleAxisd(head.linear()).angle() > 0.001);  // the head has moved
  double worst = 0;
  for (std::size_t k = 0; k < markers.face.size(); ++k)
    worst = std::max(worst, (frame.markers[k].position - head * binding_point(markers.face[k], pose)).norm());
  for (std::size_t h = 0; h < markers.head.size(); ++h)
    worst = std::max(worst, (frame.markers[16 + h].position - head * markers.head[h].position).norm());
  CHECK(worst < 0.06);  // 6 standard deviations of 0.1 mm, in cm
  CHECK(worst > 0.0);
}

TEST_CASE("sim dropouts occur at the configured rate and leave NaN positions") {
  SimOptions options = sim_options();
  options.dropout_probability = 0.1;
  const MarkerSet markers = default_marker_set(BuiltinFace::instance().rig(), 48, 4);
  SimSource sim(options, builtin_rig(), markers);
  sim.open();
  MarkerFrame frame = make_marker_frame(sim.info().labels);
  std::size_t missing = 0, total = 0;
  for (int64_t n = 0; n < 200; ++n) {
    sim.render_frame(n, frame);
    for (const Marker& m : frame.markers) {
      ++total;
      if (!m.present()) {
        ++missing;
        CHECK(std::isnan(m.position.x()));
      }
    }
  }
  CHECK(double(missing) / double(total) == Approx(0.1).margin(0.01));
}

TEST_CASE("the sim delivers frames at its rate through the mailbox") {
  SimOptions options = sim_options();
  options.rate_hz = 200.0;
  const MarkerSet markers = default_marker_set(BuiltinFace::instance().rig(), 8, 0);
  SimSource sim(options, builtin_rig(), markers);
  sim.open();
  MarkerFrame frame = make_marker_frame(sim.info().labels);
  const int64_t epoch = monotonic_now_ns();
  sim.start({.epoch_ns = epoch});
  int64_t newest = -1;
  for (int i = 0; i < 100; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
    while (sim.take_frame(monotonic_now_ns(), frame)) newest = frame.frame_no;
  }
  const double elapsed_s = double(monotonic_now_ns() - epoch) / kNsPerSecond;
  sim.stop();
  // Frames are numbered by their due time: the newest is about elapsed * rate.
  CHECK(double(newest) == Approx(elapsed_s * 200.0).margin(20));
  const SourceHealth health = sim.health();
  CHECK(health.frames_delivered + health.frames_overwritten + health.frames_late >= uint64_t(newest) - 20);
  CHECK_THROWS_WITH(sim.start({.epoch_ns = epoch, .lockstep = true}), Contains("cannot run in lockstep"));
}

TEST_CASE("sim motion from a Live Link Face CSV drives the rig's shapes of the same names") {
  FACECAP_REQUIRE_SHARED_DATA(csv, "livelinkface/jmtechart_MySlate_3_Jason_Millers_iPhone.csv");
  SimOptions options = sim_options();
  options.motion = csv.string();
  const Rig& rig = BuiltinFace::instance().rig();
  SimSource sim(options, builtin_rig(), default_marker_set(rig, 8, 0));
  sim.open();
  CHECK_THAT(sim.description(), Contains("Live Link Face"));
  double jaw = 0;
  for (int64_t n = 0; n < 600; n += 10) jaw = std::max(jaw, sim.weights_at(n)[*rig.shape_index("jawOpen")]);
  CHECK(jaw > 0.05);
}

TEST_CASE("replay in lockstep hands every frame of the window in order and then finishes") {
  const auto file = write_small_take("lockstep.fcrec", 10);
  ReplayOptions options = replay_options(file);
  options.start_s = 0.2;
  options.end_s = 0.6;
  ReplaySource replay(options);
  replay.open();
  CHECK(replay.window_frames() == 5);  // 0.2, 0.3, 0.4, 0.5, 0.6 s
  CHECK(replay.info().labels == std::vector<std::string>{"A", "B", "C"});
  CHECK(replay.info().units == "mm");
  replay.start({.epoch_ns = 0, .lockstep = true});
  MarkerFrame frame = make_marker_frame(replay.info().labels);
  std::vector<int64_t> seen;
  while (replay.take_frame(0, frame)) seen.push_back(frame.frame_no);
  CHECK(seen == std::vector<int64_t>{2, 3, 4, 5, 6});
  CHECK(frame.markers[1].position == Eigen::Vector3d(6, 1, 0));
  CHECK(replay.health().finished);
}

TEST_CASE("a replay whose every point came without identity says its source is unlabelled, and only then") {
  ReplaySource named(replay_options(write_small_take("named.fcrec", 4)));
  named.open();
  CHECK_FALSE(named.info().unlabelled);
  ReplaySource cloud(replay_options(write_small_take("cloud.fcrec", 4, kMarkerUnlabelled)));
  cloud.open();
  CHECK(cloud.info().unlabelled);
  // A missing slot of a cloud is unlabelled too (as the camera and NatNet drivers mark it).
  ReplaySource gappy(replay_options(write_small_take("gappy.fcrec", 4, kMarkerUnlabelled | kMarkerMissing)));
  gappy.open();
  CHECK(gappy.info().unlabelled);
}

TEST_CASE("a real Motive capture replayed as a cloud (no marker set) is unlabelled, and by its marker set it is not") {
  FACECAP_REQUIRE_SHARED_DATA(natnet, "natnet");
  ReplayOptions options = replay_options(natnet / "traffic.pcapng");
  NatNetOptions cloud;
  cloud.unlabelled_markers = 8;
  ReplaySource as_cloud(options, cloud);
  as_cloud.open();
  CHECK(as_cloud.info().unlabelled);
  std::size_t points = 0;
  for (const MarkerFrame& frame : as_cloud.recorded_frames()) points += frame.present_count();
  CHECK(points > 0);  // the capture's points, in the unlabelled slots
  NatNetOptions named;
  named.marker_set = "RaceQuad";
  ReplaySource by_set(options, named);
  by_set.open();
  CHECK_FALSE(by_set.info().unlabelled);
}

TEST_CASE("paced replay hands the frame due at each time and counts the ones passed over and loops") {
  const auto file = write_small_take("paced.fcrec", 10);  // 1 s long at 10 Hz
  ReplayOptions options = replay_options(file);
  options.speed = 2.0;
  options.loop = true;
  ReplaySource replay(options);
  replay.open();
  const int64_t epoch = 1'000'000'000;
  replay.start({.epoch_ns = epoch});
  MarkerFrame frame = make_marker_frame(replay.info().labels);
  CHECK_FALSE(replay.take_frame(epoch - 1, frame));  // before the start
  REQUIRE(replay.take_frame(epoch, frame));
  CHECK(frame.frame_no == 0);
  CHECK(frame.receive_time_ns == epoch);
  CHECK_FALSE(replay.take_frame(epoch + 10 * kNsPerMs, frame));  // frame 1 is due at 50 ms (speed 2)
  REQUIRE(replay.take_frame(epoch + 160 * kNsPerMs, frame));    // 320 ms of take: frame 3
  CHECK(frame.frame_no == 3);
  CHECK(replay.health().frames_late == 2);  // frames 1 and 2 were passed over
  // Loop: at 1.05 s of take time, the second pass's frame 0, numbered on.
  REQUIRE(replay.take_frame(epoch + 525 * kNsPerMs, frame));
  CHECK(frame.frame_no == 10);
  CHECK(frame.source_time_ns == 1000 * kNsPerMs);
  CHECK_FALSE(replay.health().finished);
}

TEST_CASE("replay without looping finishes after its last frame") {
  const auto file = write_small_take("once.fcrec", 4);
  ReplaySource replay(replay_options(file));
  replay.open();
  replay.start({.epoch_ns = 0});
  MarkerFrame frame = make_marker_frame(replay.info().labels);
  REQUIRE(replay.take_frame(10 * kNsPerSecond, frame));  // long past the end: the last frame
  CHECK(frame.frame_no == 3);
  CHECK_FALSE(replay.take_frame(11 * kNsPerSecond, frame));
  CHECK(replay.health().finished);
}

TEST_CASE("replay refuses a take whose frames carry one timestamp and no rate") {
  // Its cycle was 0 ns long: the first paced take_frame divided by zero (SIGFPE).
  const auto path = test::scratch_dir("replay-still") / "still.trc";
  test::write_text(path, "PathFileType\t4\t(X/Y/Z)\tstill.trc\nNumFrames\tNumMarkers\tUnits\n3\t1\tmm\n"
                         "Frame#\tTime\tA\n\t\tX1\tY1\tZ1\n1\t0\t1\t2\t3\n2\t0\t1\t2\t3\n3\t0\t1\t2\t3\n");
  ReplaySource replay(replay_options(path));
  CHECK_THROWS_WITH(replay.open(), Contains("still.trc") && Contains("nothing to pace them by"));
}

TEST_CASE("replay refuses a missing file and an empty window") {
  ReplaySource missing(replay_options("/nonexistent/take.c3d"));
  CHECK_THROWS_AS(missing.open(), Error);
  const auto file = write_small_take("window.fcrec", 4);
  ReplayOptions options = replay_options(file);
  options.start_s = 5.0;
  ReplaySource empty(options);
  CHECK_THROWS_WITH(empty.open(), Contains("holds no frame"));
}
