// The solve thread's per-frame work must not allocate. tests/alloc_counter.cpp replaces
// global operator new and interposes malloc and friends (Eigen allocates with malloc),
// counting the calling thread's allocations.
#include <cstdlib>
#include <thread>

#include <catch2/catch.hpp>
#include <fmt/format.h>

#include "config/schema.hpp"
#include "core/time.hpp"
#include "daemon/calibration.hpp"
#include "daemon/recorder.hpp"
#include "daemon/shm_writer.hpp"
#include "daemon/solve_loop.hpp"
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

TEST_CASE("a tick allocates nothing: sim source, prefetch, solve, shm publish, recorder and solver swap") {
  const config::DaemonConfig c = config::default_config();
  const auto rig = std::shared_ptr<const Rig>(std::shared_ptr<const Rig>(), &BuiltinFace::instance().rig());
  const MarkerCalibration calibration = load_calibration(c.calibration, *rig);
  drivers::SimSource sim(c.source.sim, rig, calibration.markers);
  sim.open();
  ShmOutputSpec spec;
  spec.name = fmt::format("facecap-test-{}-noalloc", ::getpid());
  spec.shape_names = rig->shape_names;
  spec.vertex_count = uint32_t(rig->vertex_count());
  ShmWriter shm(spec);
  RecorderOptions r;
  r.file = test::scratch_dir("noalloc") / "run.fcrec";
  r.header.shape_names = rig->shape_names;
  Recorder recorder(r, drivers::make_marker_frame(sim.info().labels), rig->shape_count());
  LoopOptions options;
  options.realtime.fifo = false;
  options.prefetch_lead_ns = 800'000;
  SolveLoop loop(options, sim, std::make_unique<SolvePipeline>(*rig, calibration, sim.info(), c.solver, true), &shm,
                 &recorder, true);
  sim.start({.epoch_ns = monotonic_now_ns()});

  const Counted first = run_ticks(loop, 120, loop.period_ns());
  CHECK(first.frames == 120);
  CHECK(first.allocations == 0);

  // Swapping in a rebuilt solver happens inside a tick too.
  config::SolverSection linear = c.solver;
  linear.method = "linear";
  loop.offer_pipeline(std::make_unique<SolvePipeline>(*rig, calibration, sim.info(), linear, true));
  const Counted after_swap = run_ticks(loop, 60, loop.period_ns());
  CHECK(loop.counters().pipeline_swaps.load() == 1);
  CHECK(after_swap.frames == 60);
  CHECK(after_swap.allocations == 0);
  sim.stop();
  recorder.stop();
  CHECK(recorder.counters().marker_frames + recorder.counters().dropped == 180);
}

TEST_CASE("a tick pulling from a replay allocates nothing") {
  const config::DaemonConfig c = config::default_config();
  const auto rig = std::shared_ptr<const Rig>(std::shared_ptr<const Rig>(), &BuiltinFace::instance().rig());
  const MarkerCalibration calibration = load_calibration(c.calibration, *rig);
  const auto file = test::scratch_dir("noalloc-replay") / "take.fcrec";
  test::write_sim_take(file, c.source.sim, rig, calibration.markers, 50);
  drivers::ReplayOptions replay_options;
  replay_options.file = file.string();
  replay_options.loop = true;
  drivers::ReplaySource replay(replay_options);
  replay.open();
  LoopOptions options;
  options.lockstep = true;
  options.realtime.fifo = false;
  SolveLoop loop(options, replay, std::make_unique<SolvePipeline>(*rig, calibration, replay.info(), c.solver, true),
                 nullptr, nullptr, false);
  replay.start({.lockstep = true});
  const Counted counted = run_ticks(loop, 120, 0);  // loops the 50-frame take
  CHECK(counted.frames == 120);
  CHECK(counted.allocations == 0);
}
