#include "daemon/process_signals.hpp"

#include <cstdio>
#include <cstdlib>
#include <cstring>

#include <dlfcn.h>
#include <unistd.h>
#include <fmt/format.h>
#include <ctime>

#include "core/time.hpp"

namespace facecap::daemon {

sigset_t control_signals() {
  sigset_t set;
  sigemptyset(&set);
  sigaddset(&set, SIGTERM);
  sigaddset(&set, SIGINT);
  sigaddset(&set, SIGHUP);
  return set;
}

void prepare_process_signals() {
  const sigset_t handled = control_signals();
  pthread_sigmask(SIG_BLOCK, &handled, nullptr);
  struct sigaction ignore {};
  ignore.sa_handler = SIG_IGN;
  sigaction(SIGXFSZ, &ignore, nullptr);
}

std::string pin_library_thread_pools() {
  std::string done;
  // Looked up at run time: which BLAS is loaded is the system's choice (Debian's
  // alternatives), and the reference BLAS has no pool.
  auto pin = [&](const char* environment, const char* setter) {
    if (const char* given = std::getenv(environment)) {
      done += fmt::format("{}{}={} (from the environment)", done.empty() ? "" : ", ", environment, given);
      return;
    }
    if (void* symbol = dlsym(RTLD_DEFAULT, setter)) {
      reinterpret_cast<void (*)(int)>(symbol)(1);
      done += fmt::format("{}{}(1)", done.empty() ? "" : ", ", setter);
    }
  };
  pin("OPENBLAS_NUM_THREADS", "openblas_set_num_threads");
  pin("OMP_NUM_THREADS", "omp_set_num_threads");
  return done;
}

int wait_for_control_signal(int64_t timeout_ns) {
  const sigset_t handled = control_signals();
  const timespec timeout{time_t(timeout_ns / kNsPerSecond), long(timeout_ns % kNsPerSecond)};
  const int signal = sigtimedwait(&handled, nullptr, &timeout);
  return signal > 0 ? signal : 0;
}

StartupSignalWatch::StartupSignalWatch() {
  thread_ = std::thread([this] {
    while (!stopping_.load()) {
      const int signal = wait_for_control_signal(20 * kNsPerMs);
      if (signal == 0) continue;
      if (signal == SIGHUP) {  // a reload: the run loop's, once it runs
        hup_pending_.store(true);
        continue;
      }
      if (stopping_.load()) {
        ::kill(::getpid(), signal);  // pending again, for the run loop
        return;
      }
      std::fprintf(stderr, "facecapd: %s during startup: stopping\n", strsignal(signal));
      struct sigaction fallback {};
      fallback.sa_handler = SIG_DFL;
      sigaction(signal, &fallback, nullptr);
      sigset_t just_this;
      sigemptyset(&just_this);
      sigaddset(&just_this, signal);
      pthread_sigmask(SIG_UNBLOCK, &just_this, nullptr);
      ::raise(signal);  // ends the process by the signal, as an unhandled SIGTERM would
      std::_Exit(128 + signal);
    }
  });
}

void StartupSignalWatch::stop() {
  stopping_.store(true);
  if (thread_.joinable()) thread_.join();
  if (hup_pending_.exchange(false)) ::kill(::getpid(), SIGHUP);
}

}  // namespace facecap::daemon
