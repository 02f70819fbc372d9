// facecap loopcheck: can this machine hold a fixed rate? Runs facecapd's loop timing
// (absolute deadlines, SCHED_FIFO, the same missed-deadline accounting) with a fixed
// amount of pure computation in place of the solve, so that what it misses is the
// machine's doing (scheduler, other load, a hypervisor holding the CPU), not the solver's.
#include <algorithm>
#include <atomic>
#include <thread>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "core/error.hpp"
#include "core/realtime.hpp"
#include "core/time.hpp"
#include "core/rt/deadline_grid.hpp"
#include "tools/commands.hpp"
#include "tools/progress.hpp"
#include "tools/tool_support.hpp"

namespace facecap::tools {
namespace {

struct LoopCheckOptions {
  double rate_hz = 120.0;
  double work_ms = 1.0;
  double seconds = 60.0;
  int priority = kDefaultRealtimePriority;
  std::vector<int64_t> cpus;
  bool json = false;
  bool strict = false;
  bool progress = false;
};

struct LoopCheckResult {
  uint64_t slots = 0;  // grid slots the run spanned
  uint64_t ticks = 0;
  uint64_t missed = 0;
  uint64_t started_late = 0;
  uint64_t skipped = 0;
  std::vector<double> wake_late_ms;  // per tick
  std::vector<double> tick_ms;       // per tick, wake-up to the end of its work
  RealtimeReport realtime;
};

// A dependent chain of multiply-adds: compute only, no memory traffic, not vectorisable.
[[gnu::noinline]] double compute(uint64_t steps, double x) noexcept {
  for (uint64_t i = 0; i < steps; ++i) x = x * 1.0000001 + 1e-9;
  return x;
}

// Steps of compute() that take work_ns here: the fastest of a few trials, so that a trial
// the machine interrupted does not shrink the work.
uint64_t calibrate_steps(int64_t work_ns) {
  constexpr uint64_t kTrialSteps = 1'000'000;
  int64_t best_ns = INT64_MAX;
  double sink = 1.0;
  for (int trial = 0; trial < 7; ++trial) {
    const int64_t start = monotonic_now_ns();
    sink = compute(kTrialSteps, sink);
    best_ns = std::min(best_ns, monotonic_now_ns() - start);
  }
  if (sink == 0.0) throw Error("loopcheck: calibration failed");  // keeps sink alive
  return uint64_t(double(kTrialSteps) * double(work_ns) / double(std::max<int64_t>(best_ns, 1)));
}

void run_loop(const LoopCheckOptions& options, const RealtimeRequest& realtime, uint64_t steps, LoopCheckResult& result,
              std::atomic<uint64_t>& slots_done) noexcept {
  result.realtime = apply_realtime(realtime);
  const auto period_ns = int64_t(double(kNsPerSecond) / options.rate_hz + 0.5);
  const auto slots = uint64_t(options.seconds * options.rate_hz + 0.5);
  rt::DeadlineGrid grid(monotonic_now_ns() + 10 * kNsPerMs, period_ns);
  double sink = 1.0;
  uint64_t slot = 0;
  while (slot < slots) {
    sleep_until(grid.deadline_ns());
    const int64_t wake_ns = monotonic_now_ns();
    sink = compute(steps, sink);
    const int64_t end_ns = monotonic_now_ns();
    result.wake_late_ms.push_back(double(wake_ns - grid.deadline_ns()) / kNsPerMs);  // reserved: no allocation
    result.tick_ms.push_back(double(end_ns - wake_ns) / kNsPerMs);
    const rt::TickOutcome outcome = grid.advance(wake_ns, end_ns);
    ++result.ticks;
    slot += 1 + outcome.skipped;
    if (outcome.missed) {
      ++result.missed;
      result.started_late += outcome.started_late ? 1 : 0;
      result.skipped += outcome.skipped;
    }
    slots_done.store(slot, std::memory_order_relaxed);
  }
  result.slots = slot;
  if (sink == 0.0) result.ticks = 0;  // keeps the computation from being optimised away
}

struct Spread {
  double p50, p99, max;
};

Spread spread_of(std::vector<double>& values) {
  return {percentile(values, 50.0), percentile(values, 99.0), percentile(values, 100.0)};
}

int run_loopcheck(const LoopCheckOptions& options) {
  if (!(options.rate_hz >= 1 && options.rate_hz <= 10000)) throw Error(fmt::format("--rate {} Hz: allowed 1 to 10000", options.rate_hz));
  const double period_ms = 1000.0 / options.rate_hz;
  if (!(options.work_ms >= 0 && options.work_ms < period_ms))
    throw Error(fmt::format("--work-ms {}: allowed 0 up to the period, {:.3f} ms at {} Hz", options.work_ms, period_ms,
                            options.rate_hz));
  if (!(options.seconds > 0)) throw Error(fmt::format("--seconds {}: must be above 0", options.seconds));

  const uint64_t steps = calibrate_steps(int64_t(options.work_ms * kNsPerMs));
  LoopCheckResult result;
  const auto slots = std::size_t(options.seconds * options.rate_hz + 0.5);
  result.wake_late_ms.reserve(slots);
  result.tick_ms.reserve(slots);
  std::atomic<uint64_t> slots_done{0};
  // The loop runs on a thread of its own, as facecapd's does; this one draws progress.
  const RealtimeRequest realtime{.fifo = true, .priority = options.priority, .cpus = options.cpus};
  std::thread loop([&] { run_loop(options, realtime, steps, result, slots_done); });
  {
    ProgressBar bar("loopcheck", options.progress || stderr_is_terminal());
    while (slots_done.load(std::memory_order_relaxed) < slots) {
      bar.update(slots_done.load(std::memory_order_relaxed), slots);
      sleep_until(monotonic_now_ns() + 200 * kNsPerMs);
    }
  }
  loop.join();

  const Spread wake_late = spread_of(result.wake_late_ms), tick = spread_of(result.tick_ms);
  const double missed_percent = result.ticks ? 100.0 * double(result.missed) / double(result.ticks) : 0.0;
  if (options.json) {
    nlohmann::json j;
    j["rate_hz"] = options.rate_hz;
    j["work_ms"] = options.work_ms;
    j["seconds"] = options.seconds;
    j["fifo"] = result.realtime.fifo_applied;
    j["priority"] = result.realtime.priority;
    j["slots"] = result.slots;
    j["ticks"] = result.ticks;
    j["missed_deadlines"] = result.missed;
    j["late_start_misses"] = result.started_late;
    j["skipped_ticks"] = result.skipped;
    j["wake_late_ms"] = {{"p50", wake_late.p50}, {"p99", wake_late.p99}, {"max", wake_late.max}};
    j["tick_ms"] = {{"p50", tick.p50}, {"p99", tick.p99}, {"max", tick.max}};
    fmt::print("{}\n", j.dump(2));
  } else {
    for (const std::string& line : result.realtime.describe(realtime)) fmt::print("{}\n", line);
    fmt::print("{:g} Hz for {:g} s with {:.2f} ms of computation a tick: {} ticks, {} slots skipped\n",
               options.rate_hz, options.seconds, options.work_ms, result.ticks, result.skipped);
    fmt::print("missed deadlines {} ({:.2f}% of ticks): {} started late, {} ran longer than a period\n", result.missed,
               missed_percent, result.started_late, result.missed - result.started_late);
    fmt::print("wake-up after the deadline: p50 {:.3f} p99 {:.3f} max {:.2f} ms\n", wake_late.p50, wake_late.p99,
               wake_late.max);
    fmt::print("tick, wake-up to end of work: p50 {:.3f} p99 {:.3f} max {:.2f} ms\n", tick.p50, tick.p99, tick.max);
    if (result.missed == 0)
      fmt::print("no deadline missed: the machine held {:g} Hz for {:g} s\n", options.rate_hz, options.seconds);
    else
      fmt::print("the machine missed deadlines with no solver running: facecapd on it will miss at least as often "
                 "(see docs/daemon.md, Troubleshooting)\n");
  }
  return options.strict && result.missed > 0 ? 1 : 0;
}

}  // namespace

void add_loopcheck_command(CLI::App& app, int& exit_code) {
  auto opts = std::make_shared<LoopCheckOptions>();
  auto* cmd = app.add_subcommand("loopcheck", "Check that this machine holds a fixed loop rate, with no solver running");
  cmd->add_option("--rate", opts->rate_hz, "Loop rate in Hz (facecapd's loop.rate_hz)")->capture_default_str();
  cmd->add_option("--work-ms", opts->work_ms, "Computation per tick in ms (a solve's cost: see facecap bench)")
      ->capture_default_str();
  cmd->add_option("--seconds", opts->seconds, "How long to run")->capture_default_str();
  cmd->add_option("--priority", opts->priority, "SCHED_FIFO priority (facecapd's loop.priority)")->capture_default_str();
  cmd->add_option("--cpu", opts->cpus, "Pin the loop to these CPUs (facecapd's loop.cpu_affinity)");
  cmd->add_flag("--json", opts->json, "Print the figures as JSON");
  cmd->add_flag("--strict", opts->strict, "Exit 1 when any deadline is missed");
  cmd->add_flag("--progress", opts->progress, "Show progress on stderr (default: on a terminal)");
  cmd->callback([opts, &exit_code] { exit_code = run_loopcheck(*opts); });
}

}  // namespace facecap::tools
