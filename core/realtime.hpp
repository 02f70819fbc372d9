#pragma once
// Real-time setup as a reported try: each step that fails leaves its errno and an
// actionable hint in the report, and the caller keeps running without it. Used by the
// solve thread and by drivers whose threads stand in for hardware timing.
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace facecap {

// Middle of the SCHED_FIFO range, below the kernel's threaded interrupts (50).
inline constexpr int kDefaultRealtimePriority = 40;
// A configured priority, 0 meaning the default.
inline constexpr int realtime_priority(int configured) noexcept {
  return configured > 0 ? configured : kDefaultRealtimePriority;
}

struct RealtimeRequest {
  bool fifo = true;                 // SCHED_FIFO for the calling thread
  int priority = 0;                 // 0: kDefaultRealtimePriority
  std::vector<int64_t> cpus;        // affinity of the calling thread; empty: leave it
};

struct RealtimeReport {
  bool fifo_applied = false;
  int priority = 0;                 // what was applied or tried
  int fifo_errno = 0;
  bool priority_clamped = false;    // lowered to RLIMIT_RTPRIO
  bool affinity_applied = false;
  int affinity_errno = 0;
  // For the log, produced off the real-time thread.
  std::vector<std::string> describe(const RealtimeRequest& request) const;
};

// Applies the request to the calling thread. Uses only system calls and does not log;
// call it on the thread itself before its loop starts. RT-safe.
RealtimeReport apply_realtime(const RealtimeRequest& request) noexcept;

struct MemoryLockReport {
  bool locked = false;
  int error = 0;
  std::string describe() const;
};

// mlockall(MCL_CURRENT | MCL_FUTURE) for the whole process. Not RT-safe (call at start).
MemoryLockReport lock_memory() noexcept;

// Prefetches `ranges` into the cache, in order, until CLOCK_MONOTONIC reaches
// deadline_ns (checked every 64 KiB). Returns the bytes prefetched. A thread that sleeps
// between frames calls it before waking for the next one, so that a solve streaming
// megabytes of model data does not start from main memory. RT-safe: prefetch
// instructions and clock reads only.
std::size_t prefetch_until(std::span<const std::span<const std::byte>> ranges, int64_t deadline_ns) noexcept;

}  // namespace facecap
