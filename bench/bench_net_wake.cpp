// bench_net_wake: how a network output's queue should wake facecapd's I/O thread. The
// solve thread copies each frame into a pre-sized rt::SpscSlots slot; then either
//   eventfd     writes an eventfd the io_context waits on (posix::stream_descriptor), as
//               outputs/net/net_sink.cpp does, or
//   timer N us  does nothing more, and a steady_timer on the I/O thread polls the queue
//               every N us.
// For each: what an offer costs the solve thread (copy + wake, p50/p99/max), the latency it
// adds (commit -> the I/O thread holding the frame, p50/p99) and the I/O thread's CPU.
// Runs are interleaved round by round so that the machine's load falls on all alike.
//
//   bench_net_wake [--rate HZ] [--seconds S per run] [--rounds N] [--vertices N] [--no-fifo]
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <functional>
#include <string>
#include <thread>
#include <vector>

#include <sys/eventfd.h>
#include <sys/resource.h>
#include <unistd.h>

#include <boost/asio/io_context.hpp>
#include <boost/asio/post.hpp>
#include <boost/asio/posix/stream_descriptor.hpp>
#include <boost/asio/steady_timer.hpp>

#include "core/frame.hpp"
#include "core/latency_histogram.hpp"
#include "core/realtime.hpp"
#include "core/rt/spsc_slots.hpp"
#include "core/time.hpp"

using namespace facecap;
namespace asio = boost::asio;

namespace {

struct Options {
  double rate_hz = 240.0;
  double seconds = 3.0;
  int rounds = 3;
  Eigen::Index shapes = 57;
  Eigen::Index vertices = 0;
  bool fifo = true;
};

struct Result {
  LatencyHistogram offer, latency;
  int64_t offer_max_ns = 0;
  int64_t io_cpu_ns = 0;
  int64_t wall_ns = 0;
};

int64_t thread_cpu_ns() {
  rusage u{};
  getrusage(RUSAGE_THREAD, &u);
  return (int64_t(u.ru_utime.tv_sec) + u.ru_stime.tv_sec) * kNsPerSecond + (int64_t(u.ru_utime.tv_usec) + u.ru_stime.tv_usec) * 1000;
}

// One run: a producer at rate_hz on this thread, the consumer on an io_context thread.
// poll_us 0: eventfd; else a timer every poll_us.
void run(const Options& o, int64_t poll_us, Result& r) {
  SolvedFrame prototype;
  prototype.resize(o.shapes, o.vertices);
  rt::SpscSlots<SolvedFrame> queue(16, prototype);
  SolvedFrame frame = prototype;
  frame.weights.setConstant(0.5f);
  asio::io_context io(1);
  const int efd = eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
  asio::posix::stream_descriptor wake(io, efd);
  asio::steady_timer timer(io);
  std::atomic<bool> done{false};
  volatile float seen = 0;

  auto drain = [&] {
    while (SolvedFrame* f = queue.front()) {
      r.latency.record(monotonic_now_ns() - f->solve_end_ns);
      seen = f->weights[0];
      queue.pop();
    }
  };
  std::function<void()> arm;
  if (poll_us == 0) {
    arm = [&] {
      wake.async_wait(asio::posix::stream_descriptor::wait_read, [&](const boost::system::error_code& ec) {
        if (ec) return;
        uint64_t n;
        [[maybe_unused]] ssize_t rd = read(efd, &n, sizeof n);
        drain();
        if (!done.load()) arm();
      });
    };
  } else {
    arm = [&] {
      timer.expires_after(std::chrono::microseconds(poll_us));
      timer.async_wait([&](const boost::system::error_code& ec) {
        if (ec) return;
        drain();
        if (!done.load()) arm();
      });
    };
  }
  arm();
  int64_t io_cpu = 0;
  std::thread consumer([&] {
    const int64_t before = thread_cpu_ns();
    io.run();
    io_cpu = thread_cpu_ns() - before;
  });

  const int64_t period = int64_t(double(kNsPerSecond) / o.rate_hz);
  const int64_t start = monotonic_now_ns() + 10 * kNsPerMs;
  const int64_t ticks = int64_t(o.seconds * o.rate_hz);
  for (int64_t t = 0; t < ticks; ++t) {
    sleep_until(start + t * period);
    const int64_t begin = monotonic_now_ns();
    if (SolvedFrame* slot = queue.begin_push()) {
      frame.solve_end_ns = monotonic_now_ns();
      copy_solved_frame(frame, *slot);
      queue.commit_push();
      if (poll_us == 0) {
        const uint64_t one = 1;
        [[maybe_unused]] ssize_t w = write(efd, &one, sizeof one);
      }
    }
    const int64_t cost = monotonic_now_ns() - begin;
    r.offer.record(cost);
    r.offer_max_ns = std::max(r.offer_max_ns, cost);
  }
  sleep_until(monotonic_now_ns() + 5 * kNsPerMs);
  done.store(true);
  asio::post(io, [&] {
    wake.close();
    timer.cancel();
  });
  consumer.join();
  r.io_cpu_ns += io_cpu;
  r.wall_ns += monotonic_now_ns() - start;
}

double us(int64_t ns) { return double(ns) / 1000.0; }

}  // namespace

int main(int argc, char** argv) {
  Options o;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&] { return i + 1 < argc ? std::atof(argv[++i]) : 0.0; };
    if (a == "--rate") o.rate_hz = next();
    else if (a == "--seconds") o.seconds = next();
    else if (a == "--rounds") o.rounds = int(next());
    else if (a == "--vertices") o.vertices = Eigen::Index(next());
    else if (a == "--no-fifo") o.fifo = false;
    else {
      std::fprintf(stderr, "usage: %s [--rate HZ] [--seconds S] [--rounds N] [--vertices N] [--no-fifo]\n", argv[0]);
      return 2;
    }
  }
  const RealtimeReport rt = apply_realtime({.fifo = o.fifo});
  std::printf("producer at %.0f Hz, %s; frames of %ld weights and %ld vertices; %d rounds of %.1f s per mechanism\n",
              o.rate_hz, rt.fifo_applied ? "SCHED_FIFO" : "SCHED_OTHER", long(o.shapes), long(o.vertices), o.rounds, o.seconds);
  const std::vector<int64_t> mechanisms = {0, 250, 1000};
  std::vector<Result> results(mechanisms.size());
  for (int round = 0; round < o.rounds; ++round)
    for (std::size_t m = 0; m < mechanisms.size(); ++m) run(o, mechanisms[m], results[m]);
  std::printf("%-12s %10s %10s %10s %12s %12s %10s\n", "wake", "offer p50", "offer p99", "offer max", "latency p50",
              "latency p99", "I/O CPU");
  for (std::size_t m = 0; m < mechanisms.size(); ++m) {
    const Result& r = results[m];
    const auto offer = r.offer.snapshot(), latency = r.latency.snapshot();
    const std::string name = mechanisms[m] == 0 ? "eventfd" : "timer " + std::to_string(mechanisms[m]) + " us";
    std::printf("%-12s %7.1f us %7.1f us %7.1f us %9.1f us %9.1f us %9.2f%%\n", name.c_str(), us(offer.quantile_ns(0.5)),
                us(offer.quantile_ns(0.99)), us(r.offer_max_ns), us(latency.quantile_ns(0.5)), us(latency.quantile_ns(0.99)),
                100.0 * double(r.io_cpu_ns) / double(r.wall_ns));
  }
  return 0;
}
