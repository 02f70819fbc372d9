// The daemon in-process: solve accuracy against the sim's ground truth, head
// stabilisation, the latency histogram, lockstep replay, the recorder, solver swaps and
// SIGHUP-style reloads.
#include <random>
#include <thread>

#include <catch2/catch.hpp>
#include <fmt/format.h>

#include "client/facecap_client.hpp"
#include "config/config_file.hpp"
#include "core/error.hpp"
#include "core/log.hpp"
#include "core/time.hpp"
#include "daemon/daemon.hpp"
#include "daemon/latency_histogram.hpp"
#include "daemon/marker_mapper.hpp"
#include "daemon/solve_pipeline.hpp"
#include "drivers/replay/replay_source.hpp"
#include "drivers/sim/sim_source.hpp"
#include "formats/recording.hpp"
#include "solver/align/mapper.hpp"
#include "solver/align/pipeline.hpp"
#include "solver/align/profile.hpp"
#include "solver/builtin_face.hpp"
#include "tests/align_test_support.hpp"
#include "tests/daemon_test_support.hpp"
#include "tests/test_support.hpp"

using namespace facecap;
using namespace facecap::daemon;
using Catch::Contains;
namespace fs = std::filesystem;

namespace {

std::shared_ptr<const Rig> builtin_rig() {
  return std::shared_ptr<const Rig>(std::shared_ptr<const Rig>(), &BuiltinFace::instance().rig());
}

std::string unique_shm(const std::string& what) { return fmt::format("facecap-test-{}-{}", ::getpid(), what); }

config::LoadedConfig loaded(const std::vector<std::string>& overrides) { return config::load_config("", overrides); }

}  // namespace

TEST_CASE("solved frames match the sim's ground truth under noise and dropouts and head motion") {
  const config::DaemonConfig c = config::default_config();  // 0.1 mm noise, 0.5% dropouts, 4 degrees / 8 mm sway
  const auto rig = builtin_rig();
  const MarkerCalibration calibration = load_calibration(c.calibration, *rig);
  drivers::SimSource sim(c.source.sim, rig, calibration.markers);
  sim.open();
  SolvePipeline pipeline(*rig, calibration, sim.info(), c.solver, c.calibration.stabilise_head);
  SolvedFrame solved = pipeline.make_solved_frame(true);
  MarkerFrame markers = drivers::make_marker_frame(sim.info().labels);
  const Eigen::Index jaw = *rig->shape_index("jawOpen");
  double weight_error = 0, jaw_error = 0, vertex_error_cm = 0, worst_head_deg = 0, worst_head_shift_cm = 0;
  int frames = 0;
  for (int64_t n = 0; n < 1200; ++n) {
    sim.render_frame(n, markers);
    pipeline.process(markers, solved);
    if (n < 120 || n % 4 != 0) continue;  // let the temporal prior settle; sample every 4th
    const Eigen::VectorXd truth = sim.weights_at(n);
    weight_error += (solved.weights.cast<double>() - truth).cwiseAbs().mean();
    jaw_error += std::abs(solved.weights[jaw] - truth[jaw]);
    const Eigen::Matrix3Xd true_pose = BuiltinFace::instance().articulated_pose(truth);
    vertex_error_cm += (solved.vertices.cast<double>() - true_pose).colwise().norm().mean();
    const Eigen::Isometry3d head = sim.head_pose_at(n);
    worst_head_deg = std::max(worst_head_deg, Eigen::Quaterniond(head.linear()).angularDistance(solved.head_rotation) * 180 / M_PI);
    worst_head_shift_cm = std::max(worst_head_shift_cm, (head.translation() - solved.head_translation).norm());
    ++frames;
  }
  weight_error /= frames;
  jaw_error /= frames;
  vertex_error_cm /= frames;
  INFO("mean |w - w_true| " << weight_error << ", jawOpen " << jaw_error << ", vertex " << vertex_error_cm * 10
                            << " mm, head " << worst_head_deg << " deg " << worst_head_shift_cm * 10 << " mm");
  CHECK(weight_error < 0.06);
  CHECK(jaw_error < 0.03);
  CHECK(vertex_error_cm < 0.05);  // 0.5 mm mean over the face
  CHECK(worst_head_deg < 0.5);
  CHECK(worst_head_shift_cm < 0.1);
}

