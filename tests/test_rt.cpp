// The real-time hand-offs of core/rt: latest-value mailbox, SPSC slots, deadline grid,
// phase follower, pipeline hand-off. Threaded cases run under TSan too (docs/building.md).
#include <array>
#include <atomic>
#include <memory>
#include <thread>

#include <catch2/catch.hpp>

#include "core/rt/deadline_grid.hpp"
#include "core/rt/handoff.hpp"
#include "core/rt/latest_mailbox.hpp"
#include "core/rt/phase_follower.hpp"
#include "core/rt/spsc_slots.hpp"

using namespace facecap;

TEST_CASE("the mailbox hands over the newest value and counts the ones overwritten") {
  rt::LatestMailbox<int> box(0);
  CHECK(box.take() == nullptr);
  box.write_buffer() = 1;
  box.publish();
  box.write_buffer() = 2;
  box.publish();
  const int* v = box.take();
  REQUIRE(v != nullptr);
  CHECK(*v == 2);
  CHECK(box.overwritten() == 1);
  CHECK(box.take() == nullptr);  // nothing new
  box.write_buffer() = 3;
  box.publish();
  v = box.take();
  REQUIRE(v != nullptr);
  CHECK(*v == 3);
  CHECK(box.published() == 3);
}

TEST_CASE("the mailbox never hands out a value the producer is still writing") {
  rt::LatestMailbox<std::array<int64_t, 64>> box(std::array<int64_t, 64>{});
  std::atomic<bool> done{false};
  std::thread producer([&] {
    for (int64_t n = 1; n <= 200000; ++n) {
      box.write_buffer().fill(n);
      box.publish();
    }
    done = true;
  });
  int64_t last = 0, torn = 0, taken = 0;
  while (!done.load()) {
    if (const auto* v = box.take()) {
      ++taken;
      for (const int64_t x : *v) torn += x != (*v)[0] ? 1 : 0;
      CHECK((*v)[0] > last);
      last = (*v)[0];
    }
  }
  producer.join();
  if (const auto* v = box.take()) {  // the last value, when the producer outran the loop above
    ++taken;
    for (const int64_t x : *v) torn += x != (*v)[0] ? 1 : 0;
  }
  CHECK(taken > 0);
  CHECK(torn == 0);
  CHECK(box.overwritten() + uint64_t(taken) <= 200000);
}

TEST_CASE("spsc slots hand over every value in order and refuse to overwrite when full") {
  rt::SpscSlots<std::array<int64_t, 16>> queue(4, std::array<int64_t, 16>{});
  for (int64_t n = 0; n < 4; ++n) {
    auto* slot = queue.begin_push();
    REQUIRE(slot != nullptr);
    slot->fill(n);
    queue.commit_push();
  }
  CHECK(queue.begin_push() == nullptr);  // full: the producer drops rather than waits
  REQUIRE(queue.front() != nullptr);
  CHECK((*queue.front())[15] == 0);
  queue.pop();
  CHECK(queue.begin_push() != nullptr);  // room again
}

TEST_CASE("spsc slots pass 200000 values between threads without loss, tear or reorder") {
  rt::SpscSlots<std::array<int64_t, 16>> queue(8, std::array<int64_t, 16>{});
  constexpr int64_t kCount = 200000;
  std::thread producer([&] {
    for (int64_t n = 1; n <= kCount;) {
      if (auto* slot = queue.begin_push()) {
        slot->fill(n++);
        queue.commit_push();
      }
    }
  });
  int64_t expected = 1, torn = 0;
  while (expected <= kCount) {
    if (const auto* v = queue.front()) {
      for (const int64_t x : *v) torn += x != expected ? 1 : 0;
      ++expected;
      queue.pop();
    }
  }
  producer.join();
  CHECK(torn == 0);
  CHECK(queue.front() == nullptr);
}

