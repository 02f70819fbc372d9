#include "core/realtime.hpp"

#include <algorithm>
#include <cerrno>
#include <cstring>

#include <fmt/format.h>
#include <pthread.h>
#include <sched.h>
#include <sys/mman.h>
#include <sys/resource.h>

namespace facecap {

RealtimeReport apply_realtime(const RealtimeRequest& request) noexcept {
  RealtimeReport report;
  if (request.fifo) {
    const int lowest = sched_get_priority_min(SCHED_FIFO), highest = sched_get_priority_max(SCHED_FIFO);
    int priority = request.priority > 0 ? request.priority : kDefaultRealtimePriority;
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

std::string MemoryLockReport::describe() const {
  if (locked) return "memory locked (mlockall)";
  return fmt::format("could not lock memory: {}; page faults may delay solves (grant CAP_IPC_LOCK or raise "
                     "RLIMIT_MEMLOCK, e.g. LimitMEMLOCK=infinity)", std::strerror(error));
}

}  // namespace facecap
