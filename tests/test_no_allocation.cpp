// The solve thread's per-frame work must not allocate. tests/alloc_counter.cpp replaces
// global operator new and interposes malloc and friends (Eigen allocates with malloc),
// counting the calling thread's allocations.
#include <cstdlib>
#include <thread>

#include <catch2/catch.hpp>
#include <fmt/format.h>

#include "config/schema.hpp"
#include "control/stream_sink.hpp"
#include "core/time.hpp"
#include "daemon/io_thread.hpp"
#include "daemon/solve_loop.hpp"
#include "formats/arkit.hpp"
#include "outputs/livelink/livelink_protocol.hpp"
#include "outputs/net/net_sink.hpp"
#include "outputs/recording/recorder.hpp"
#include "outputs/recording/take_recorder.hpp"
#include "outputs/shm/shm_sink.hpp"
#include "outputs/udp/udp_stream_protocol.hpp"
#include "outputs/vmc/vmc_protocol.hpp"
#include "pipeline/calibration.hpp"
#include "pipeline/recording_header.hpp"
#include "pipeline/settings.hpp"
#include "drivers/replay/replay_source.hpp"
#include "drivers/sim/sim_source.hpp"
#include "solver/builtin_face.hpp"
#include "tests/alloc_counter.hpp"
#include "tests/daemon_test_support.hpp"
#include "tests/test_support.hpp"

using namespace facecap;
using namespace facecap::daemon;

namespace {

struct Counted {
  std::size_t allocations = 0;
  uint64_t frames = 0;
};

// Runs ticks until `frames` frames are solved, counting allocations in the wait before
// each tick (prefetching included) and in tick().
Counted run_ticks(SolveLoop& loop, uint64_t frames, int64_t period_ns) {
  Counted c;
  int64_t deadline = monotonic_now_ns();
  for (int i = 0; i < 20000 && c.frames < frames; ++i) {
    deadline += period_ns;
    bool solved = false;
    {
      const test::CountAllocations counter;
      loop.wait_for_tick(deadline);
      solved = loop.tick(monotonic_now_ns());
      c.allocations += std::size_t(counter.count());
    }
    c.frames += solved ? 1 : 0;
  }
  return c;
}

}  // namespace

TEST_CASE("the counter sees allocations by new and by malloc") {
  int64_t seen = 0;
  int* p = nullptr;
  void* q = nullptr;
  {
    const test::CountAllocations counter;
    p = new int(3);
    q = std::malloc(16);
    Eigen::VectorXd v(100);
    // Escapes, so the compiler may not elide the allocations.
    asm volatile("" : : "g"(p), "g"(q), "g"(v.data()) : "memory");
    seen = counter.count();
  }
  CHECK(seen == 3);
  delete p;
  std::free(q);
}

