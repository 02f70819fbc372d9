#pragma once
// The signals facecapd handles, in one place: SIGTERM and SIGINT stop it, SIGHUP reloads
// its configuration. They are blocked in every thread and taken synchronously by the
// supervisor (wait_for_control_signal); no asynchronous handler runs anywhere.
#include <atomic>
#include <cstdint>
#include <string>
#include <thread>

#include <signal.h>

namespace facecap::daemon {

// SIGTERM, SIGINT and SIGHUP.
sigset_t control_signals();

// Prepares the process before any library starts a thread; runs from facecapd's
// .preinit_array, i.e. before every shared library's constructors (OpenBLAS starts its
// worker pool from one, and a thread that does not block the control signals is where the
// kernel delivers them: the default action then ends the process). Threads inherit the mask.
//  - blocks control_signals();
//  - ignores SIGXFSZ, so a write past RLIMIT_FSIZE fails with EFBIG into the recorder's
//    error path instead of killing the box mid-shoot.
// Only system calls: libc itself is not initialised yet (environ is still null there, so
// an environment variable set here would not reach the libraries).
void prepare_process_signals();

// Makes OpenBLAS and OpenMP (when loaded) run their work on the calling thread, unless
// the environment sizes their pools (OPENBLAS_NUM_THREADS, OMP_NUM_THREADS): the solve's
// BLAS work is small, and a pool woken beside the real-time loop would take its core. The
// pools' threads, started before main(), stay asleep. Returns what it did, for the log.
// Call first thing in main(). Not RT-safe.
std::string pin_library_thread_pools();

// Waits up to timeout_ns for a control signal: the signal, or 0 on timeout.
int wait_for_control_signal(int64_t timeout_ns);

// From construction until stop(): SIGTERM or SIGINT ends the process at once, by that
// signal, with a line on stderr, so that loading the configuration, the rig and the
// source's files stays stoppable whatever it reads; the run loop takes the signals over
// after stop(). A SIGHUP, or a signal arriving as stop() is called, is left to the run loop.
class StartupSignalWatch {
 public:
  StartupSignalWatch();
  ~StartupSignalWatch() { stop(); }
  StartupSignalWatch(const StartupSignalWatch&) = delete;
  StartupSignalWatch& operator=(const StartupSignalWatch&) = delete;
  void stop();

 private:
  std::atomic<bool> stopping_{false};
  std::atomic<bool> hup_pending_{false};
  std::thread thread_;
};

}  // namespace facecap::daemon
