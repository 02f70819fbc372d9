// The daemon in-process: solve accuracy against the sim's ground truth, head
// stabilisation, the latency histogram, lockstep replay, the recorder, solver swaps and
// SIGHUP-style reloads.
#include <random>
#include <thread>

#include <catch2/catch.hpp>
#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "client/facecap_client.hpp"
#include "config/config_file.hpp"
#include "core/error.hpp"
#include "core/log.hpp"
#include "core/time.hpp"
#include "daemon/daemon.hpp"
#include "core/latency_histogram.hpp"
#include "pipeline/calibration.hpp"
#include "pipeline/capture_calibration.hpp"
#include "pipeline/settings.hpp"
#include "pipeline/solve_pipeline.hpp"
#include "drivers/replay/replay_source.hpp"
#include "drivers/sim/sim_source.hpp"
#include "formats/recording.hpp"
#include "formats/take.hpp"
#include "solver/align/profile.hpp"
#include "solver/builtin_face.hpp"
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

pipeline::SourceDescription described(const drivers::MarkerSource& source) {
  return {source.info().labels, source.info().units};
}

}  // namespace

TEST_CASE("solved frames match the sim's ground truth under noise and dropouts and head motion") {
  const config::DaemonConfig c = config::default_config();  // 0.1 mm noise, 0.5% dropouts, 4 degrees / 8 mm sway
  const auto rig = builtin_rig();
  const pipeline::Calibration calibration = pipeline::load_calibration(pipeline::calibration_spec(c), *rig);
  drivers::SimSource sim(c.source.sim, rig, pipeline::rest_marker_set(calibration));
  sim.open();
  pipeline::SolvePipeline pipeline(*rig, calibration, described(sim), pipeline::solve_settings(c, pipeline::SolveContext::kLive));
  SolvedFrame solved = pipeline.make_solved_frame(true);
  MarkerFrame markers = make_marker_frame(sim.info().labels);
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
  const pipeline::Calibration calibration = pipeline::load_calibration(pipeline::calibration_spec(defaults), *rig);
  test::write_sim_take(dir / "take.fcrec", defaults.source.sim, rig, pipeline::rest_marker_set(calibration), 90);

  Daemon d({.handle_signals = false},
           loaded({"source.driver=replay", "source.replay.file=" + (dir / "take.fcrec").string(), "loop.mode=lockstep",
                   "outputs.shm.name=" + unique_shm("lockstep"), "outputs.recording.enabled=true",
                   "outputs.recording.directory=" + (dir / "rec").string(), "loop.realtime=false"}));
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

TEST_CASE("the default marker set observes the demo's blinks and brows: the sim solved follows them") {
  // 8 s of the sim (blinks at 0, 3.7 and 7.4 s; brows raised and lowered on slow waves),
  // replayed in lockstep and recorded; the solved weights against the sim's truth.
  const fs::path dir = test::scratch_dir("demo-blinks");
  const config::DaemonConfig defaults = config::default_config();
  const auto rig = builtin_rig();
  const pipeline::Calibration calibration = pipeline::load_calibration(pipeline::calibration_spec(defaults), *rig);
  constexpr int64_t kFrames = 960;
  test::write_sim_take(dir / "take.fcrec", defaults.source.sim, rig, pipeline::rest_marker_set(calibration), kFrames);
  Daemon d({.handle_signals = false},
           loaded({"source.driver=replay", "source.replay.file=" + (dir / "take.fcrec").string(), "loop.mode=lockstep",
                   "outputs.shm.name=" + unique_shm("demo-blinks"), "outputs.recording.enabled=true",
                   "outputs.recording.directory=" + (dir / "rec").string(), "loop.realtime=false"}));
  d.start();
  REQUIRE(d.run() == 0);
  formats::RecordingReader reader(d.recording_file());
  REQUIRE(reader.solved_frame_count() == std::size_t(kFrames));
  for (const char* name : {"eyeBlink_L", "eyeBlink_R", "browInnerUp_L", "browInnerUp_R", "browDown_L", "browDown_R"}) {
    const Eigen::Index s = *rig->shape_index(name);
    double error = 0, peak_truth = 0, solved_at_peak = 0;
    SolvedFrame f;
    for (int64_t n = 0; n < kFrames; ++n) {
      reader.read_solved_frame(std::size_t(n), f);
      const double truth = BuiltinFace::instance().motion_weights(double(f.frame_no) / 120.0)[s];
      error += std::abs(double(f.weights[s]) - truth);
      if (truth > peak_truth) peak_truth = truth, solved_at_peak = f.weights[s];
    }
    INFO(name << ": mean |w - truth| " << error / kFrames << ", at the truth's peak " << peak_truth << " solved "
              << solved_at_peak);
    CHECK(peak_truth > 0.4);
    CHECK(solved_at_peak > 0.6 * peak_truth);  // left at 0 when no marker observed them
    CHECK(error / kFrames < 0.1);
  }
}

TEST_CASE("a replay of unlabelled points, as facecapd records cameras, is labelled without being told and solves the face") {
  const fs::path dir = test::scratch_dir("unlabelled-replay");
  const config::DaemonConfig defaults = config::default_config();
  REQUIRE_FALSE(defaults.calibration.label_markers);
  const auto rig = builtin_rig();
  const pipeline::Calibration calibration = pipeline::load_calibration(pipeline::calibration_spec(defaults), *rig);
  constexpr int64_t kFrames = 240;
  test::write_sim_take(dir / "cloud.fcrec", defaults.source.sim, rig, pipeline::rest_marker_set(calibration), kFrames,
                       {}, test::SimTakeLabels::kUnlabelled);

  Daemon d({.handle_signals = false},
           loaded({"source.driver=replay", "source.replay.file=" + (dir / "cloud.fcrec").string(), "loop.mode=lockstep",
                   "outputs.shm.name=" + unique_shm("cloud"), "outputs.recording.enabled=true",
                   "outputs.recording.directory=" + (dir / "rec").string(), "loop.realtime=false"}));
  d.start();  // before, it refused: none of the calibration's markers were among the source's
  CHECK(d.run() == 0);
  formats::RecordingReader reader(d.recording_file());
  REQUIRE(reader.solved_frame_count() == std::size_t(kFrames));
  CHECK_THAT(reader.header().solver_settings, Catch::Contains("label_markers = true"));

  // The solved weights against the sim's truth, once the labeller and the solve have settled.
  drivers::SimSource sim(defaults.source.sim, rig, pipeline::rest_marker_set(calibration));
  sim.open();
  const Eigen::Index jaw = *rig->shape_index("jawOpen");
  double weight_error = 0, jaw_error = 0;
  int compared = 0;
  SolvedFrame solved;
  for (std::size_t i = 60; i < reader.solved_frame_count(); ++i) {
    reader.read_solved_frame(i, solved);
    const Eigen::VectorXd truth = sim.weights_at(solved.frame_no);
    weight_error += (solved.weights.cast<double>() - truth).cwiseAbs().mean();
    jaw_error += std::abs(solved.weights[jaw] - truth[jaw]);
    ++compared;
  }
  weight_error /= compared;
  jaw_error /= compared;
  INFO("mean |w - w_true| " << weight_error << ", jawOpen " << jaw_error);
  CHECK(weight_error < 0.06);
  CHECK(jaw_error < 0.03);
}

TEST_CASE("a new solver is swapped in between frames and the old one retired off the loop") {
  const auto rig = builtin_rig();
  const config::DaemonConfig c = config::default_config();
  const pipeline::Calibration calibration = pipeline::load_calibration(pipeline::calibration_spec(c), *rig);
  drivers::SimSource sim(c.source.sim, rig, pipeline::rest_marker_set(calibration));
  sim.open();
  LoopOptions options;
  options.realtime.fifo = false;
  const pipeline::SolveSettings settings = pipeline::solve_settings(c, pipeline::SolveContext::kLive);
  SolveLoop loop(options, sim, std::make_unique<pipeline::SolvePipeline>(*rig, calibration, described(sim), settings), {});
  sim.start({.epoch_ns = monotonic_now_ns()});
  auto tick_until_solved = [&] {
    for (int i = 0; i < 200; ++i) {
      if (loop.tick(monotonic_now_ns())) return true;
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    return false;
  };
  REQUIRE(tick_until_solved());
  pipeline::SolveSettings linear = settings;
  linear.method = SolverMethod::kLinear;
  loop.offer_pipeline(std::make_unique<pipeline::SolvePipeline>(*rig, calibration, described(sim), linear));
  CHECK(loop.counters().pipeline_swaps.load() == 0);
  REQUIRE(tick_until_solved());
  CHECK(loop.counters().pipeline_swaps.load() == 1);
  loop.collect_retired();
  // A second offer while nothing is retired is adopted the same way.
  loop.offer_pipeline(std::make_unique<pipeline::SolvePipeline>(*rig, calibration, described(sim), settings));
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
  const pipeline::Calibration calibration = pipeline::load_calibration(pipeline::calibration_spec(c), *rig);
  test::write_sim_take(dir / "take.fcrec", c.source.sim, rig, pipeline::rest_marker_set(calibration), 20);
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
  SolveLoop loop(options, replay,
                 std::make_unique<pipeline::SolvePipeline>(*rig, calibration, described(replay), pipeline::solve_settings(c, pipeline::SolveContext::kLive)),
                 {});
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

TEST_CASE("on-box calibration of the default sim (0.5 percent dropouts) succeeds on the same stretch, its residuals at most "
          "10 percent above the sim's without dropouts") {
  // The capture the control API's POST /calibrate records: 3 s of the sim at 120 Hz.
  const fs::path dir = test::scratch_dir("calibrate-dropouts");
  const config::DaemonConfig defaults = config::default_config();
  REQUIRE(defaults.source.sim.dropout_probability == 0.005);
  const auto rig = builtin_rig();
  const pipeline::Calibration calibration = pipeline::load_calibration(pipeline::calibration_spec(defaults), *rig);
  auto calibrated = [&](double dropout, const std::string& name) {
    drivers::SimOptions sim = defaults.source.sim;
    sim.dropout_probability = dropout;
    test::write_sim_take(dir / name, sim, rig, pipeline::rest_marker_set(calibration), 360);
    const formats::MarkerTake take = formats::take_from_recording(formats::RecordingReader(dir / name));
    std::size_t complete = 0;
    for (const auto& f : take.frames) complete += f.present_count() == take.labels.size();
    INFO(name << ": " << complete << " of " << take.frames.size() << " frames have every marker");
    return pipeline::calibrate_capture(*rig, take, name, defaults.calibration.neutral_min_presence);
  };
  const pipeline::CaptureCalibration clean = calibrated(0.0, "clean.fcrec");
  const pipeline::CaptureCalibration dropped = calibrated(defaults.source.sim.dropout_probability, "dropouts.fcrec");
  WARN(fmt::format("sim calibration residual median {:.3f} max {:.3f} mm (neutral frame {}); with 0.5% dropouts median "
                   "{:.3f} max {:.3f} mm (neutral frame {})",
                   clean.residual_median_mm, clean.residual_max_mm, clean.result.frame, dropped.residual_median_mm,
                   dropped.residual_max_mm, dropped.result.frame));
  CHECK(dropped.result.calibration.markers.size() == clean.result.calibration.markers.size());
  // The same still stretch to within 50 ms (gaps bridged in the search). The median, about
  // 0.1 mm, is the sim's noise averaged over the stretch, and a dropped marker draws no noise,
  // so every later marker's noise differs between the two runs: the dropouts must not make
  // it worse by more than 10%.
  CHECK(std::abs(double(dropped.result.frame) - double(clean.result.frame)) <= 0.05 * 120);
  CHECK(dropped.residual_median_mm <= 1.1 * clean.residual_median_mm);
  CHECK(dropped.residual_max_mm <= 1.1 * clean.residual_max_mm);
}

TEST_CASE("a real take with its mouth markers gone reads bad, naming them; the same take whole reads good", "[data]") {
  FACECAP_REQUIRE_SHARED_DATA(ict, "ict-face");
  FACECAP_REQUIRE_SHARED_DATA(animface, "markers/animface");
  const fs::path dir = test::scratch_dir("quality-mouth");
  const Rig rig = load_rig(ict.string());
  formats::MarkerTake take = formats::read_take(animface / "JawMoCap.trc");
  take.frames.resize(600);  // 10 s at 60 Hz
  const pipeline::CaptureCalibration calibrated = pipeline::calibrate_capture(rig, take, "JawMoCap.trc", 0.8);
  align::save_calibration_profile(dir / "actor.toml", calibrated.result.calibration);
  std::vector<std::string> mouth;
  for (const auto& label : take.labels)
    if (label.starts_with("Mouth_")) mouth.push_back(label);
  REQUIRE(mouth.size() == 8);
  formats::MarkerTake without_mouth = take;
  for (auto& f : without_mouth.frames)
    for (std::size_t k = 0; k < take.labels.size(); ++k)
      if (take.labels[k].starts_with("Mouth_")) f.markers[k].flags |= kMarkerMissing;
  take.format = without_mouth.format = formats::TakeFormat::kRecording;
  formats::write_take(dir / "whole.fcrec", take);
  formats::write_take(dir / "without-mouth.fcrec", without_mouth);

  for (const std::string name : {"whole", "without-mouth"}) {
    Daemon d({.handle_signals = false},
             loaded({"rig.path=" + ict.string(), "calibration.file=" + (dir / "actor.toml").string(), "source.driver=replay",
                     "source.replay.file=" + (dir / (name + ".fcrec")).string(), "loop.mode=lockstep", "loop.realtime=false",
                     "outputs.shm.name=" + unique_shm("mouth-" + name), "logging.stats_file=" + (dir / (name + ".json")).string()}));
    d.start();
    REQUIRE(d.run() == 0);
    const auto stats = nlohmann::json::parse(test::slurp(dir / (name + ".json")));
    const auto& capture = stats["capture"];
    INFO(name << ": " << capture.dump());
    const std::string reasons = capture["quality_reasons"].dump();
    if (name == "whole") {
      CHECK_THAT(reasons, !Contains("missing"));
      continue;
    }
    CHECK(capture["quality"] == "bad");
    CHECK_THAT(reasons, Contains("8 of 8 mouth markers missing: " + mouth[0] + ", " + mouth[1]) && Contains(" and 2 more"));
  }
}