TEST_CASE("a tick allocates nothing: sim source, phase lock, prefetch, solve, temporal filters, label check, every output, solver "
          "swap and the units check's marker samples") {
  const config::DaemonConfig c = config::default_config();
  const auto rig = std::shared_ptr<const Rig>(std::shared_ptr<const Rig>(), &BuiltinFace::instance().rig());
  const pipeline::Calibration calibration = pipeline::load_calibration(pipeline::calibration_spec(c), *rig);
  drivers::SimSource sim(c.source.sim, rig, pipeline::rest_marker_set(calibration));
  sim.open();
  const pipeline::SourceDescription source{sim.info().labels, sim.info().units};
  outputs::ShmOutputSpec spec;
  spec.name = fmt::format("facecap-test-{}-noalloc", ::getpid());
  spec.shape_names = rig->shape_names;
  spec.vertex_count = uint32_t(rig->vertex_count());
  outputs::ShmSink shm(spec);
  outputs::RecorderOptions r;
  r.file = test::scratch_dir("noalloc") / "run.fcrec";
  r.header = pipeline::make_recording_header(*rig, calibration, source, "test", 120.0, "");
  r.vertices = true;
  outputs::Recorder recorder(r, rig->vertex_count());
  // The network outputs, sending to loopback ports nobody listens on: their send errors
  // happen on the I/O thread, which may allocate; the solve thread only queues and wakes.
  IoThread io;
  io.start();
  constexpr uint16_t kDiscardPort = 9;
  auto net_spec = [&](uint16_t port, bool vertices) {
    outputs::NetSinkSpec spec;
    spec.destination = {"127.0.0.1", port};
    spec.shape_count = Eigen::Index(rig->shape_count());
    spec.vertex_count = vertices ? Eigen::Index(rig->vertex_count()) : 0;
    spec.periodic_interval_ns = kNsPerSecond;
    return spec;
  };
  outputs::udp_stream::StreamSchema schema;
  schema.shape_names = rig->shape_names;
  schema.vertex_count = uint32_t(rig->vertex_count());
  outputs::NetSink udp(io.context(), net_spec(kDiscardPort, true), std::make_unique<outputs::UdpStreamProtocol>(schema, true));
  outputs::NetSink vmc(io.context(), net_spec(kDiscardPort, false),
                       std::make_unique<outputs::VmcProtocol>(outputs::arkit_vmc_shapes(rig->shape_names), outputs::VmcRootPose{true, 0.01}));
  outputs::NetSink livelink(io.context(), net_spec(kDiscardPort, false),
                            std::make_unique<outputs::LiveLinkProtocol>(outputs::LiveLinkSpec{"", "facecap", rig->shape_names, 120.0}));
  LoopOptions options;
  options.realtime.fifo = false;
  options.prefetch_lead_ns = 800'000;
  options.phase_margin_ns = 300'000;  // the sim is on its own clock: the phase follower runs too
  pipeline::SolveSettings settings = pipeline::solve_settings(c, pipeline::SolveContext::kLive);
  REQUIRE(settings.filter.targets);  // on for a live source by default; the weights' filter too here
  settings.filter.weights = true;
  SolveLoop loop(options, sim, std::make_unique<pipeline::SolvePipeline>(*rig, calibration, source, settings),
                 {&shm, &recorder, &udp, &vmc, &livelink});
  sim.start({.epoch_ns = monotonic_now_ns()});
  loop.sample_markers(true);  // marker frames copied for the supervisor's units check

  const Counted first = run_ticks(loop, 120, loop.period_ns());
  CHECK(first.frames == 120);
  CHECK(first.allocations == 0);
  const MarkerFrame* sampled = loop.sampled_markers().front();  // nobody drains them here: the first is frame 0's
  REQUIRE(sampled != nullptr);
  CHECK(sampled->markers.size() == sim.info().labels.size());
  CHECK(sampled->present_count() > 40);

  // Swapping in a rebuilt solver happens inside a tick too; this one checks labels.
  pipeline::SolveSettings linear = settings;
  linear.method = SolverMethod::kLinear;
  linear.check_labels = true;
  loop.offer_pipeline(std::make_unique<pipeline::SolvePipeline>(*rig, calibration, source, linear));
  const Counted after_swap = run_ticks(loop, 60, loop.period_ns());
  CHECK(loop.counters().pipeline_swaps.load() == 1);
  CHECK(after_swap.frames == 60);
  CHECK(after_swap.allocations == 0);
  sim.stop();
  recorder.stop();
  CHECK(recorder.counters().marker_frames + recorder.counters().dropped == 180);
  for (outputs::NetSink* sink : {&udp, &vmc, &livelink}) {
    sink->stop();
    INFO(sink->name());
    CHECK(sink->health().offered == 180);
    CHECK(sink->health().delivered + sink->health().dropped == 180);
  }
}