TEST_CASE("the deadline grid counts a late start, a long tick and the slots each gives up") {
  constexpr int64_t kPeriod = 4'000'000;
  rt::DeadlineGrid grid(1'000'000, kPeriod);
  // On time: work within the period, the next deadline one period on.
  rt::TickOutcome t = grid.advance(1'000'000, 2'000'000);
  CHECK_FALSE(t.missed);
  CHECK(grid.deadline_ns() == 5'000'000);
  // Woke 3.5 ms late, 1 ms of work: past the next deadline by 0.5 ms, one slot given up.
  t = grid.advance(8'500'000, 9'500'000);
  CHECK(t.missed);
  CHECK(t.started_late);
  CHECK(t.skipped == 1);
  CHECK(grid.deadline_ns() == 13'000'000);
  // Woke on time, 10 ms of work: ran past the deadlines at 17 and 21 ms; both given up.
  t = grid.advance(13'000'000, 23'000'000);
  CHECK(t.missed);
  CHECK_FALSE(t.started_late);
  CHECK(t.skipped == 2);
  CHECK(grid.deadline_ns() == 25'000'000);
  // A phase correction moves the next deadline by exactly itself.
  t = grid.advance(25'000'000, 25'500'000, -300'000);
  CHECK_FALSE(t.missed);
  CHECK(grid.deadline_ns() == 28'700'000);
}

namespace {
// A source at the loop's rate whose frame k arrives at offset + k * period + delay(k),
// handed over by a latest-value mailbox to ticks on a deadline grid that the follower
// moves (the work itself takes no time): what the solve loop does, on simulated time.
struct PhaseRun {
  uint64_t taken = 0, replaced = 0, idle = 0;
  double wait_sum_ns = 0;
  double mean_wait_ms() const { return taken ? wait_sum_ns / double(taken) / 1e6 : 0.0; }
};

class PhaseSim {
 public:
  PhaseSim(int64_t period_ns, int64_t margin_ns, int64_t offset_ns)
      : follower(period_ns, margin_ns), grid_(0, period_ns), offset_ns_(offset_ns) {}

  // Frames first .. first + frames - 1, and the ticks before the last arrives.
  template <typename Delay>
  PhaseRun run(int64_t first, int64_t frames, Delay delay) {
    PhaseRun run;
    for (int64_t k = first; k < first + frames; ++k) {
      const int64_t arrival = offset_ns_ + k * grid_.period_ns() + delay(k);
      while (grid_.deadline_ns() < arrival) {
        const int64_t tick = grid_.deadline_ns();
        int64_t correction = 0;
        if (pending_arrival_ >= 0) {
          ++run.taken;
          run.wait_sum_ns += double(tick - pending_arrival_);
          correction = follower.correction(tick - pending_arrival_, replaced_total_);
          pending_arrival_ = -1;
        } else {
          ++run.idle;
        }
        grid_.advance(tick, tick, correction);
      }
      if (pending_arrival_ >= 0) ++run.replaced, ++replaced_total_;
      pending_arrival_ = arrival;
    }
    return run;
  }

  rt::PhaseFollower follower;

 private:
  rt::DeadlineGrid grid_;
  int64_t offset_ns_;
  int64_t pending_arrival_ = -1;  // a frame in the mailbox no tick has taken yet
  uint64_t replaced_total_ = 0;
};

// Deterministic pseudo-random delays in [0, spread_ns) (the same on every library).
struct UniformDelay {
  int64_t spread_ns;
  int64_t operator()(int64_t k) const {
    uint64_t x = uint64_t(k) * 0x9E3779B97F4A7C15ull;
    x = (x ^ (x >> 31)) * 0xBF58476D1CE4E5B9ull;
    x ^= x >> 29;
    return int64_t(x % uint64_t(spread_ns));
  }
};
}  // namespace

TEST_CASE("the phase follower puts ticks just after a steady source's frames and waits out a jittery one's") {
  constexpr int64_t kPeriod = 4'166'667;  // 240 Hz
  constexpr int64_t kMargin = 300'000;
  constexpr int64_t kSecond = 240;
  // Frames arrive 1.7 ms after the grid's first ticks.
  PhaseSim sim(kPeriod, kMargin, 1'700'000);
  const auto steady = [](int64_t) { return int64_t{0}; };

  // Steady: within 2 s every frame waits the margin, nothing is replaced.
  sim.run(0, 2 * kSecond, steady);
  PhaseRun run = sim.run(2 * kSecond, 10 * kSecond, steady);
  CHECK(run.replaced == 0);
  CHECK(run.idle == 0);
  CHECK(run.mean_wait_ms() == Approx(0.3).margin(0.01));
  CHECK(sim.follower.jitter_margin_ns() == 0);

  // Frames now come up to 1.5 ms late (uniformly). With ticks kept 0.3 ms after the
  // earliest arrivals, most frames would miss their tick and be replaced by the next; the
  // follower waits longer instead. After 5 s of it, 60 s lose under 2% of frames.
  const UniformDelay jitter{1'500'000};
  sim.run(12 * kSecond, 5 * kSecond, jitter);
  run = sim.run(17 * kSecond, 60 * kSecond, jitter);
  INFO("replaced " << run.replaced << " of " << 60 * kSecond << ", mean wait " << run.mean_wait_ms() << " ms");
  CHECK(double(run.replaced) < 0.02 * 60 * kSecond);
  CHECK(run.idle == run.replaced);  // a late frame leaves its tick idle
  // The wait grows by about the jitter's spread, not by whole periods.
  CHECK(run.mean_wait_ms() < 0.3 + 1.5 + 0.5);

  // Steady again: within 10 s the extra wait is gone.
  sim.run(77 * kSecond, 10 * kSecond, steady);
  run = sim.run(87 * kSecond, 5 * kSecond, steady);
  CHECK(sim.follower.jitter_margin_ns() == 0);
  CHECK(run.replaced == 0);
  CHECK(run.mean_wait_ms() == Approx(0.3).margin(0.01));
}

namespace {
// Counts live instances, so the test sees exactly when the hand-off frees one.
struct Counted {
  static inline std::atomic<int> alive{0};
  int id;
  explicit Counted(int i) : id(i) { ++alive; }
  ~Counted() { --alive; }
};
}  // namespace

TEST_CASE("the hand-off swaps in an offer, retires the old object and frees only on the producer side") {
  {
    rt::Handoff<Counted> handoff;
    auto current = std::make_unique<Counted>(1);
    CHECK_FALSE(handoff.adopt(current));  // nothing offered
    handoff.offer(std::make_unique<Counted>(2));
    handoff.offer(std::make_unique<Counted>(3));  // supersedes 2, which is freed by offer()
    CHECK(Counted::alive == 2);
    CHECK(handoff.pending());
    REQUIRE(handoff.adopt(current));
    CHECK(current->id == 3);
    CHECK(Counted::alive == 2);  // 1 retired, not freed by the consumer
    handoff.offer(std::make_unique<Counted>(4));
    CHECK(Counted::alive == 2);  // offer() collected 1 first
    handoff.offer(std::make_unique<Counted>(5));
    REQUIRE(handoff.adopt(current));
    handoff.offer(std::make_unique<Counted>(6));  // collects 3
    // 3 was collected, so the next adoption may go ahead.
    REQUIRE(handoff.adopt(current));
    CHECK(current->id == 6);
    CHECK_FALSE(handoff.adopt(current));
    // Retired 5 still waits for collect(); the destructor frees it.
  }
  CHECK(Counted::alive == 0);
}

TEST_CASE("the hand-off loses and leaks nothing when offers race adoptions") {
  {
    rt::Handoff<Counted> handoff;
    auto current = std::make_unique<Counted>(0);
    std::atomic<bool> done{false};
    std::thread producer([&] {
      for (int i = 1; i <= 20000; ++i) handoff.offer(std::make_unique<Counted>(i));
      done = true;
    });
    int last = 0, adoptions = 0, backwards = 0;
    while (!done.load() || handoff.pending()) {
      if (handoff.adopt(current)) {
        ++adoptions;
        backwards += current->id <= last ? 1 : 0;
        last = current->id;
      }
      if (done.load()) handoff.collect();  // the producer has stopped collecting
    }
    producer.join();
    CHECK(adoptions > 0);
    CHECK(backwards == 0);  // offers are adopted newest-last, never an older one after a newer
    CHECK(current->id == 20000);
    CHECK(Counted::alive <= 2);  // current and at most one uncollected retiree
  }
  CHECK(Counted::alive == 0);
}