TEST_CASE("head stabilisation undoes a known rigid motion exactly") {
  const Rig& rig = BuiltinFace::instance().rig();
  MarkerCalibration calibration;
  calibration.markers = default_marker_set(rig, 6, 4);
  calibration.origin = "test";
  const std::vector<std::string> labels = calibration.markers.labels();
  MarkerMapper mapper(calibration, labels, 1.0, true, 0.1);
  Eigen::Isometry3d motion = Eigen::Isometry3d::Identity();
  motion.linear() = Eigen::AngleAxisd(0.3, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  motion.translation() = Eigen::Vector3d(1.5, -2, 0.7);
  MarkerFrame frame = drivers::make_marker_frame(labels);
  for (std::size_t k = 0; k < 6; ++k) {
    frame.markers[k].position = motion * rig.neutral.col(calibration.markers.face[k].vertices[0]);
    frame.markers[k].flags = 0;
  }
  for (std::size_t h = 0; h < 4; ++h) {
    frame.markers[6 + h].position = motion * calibration.markers.head[h].position;
    frame.markers[6 + h].flags = 0;
  }
  frame.markers[2].flags = kMarkerMissing;
  Eigen::Matrix3Xd targets = Eigen::Matrix3Xd::Zero(3, 6);
  std::vector<uint8_t> present(6, 0);
  const MappedFrame mapped = mapper.map(frame, targets, present);
  CHECK(mapped.face_markers_present == 5);
  CHECK(mapped.head_markers_present == 4);
  CHECK_FALSE(mapped.head_pose_held);
  CHECK(present == std::vector<uint8_t>{1, 1, 0, 1, 1, 1});
  CHECK((mapped.T_world_head.matrix() - motion.matrix()).norm() < 1e-9);
  CHECK((targets.col(0) - rig.neutral.col(calibration.markers.face[0].vertices[0])).norm() < 1e-9);
  // Two head markers lost: the pose is held, not refitted from too little.
  frame.markers[6].flags = frame.markers[7].flags = kMarkerMissing;
  const MappedFrame held = mapper.map(frame, targets, present);
  CHECK(held.head_pose_held);
  CHECK((held.T_world_head.matrix() - motion.matrix()).norm() < 1e-9);
}

TEST_CASE("a source with none of the calibration's markers is refused") {
  MarkerCalibration calibration;
  calibration.markers = default_marker_set(BuiltinFace::instance().rig(), 4, 0);
  calibration.origin = "default marker set";
  CHECK_THROWS_WITH(MarkerMapper(calibration, {"LeftCheek", "Chin"}, 1.0, true, 0.1),
                    Contains("none of the 4 face markers of the default marker set (M000, ...) is among the source's 2 markers"));
}

TEST_CASE("a calibration file binds markers and scales and moves them into rig space") {
  const fs::path file = test::scratch_dir("calibration") / "cal.toml";
  test::write_text(file, "version = 1\nmarker_units = \"mm\"\ntranslation = [0, 0, 1]\n"
                         "[[face]]\nlabel = \"a\"\nvertex = 10\n[[face]]\nlabel = \"b\"\nvertex = 20\n"
                         "[[face]]\nlabel = \"c\"\nvertices = [30, 31, 32]\nbarycentric = [0.5, 0.25, 0.25]\n");
  config::CalibrationSection section;
  section.file = file.string();
  const Rig& rig = BuiltinFace::instance().rig();
  const MarkerCalibration calibration = load_calibration(section, rig);
  REQUIRE(calibration.markers.face.size() == 3);
  CHECK(calibration.markers.face[2].vertices == std::array<int, 3>{30, 31, 32});
  CHECK(marker_to_rig_scale(calibration, "m", rig) == Approx(0.1));  // the file's mm win over the source's m
  MarkerMapper mapper(calibration, {"c", "a", "b"}, 0.1, false, 0.1);
  MarkerFrame frame = drivers::make_marker_frame({"c", "a", "b"});
  for (auto& m : frame.markers) m.flags = 0;
  frame.markers[1].position = Eigen::Vector3d(10, 20, 30);  // "a", in mm
  Eigen::Matrix3Xd targets = Eigen::Matrix3Xd::Zero(3, 3);
  std::vector<uint8_t> present(3, 0);
  mapper.map(frame, targets, present);
  CHECK((targets.col(0) - Eigen::Vector3d(1, 2, 4)).norm() < 1e-12);  // 0.1 * p + (0, 0, 1)

  test::write_text(file, "version = 1\n[[face]]\nlabel = \"a\"\nvertex = 999999\n");
  CHECK_THROWS_WITH(load_calibration(section, rig), Contains(file.string() + ":4:10") && Contains("vertex 999999 is not in the rig"));
}

TEST_CASE("a calibration file with nan, inf or out-of-range numbers is refused where they are") {
  const fs::path file = test::scratch_dir("calibration-nan") / "cal.toml";
  config::CalibrationSection section;
  section.file = file.string();
  const Rig& rig = BuiltinFace::instance().rig();
  const std::string faces = "[[face]]\nlabel = \"a\"\nvertex = 10\n[[face]]\nlabel = \"b\"\nvertex = 20\n"
                            "[[face]]\nlabel = \"c\"\nvertex = 30\n";
  // rotation_wxyz = [nan, 0, 0, 0] was accepted (a NaN rotation for every marker).
  for (const char* bad : {"rotation_wxyz = [nan, 0, 0, 0]", "rotation_wxyz = [1, 0, inf, 0]", "translation = [0, -inf, 0]"}) {
    INFO(bad);
    test::write_text(file, fmt::format("version = 1\n{}\n{}", bad, faces));
    CHECK_THROWS_WITH(load_calibration(section, rig), Contains(file.string() + ":2:") && Contains("finite numbers"));
  }
  // A vertex number no integer holds (its conversion was undefined behaviour).
  test::write_text(file, "version = 1\n[[face]]\nlabel = \"a\"\nvertices = [1e300, 1, 2]\nbarycentric = [1, 0, 0]\n" + faces);
  CHECK_THROWS_WITH(load_calibration(section, rig), Contains(file.string() + ":4:") && Contains("vertex 1e+300 is not in the rig"));
  test::write_text(file, "version = 1\n[[face]]\nlabel = \"\xc3\x28\"\nvertex = 1\n" + faces);
  CHECK_THROWS_WITH(load_calibration(section, rig), Contains(file.string() + ":3:10") && Contains("not valid UTF-8"));
}

// `facecap calibrate` then facecapd: the daemon reads the profile the tool writes and
// maps a take's markers to the same solver targets as the alignment tools do, a bumped
// head marker included.
TEST_CASE("a facecap calibrate profile maps markers as the alignment tools map them") {
  test::SyntheticTakeOptions options;
  options.head_sway_deg = 4.0;
  options.noise_mm = 0.0;  // so the robust and the plain head fit agree exactly
  test::SyntheticTake take = test::make_synthetic_take(options);
  // The actor's face is not the rig's: each marker sits up to a few mm off its rig point.
  std::mt19937 rng(5);
  std::normal_distribution<double> mismatch_mm(0.0, 1.5);
  for (std::size_t k = 0; k < take.labels.size(); ++k) {
    const Eigen::Vector3d mismatch(mismatch_mm(rng), mismatch_mm(rng), mismatch_mm(rng));
    for (auto& frame : take.frames) frame.markers[k].position += mismatch;
  }
  const Rig& rig = BuiltinFace::instance().rig();
  align::TakeCalibrationOptions calibrate_options;
  calibrate_options.neutral.rate_hz = 60.0;
  calibrate_options.neutral.take_mm_per_unit = 1.0;
  const align::Calibration profile = align::calibrate_take(rig, take.labels, take.frames, calibrate_options).calibration;
  REQUIRE(profile.stable_markers.size() >= 3);
  const fs::path file = test::scratch_dir("calibration") / "actor.toml";
  align::save_calibration_profile(file, profile);

  config::CalibrationSection section;
  section.file = file.string();
  const MarkerCalibration calibration = load_calibration(section, rig);
  REQUIRE(calibration.markers.face.size() == profile.markers.size());
  CHECK(calibration.markers.head.size() == profile.stable_markers.size());
  CHECK(calibration.origin == file.string() + " (facecap calibrate profile)");
  CHECK(marker_to_rig_scale(calibration, "mm", rig) == Approx(profile.take_to_rig.scale));

  // Both fit the head robustly, leaving out a stable marker 1 mm or more off the fit.
  MarkerMapper daemon_mapper(calibration, take.labels, marker_to_rig_scale(calibration, "mm", rig), true, 0.1);
  REQUIRE(daemon_mapper.stabilising());
  align::MarkerMapper tool_mapper(profile, take.labels, align::StabiliserParams{.outlier_floor = 1.0});
  // Every other frame tested, a stable marker knocked 6 mm off (a bumped marker).
  const int bumped = int(std::find(take.labels.begin(), take.labels.end(), profile.stable_markers[0]) - take.labels.begin());
  for (std::size_t f = 0; f < take.frames.size(); f += 14) take.frames[f].markers[std::size_t(bumped)].position.x() += 6.0;
  align::MappedFrame tool = tool_mapper.make_output();
  const auto K = Eigen::Index(profile.markers.size());
  Eigen::Matrix3Xd targets = Eigen::Matrix3Xd::Zero(3, K);
  std::vector<uint8_t> present(std::size_t(K), 0);
  double worst = 0.0, largest_offset = 0.0;
  int presence_differs = 0;
  for (const auto& offset : calibration.face_offsets) largest_offset = std::max(largest_offset, offset.norm());
  for (std::size_t f = 0; f < take.frames.size(); f += 7) {
    daemon_mapper.map(take.frames[f], targets, present);
    tool_mapper.process(take.frames[f], tool);
    presence_differs += present != tool.present;
    for (Eigen::Index k = 0; k < K; ++k) worst = std::max(worst, (targets.col(k) - tool.targets.col(k)).norm());
  }
  INFO("largest difference " << worst * 10.0 << " mm; largest offset " << largest_offset * 10.0 << " mm");
  CHECK(presence_differs == 0);
  CHECK(largest_offset * 10.0 > 2.0);  // the offsets matter ...
  CHECK(worst < 1e-6);                 // ... and both paths apply them alike

  // A profile made for another rig is refused, naming the file.
  auto other = profile;
  other.rig_hash ^= 1;
  align::save_calibration_profile(file, other);
  CHECK_THROWS_WITH(load_calibration(section, rig), Contains(file.string()));
}

TEST_CASE("latency quantiles come from the histogram to within a bucket") {
  LatencyHistogram h;
  for (int i = 1; i <= 1000; ++i) h.record(int64_t(i) * 10 * kNsPerUs);  // 10 us .. 10 ms
  const auto s = h.snapshot();
  CHECK(s.total() == 1000);
  CHECK(s.quantile_ns(0.5) == Approx(5.0 * kNsPerMs).epsilon(0.01));
  CHECK(s.quantile_ns(0.99) == Approx(9.9 * kNsPerMs).epsilon(0.01));
  CHECK(s.quantile_ns(1.0) == Approx(10.0 * kNsPerMs).epsilon(0.01));
  h.record(5 * kNsPerSecond);
  CHECK(h.snapshot().since(s).total() == 1);
  CHECK(h.snapshot().since(s).quantile_ns(0.5) == kNsPerSecond);  // the overflow bucket
}

TEST_CASE("lockstep replay solves every frame and the recorder writes them all") {
  // A take from the sim, replayed in lockstep with recording on.
  const fs::path dir = test::scratch_dir("lockstep-daemon");
  const config::DaemonConfig defaults = config::default_config();
  const auto rig = builtin_rig();
  const MarkerCalibration calibration = load_calibration(defaults.calibration, *rig);
  test::write_sim_take(dir / "take.fcrec", defaults.source.sim, rig, calibration.markers, 90);

  Daemon d({.handle_signals = false},
           loaded({"source.driver=replay", "source.replay.file=" + (dir / "take.fcrec").string(), "loop.mode=lockstep",
                   "outputs.shm.name=" + unique_shm("lockstep"), "recording.enabled=true",
                   "recording.directory=" + (dir / "rec").string(), "loop.realtime=false"}));
  d.start();
  CHECK(d.run() == 0);  // stops by itself when the take ends
  const fs::path recording = d.recording_file();
  REQUIRE(fs::exists(recording));
  formats::RecordingReader reader(recording);
  CHECK_FALSE(reader.truncated());
  CHECK_FALSE(reader.index_rebuilt());
  CHECK(reader.marker_frame_count() == 90);
  CHECK(reader.solved_frame_count() == 90);
  CHECK(reader.header().shape_names == rig->shape_names);
  CHECK(reader.header().rig_name == "builtin");
  SolvedFrame last;
  reader.read_solved_frame(89, last);
  CHECK(last.frame_no == 89);
  CHECK(last.weights.size() == rig->shape_count());
}

TEST_CASE("a new solver is swapped in between frames and the old one retired off the loop") {
  const auto rig = builtin_rig();
  const config::DaemonConfig c = config::default_config();
  const MarkerCalibration calibration = load_calibration(c.calibration, *rig);
  drivers::SimSource sim(c.source.sim, rig, calibration.markers);
  sim.open();
  LoopOptions options;
  options.realtime.fifo = false;
  SolveLoop loop(options, sim, std::make_unique<SolvePipeline>(*rig, calibration, sim.info(), c.solver, true), nullptr,
                 nullptr, false);
  sim.start({.epoch_ns = monotonic_now_ns()});
  auto tick_until_solved = [&] {
    for (int i = 0; i < 200; ++i) {
      if (loop.tick(monotonic_now_ns())) return true;
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    return false;
  };
  REQUIRE(tick_until_solved());
  config::SolverSection linear = c.solver;
  linear.method = "linear";
  loop.offer_pipeline(std::make_unique<SolvePipeline>(*rig, calibration, sim.info(), linear, true));
  CHECK(loop.counters().pipeline_swaps.load() == 0);
  REQUIRE(tick_until_solved());
  CHECK(loop.counters().pipeline_swaps.load() == 1);
  loop.collect_retired();
  // A second offer while nothing is retired is adopted the same way.
  loop.offer_pipeline(std::make_unique<SolvePipeline>(*rig, calibration, sim.info(), c.solver, true));
  REQUIRE(tick_until_solved());
  CHECK(loop.counters().pipeline_swaps.load() == 2);
  sim.stop();
}

TEST_CASE("a reload rejects an invalid file and applies live keys and rebuilds the solver") {
  const fs::path file = test::scratch_dir("reload") / "facecapd.toml";
  const std::string shm = unique_shm("reload");
  test::write_text(file, "version = 1\n[outputs.shm]\nname = \"" + shm + "\"\n[loop]\nrealtime = false\n");
  Daemon d({.config_file = file.string(), .handle_signals = false}, config::load_config(file.string()));
  d.start();
  std::thread supervisor([&] { d.run(); });
  client::Subscriber reader(shm);
  facecap_frame frame{};
  REQUIRE(reader.wait_next(frame, 5 * kNsPerSecond) == FACECAP_OK);

  auto wait_for = [](auto done) {
    const int64_t give_up = monotonic_now_ns() + 30 * kNsPerSecond;
    while (!done() && monotonic_now_ns() < give_up) std::this_thread::sleep_for(std::chrono::milliseconds(10));
    return done();
  };
  test::write_text(file, "version = 1\n[outputs.shm]\nname = \"" + shm + "\"\n[loop]\nrealtime = false\nrte_hz = 5\n");
  d.request_reload();
  REQUIRE(wait_for([&] { return d.reloads_rejected() == 1; }));
  CHECK(d.config().loop.rate_hz == 120.0);

  test::write_text(file, "version = 1\n[outputs.shm]\nname = \"" + shm + "\"\n[loop]\nrealtime = false\nrate_hz = 60\n"
                         "[solver]\nalpha = 0.5\n[logging]\nlevel = \"warn\"\n");
  d.request_reload();
  REQUIRE(wait_for([&] { return d.reloads_accepted() == 1; }));
  CHECK(d.config().solver.alpha == 0.5);        // rebuilt aside and swapped in
  CHECK(d.config().logging.level == LogLevel::kWarn);    // live
  CHECK(d.config().loop.rate_hz == 120.0);      // needs a restart: kept
  CHECK(wait_for([&] { return d.loop()->counters().pipeline_swaps.load() == 1; }));
  REQUIRE(reader.wait_next(frame, 5 * kNsPerSecond) == FACECAP_OK);  // still solving
  d.request_stop();
  supervisor.join();
  set_log_level(LogLevel::kInfo);
}

TEST_CASE("the fixed-rate loop stays on its deadline grid and counts what it skips when solves overrun") {
  // Ticks at 10 kHz while a solve of the built-in face takes several times the 0.1 ms
  // period: most deadlines are missed. The ticks run plus the ticks skipped must still
  // account for every slot of the grid.
  const fs::path dir = test::scratch_dir("overrun");
  const config::DaemonConfig c = config::default_config();
  const auto rig = builtin_rig();
  const MarkerCalibration calibration = load_calibration(c.calibration, *rig);
  test::write_sim_take(dir / "take.fcrec", c.source.sim, rig, calibration.markers, 20);
  drivers::ReplayOptions replay_options;
  replay_options.file = (dir / "take.fcrec").string();
  replay_options.speed = 0.0;  // a frame for every tick
  replay_options.loop = true;
  drivers::ReplaySource replay(replay_options);
  replay.open();
  LoopOptions options;
  constexpr double kRate = 10000.0;
  options.rate_hz = kRate;
  options.realtime.fifo = false;
  SolveLoop loop(options, replay, std::make_unique<SolvePipeline>(*rig, calibration, replay.info(), c.solver, true),
                 nullptr, nullptr, false);
  const int64_t start = monotonic_now_ns();
  loop.start();
  std::this_thread::sleep_for(std::chrono::milliseconds(1000));
  loop.request_stop();
  loop.join();
  const double slots = double(monotonic_now_ns() - start) * kRate / kNsPerSecond;
  const LoopCounters& k = loop.counters();
  INFO("ticks " << k.ticks.load() << " skipped " << k.skipped_ticks.load() << " missed " << k.missed_deadlines.load()
                << " of " << slots << " slots");
  CHECK(k.missed_deadlines.load() > 100);
  CHECK(k.skipped_ticks.load() >= k.missed_deadlines.load());
  CHECK(double(k.ticks.load() + k.skipped_ticks.load()) == Approx(slots).epsilon(0.05));
  CHECK(k.frames_solved.load() == k.ticks.load());  // speed 0: every tick had a frame
  // The solves take longer than the period: these misses ran long, they did not start late.
  CHECK(double(k.max_tick_ns.load()) > kNsPerSecond / kRate);
  CHECK(k.late_start_misses.load() < k.missed_deadlines.load() / 2);
}