TEST_CASE("a tick pulling from a replay allocates nothing") {
  const config::DaemonConfig c = config::default_config();
  const auto rig = std::shared_ptr<const Rig>(std::shared_ptr<const Rig>(), &BuiltinFace::instance().rig());
  const pipeline::Calibration calibration = pipeline::load_calibration(pipeline::calibration_spec(c), *rig);
  const auto file = test::scratch_dir("noalloc-replay") / "take.fcrec";
  test::write_sim_take(file, c.source.sim, rig, pipeline::rest_marker_set(calibration), 50);
  drivers::ReplayOptions replay_options;
  replay_options.file = file.string();
  replay_options.loop = true;
  drivers::ReplaySource replay(replay_options);
  replay.open();
  LoopOptions options;
  options.lockstep = true;
  options.realtime.fifo = false;
  SolveLoop loop(options, replay,
                 std::make_unique<pipeline::SolvePipeline>(*rig, calibration,
                                                           pipeline::SourceDescription{replay.info().labels, replay.info().units},
                                                           pipeline::solve_settings(c, pipeline::SolveContext::kLive)),
                 {});
  replay.start({.lockstep = true});
  const Counted counted = run_ticks(loop, 120, 0);  // loops the 50-frame take
  CHECK(counted.frames == 120);
  CHECK(counted.allocations == 0);
}

TEST_CASE("the plausibility gate allocates nothing, accepting or refusing markers") {
  const Rig& rig = BuiltinFace::instance().rig();
  const pipeline::Calibration calibration = pipeline::default_calibration(rig, 24, 4);
  const MarkerSet rest = pipeline::rest_marker_set(calibration);
  const std::vector<std::string> labels = rest.labels();
  pipeline::SolvePipeline pipeline(rig, calibration, {labels, ""}, {});
  SolvedFrame solved = pipeline.make_solved_frame(false);
  MarkerFrame frame = make_marker_frame(labels);
  for (std::size_t k = 0; k < labels.size(); ++k) {
    frame.markers[k].flags = 0;
    frame.markers[k].position =
        k < rest.face.size() ? binding_point(rest.face[k], rig.neutral) : rest.head[k - rest.face.size()].position;
  }
  pipeline.process(frame, solved);  // the first frame: every marker accepted
  const MarkerFrame clean = frame;
  std::size_t allocations = 0;
  uint32_t flagged = 0;
  for (int i = 1; i <= 3; ++i) {
    frame = clean;  // same size: no allocation, and outside the count
    frame.source_time_ns = i * (kNsPerSecond / 120);
    if (i == 2) {  // in rig units (cm): one marker 10 cm off, another at 1e300
      frame.markers[3].position.x() += 10.0;
      frame.markers[4].position.y() = 1e300;
    }
    const test::CountAllocations counter;
    pipeline.process(frame, solved);
    allocations += std::size_t(counter.count());
    flagged += (solved.flags & kSolvedImplausibleMarker) ? 1u : 0u;
  }
  CHECK(flagged == 1);
  CHECK(allocations == 0);
}

TEST_CASE("labelling an unlabelled point cloud in the pipeline allocates nothing") {
  const Rig& rig = BuiltinFace::instance().rig();
  const pipeline::Calibration calibration = pipeline::default_calibration(rig, 24, 4);
  const MarkerSet rest = pipeline::rest_marker_set(calibration);
  std::vector<Eigen::Vector3d> points;
  for (const auto& m : rest.face) points.push_back(binding_point(m, rig.neutral));
  for (const auto& m : rest.head) points.push_back(m.position);
  std::vector<std::string> slots;  // a cloud source: unlabelled slots, as the natnet and v4l2 drivers hand over
  for (std::size_t k = 0; k < points.size() + 4; ++k) slots.push_back(fmt::format("unlabelled_{}", k + 1));
  pipeline::SolveSettings settings;
  settings.label_markers = true;
  settings.filter.targets = settings.filter.weights = true;  // every stage's state in encoded_state()
  pipeline::SolvePipeline pipeline(rig, calibration, {slots, ""}, settings);
  SolvedFrame solved = pipeline.make_solved_frame(false);
  MarkerFrame frame = make_marker_frame(slots);
  std::size_t allocations = 0;
  for (int i = 0; i < 4; ++i) {
    for (std::size_t k = 0; k < slots.size(); ++k) {  // the points in another order each frame
      const std::size_t from = (k + std::size_t(i) * 7) % slots.size();
      frame.markers[k].flags = from < points.size() ? kMarkerUnlabelled : kMarkerUnlabelled | kMarkerMissing;
      if (from < points.size()) frame.markers[k].position = points[from];
    }
    frame.source_time_ns = i * (kNsPerSecond / 120);
    const test::CountAllocations counter;
    pipeline.process(frame, solved);
    if (i > 0) allocations += std::size_t(counter.count());  // the first frame may size caches
  }
  CHECK(pipeline.label_stats().assigned == int(points.size()));
  CHECK(allocations == 0);
  const test::CountAllocations counter;
  CHECK(pipeline.encoded_state().size() == pipeline.encoded_state_size());
  CHECK(counter.count() == 0);
}

