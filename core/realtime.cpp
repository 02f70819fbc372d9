#include "core/realtime.hpp"

#include <algorithm>
#include <cerrno>
#include <cstring>

#include <fmt/format.h>
#include <pthread.h>
#include <sched.h>
#include <sys/mman.h>
#include <sys/resource.h>

#include "core/time.hpp"

namespace facecap {

RealtimeReport apply_realtime(const RealtimeRequest& request) noexcept {
  RealtimeReport report;
  if (request.fifo) {
    const int lowest = sched_get_priority_min(SCHED_FIFO), highest = sched_get_priority_max(SCHED_FIFO);
    int priority = realtime_priority(request.priority);
    priority = std::clamp(priority, lowest, highest);
    // Without CAP_SYS_NICE only up to RLIMIT_RTPRIO is allowed; root's limit is often 0
    // yet it may set any priority, so the limit is applied only when it is not zero.
    rlimit limit{};
    if (getrlimit(RLIMIT_RTPRIO, &limit) == 0 && limit.rlim_cur != RLIM_INFINITY && limit.rlim_cur > 0 &&
        rlim_t(priority) > limit.rlim_cur) {
      priority = int(limit.rlim_cur);
      report.priority_clamped = true;
    }
    report.priority = priority;
    sched_param param{};
    param.sched_priority = priority;
    const int rc = pthread_setschedparam(pthread_self(), SCHED_FIFO, &param);
    report.fifo_applied = rc == 0;
    report.fifo_errno = rc;
  }
  if (!request.cpus.empty()) {
    cpu_set_t set;
    CPU_ZERO(&set);
    for (const int64_t cpu : request.cpus)
      if (cpu >= 0 && cpu < CPU_SETSIZE) CPU_SET(int(cpu), &set);
    const int rc = pthread_setaffinity_np(pthread_self(), sizeof set, &set);
    report.affinity_applied = rc == 0;
    report.affinity_errno = rc;
  }
  return report;
}

std::vector<std::string> RealtimeReport::describe(const RealtimeRequest& request) const {
  std::vector<std::string> lines;
  if (request.fifo) {
    if (fifo_applied)
      lines.push_back(fmt::format("solve thread runs SCHED_FIFO priority {}{}", priority,
                                  priority_clamped ? " (clamped to RLIMIT_RTPRIO)" : ""));
    else
      lines.push_back(fmt::format("could not make the solve thread SCHED_FIFO priority {}: {}; it runs at normal "
                                  "priority and may miss deadlines under load (grant CAP_SYS_NICE, as the systemd "
                                  "unit does, or raise RLIMIT_RTPRIO, e.g. LimitRTPRIO=)",
                                  priority, std::strerror(fifo_errno)));
  }
  if (!request.cpus.empty()) {
    if (affinity_applied) lines.push_back(fmt::format("solve thread pinned to CPUs {}", fmt::join(request.cpus, ",")));
    else
      lines.push_back(fmt::format("could not pin the solve thread to CPUs {}: {}; check loop.cpu_affinity against the "
                                  "CPUs this process may use", fmt::join(request.cpus, ","), std::strerror(affinity_errno)));
  }
  return lines;
}

MemoryLockReport lock_memory() noexcept {
  MemoryLockReport report;
  report.locked = mlockall(MCL_CURRENT | MCL_FUTURE) == 0;
  report.error = report.locked ? 0 : errno;
  return report;
}

std::size_t prefetch_until(std::span<const std::span<const std::byte>> ranges, int64_t deadline_ns) noexcept {
  constexpr std::size_t kLine = 64, kChunk = 64 * 1024;
  std::size_t done = 0;
  for (const auto range : ranges) {
    for (std::size_t begin = 0; begin < range.size(); begin += kChunk) {
      if (monotonic_now_ns() >= deadline_ns) return done;
      const std::size_t end = std::min(range.size(), begin + kChunk);
      // Locality 1: into the outer caches; the solve's own loads take it from there.
      for (std::size_t at = begin; at < end; at += kLine) __builtin_prefetch(range.data() + at, 0, 1);
      done += end - begin;
    }
  }
  return done;
}

std::string MemoryLockReport::describe() const {
  if (locked) return "memory locked (mlockall)";
  return fmt::format("could not lock memory: {}; page faults may delay solves (grant CAP_IPC_LOCK or raise "
                     "RLIMIT_MEMLOCK, e.g. LimitMEMLOCK=infinity)", std::strerror(error));
}

}  // namespace facecap