TEST_CASE("runtime takes, the control stream and the operator telemetry allocate nothing on the solve thread") {
  const config::DaemonConfig c = config::default_config();
  const auto rig = std::shared_ptr<const Rig>(std::shared_ptr<const Rig>(), &BuiltinFace::instance().rig());
  const pipeline::Calibration calibration = pipeline::load_calibration(pipeline::calibration_spec(c), *rig);
  drivers::SimOptions sim_options = c.source.sim;
  sim_options.dropout_probability = 0.3;  // markers missing: fewer used, residuals of the rest
  drivers::SimSource sim(sim_options, rig, pipeline::rest_marker_set(calibration));
  sim.open();
  const pipeline::SourceDescription source{sim.info().labels, sim.info().units};
  auto solve = std::make_unique<pipeline::SolvePipeline>(*rig, calibration, source, pipeline::solve_settings(c, pipeline::SolveContext::kLive));
  outputs::TakeRecorder takes(rig->vertex_count(), true, solve->encoded_state_size());
  control::StreamSink stream({rig->name, "cm", rig->shape_names, sim.info().labels, uint32_t(rig->vertex_count()), {}}, 8);
  stream.set_rate(1000.0);  // a client listening: every frame copied
  LoopOptions options;
  options.realtime.fifo = false;
  SolveLoop loop(options, sim, std::move(solve), {&takes, &stream});
  sim.start({.epoch_ns = monotonic_now_ns()});

  const Counted between_takes = run_ticks(loop, 30, loop.period_ns());
  CHECK(between_takes.allocations == 0);
  // Drained by this thread, as the I/O thread does, between the counted ticks.
  const auto drain = [&] {
    uint64_t n = 0;
    for (; stream.front(); stream.pop()) ++n;
    return n;
  };
  CHECK(drain() > 0);

  outputs::RecorderOptions take;
  take.file = test::scratch_dir("noalloc-takes") / "take.fcrec";
  take.header = pipeline::make_recording_header(*rig, calibration, source, "test", 120.0, "");
  take.vertices = true;
  takes.start_take(take);  // adopted by the next tick, which encodes the solve's state for it
  const Counted recording = run_ticks(loop, 60, loop.period_ns());
  drain();
  CHECK(takes.recording());
  REQUIRE(takes.stop_take());  // let go of by the next tick
  const Counted after_stop = run_ticks(loop, 30, loop.period_ns());
  drain();
  CHECK(recording.allocations == 0);
  CHECK(after_stop.allocations == 0);
  const std::optional<outputs::TakeSummary> summary = takes.finish_stopped();
  REQUIRE(summary);
  CHECK(summary->counters.marker_frames + summary->counters.dropped >= 60);
  CHECK(summary->counters.marker_frames + summary->counters.dropped <= 61);
  CHECK(formats::RecordingReader(summary->file).start_state().size() > 0);
  // The telemetry was recorded on those ticks: markers used of expected, residuals.
  CHECK(loop.counters().markers_expected.load() == 48 * loop.counters().frames_solved.load());
  CHECK(loop.counters().markers_used.load() < loop.counters().markers_expected.load());
  CHECK(loop.residuals_nm().total() > 0);
  sim.stop();
  takes.stop();
}
