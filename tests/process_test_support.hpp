#pragma once
// Programs of the build tree run in the background the way systemd runs facecapd (extra
// environment, output to a log file), and the sd_notify messages they send. Shared by
// the tests that run facecapd and natnet-serve as processes.
#include <csignal>
#include <string>
#include <vector>

#include <catch2/catch.hpp>
#include <fcntl.h>
#include <spawn.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include "core/time.hpp"
#include "daemon/notify_listener.hpp"
#include "tests/test_support.hpp"

extern char** environ;

namespace facecap::test {

// A program of the build tree ("daemon/facecapd", "tools/facecap") with extra environment,
// its output in a log file; killed when destroyed if still running.
class ChildProcess {
 public:
  ChildProcess(const std::string& program, const std::vector<std::string>& args, const std::vector<std::string>& env,
               const std::filesystem::path& log)
      : log_(log) {
    const std::string path = std::string(FACECAP_BINARY_DIR) + "/" + program;
    std::vector<std::string> argv_storage = {path};
    argv_storage.insert(argv_storage.end(), args.begin(), args.end());
    std::vector<char*> argv;
    for (auto& a : argv_storage) argv.push_back(a.data());
    argv.push_back(nullptr);
    std::vector<std::string> env_storage = env;
    for (char** e = environ; *e; ++e) env_storage.emplace_back(*e);
    std::vector<char*> envp;
    for (auto& e : env_storage) envp.push_back(e.data());
    envp.push_back(nullptr);
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_addopen(&actions, 1, log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    posix_spawn_file_actions_adddup2(&actions, 1, 2);
    const int rc = posix_spawn(&pid_, path.c_str(), &actions, nullptr, argv.data(), envp.data());
    posix_spawn_file_actions_destroy(&actions);
    REQUIRE(rc == 0);
  }
  ~ChildProcess() {
    if (!exited_) {
      ::kill(pid_, SIGKILL);
      ::waitpid(pid_, nullptr, 0);
    }
  }
  ChildProcess(const ChildProcess&) = delete;
  ChildProcess& operator=(const ChildProcess&) = delete;

  pid_t pid() const { return pid_; }
  // Exit status (128 + signal when killed), or -1 if still running after timeout_ns;
  // `usage`, when given, gets the child's resource use (wait4) once it has exited.
  int wait_exit(int64_t timeout_ns, rusage* usage = nullptr) {
    const int64_t give_up = monotonic_now_ns() + timeout_ns;
    for (;;) {
      int status = 0;
      if (::wait4(pid_, &status, WNOHANG, usage) == pid_) {
        exited_ = true;
        return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
      }
      if (monotonic_now_ns() >= give_up) return -1;
      usleep(1000);
    }
  }
  std::string log() const { return slurp(log_); }
  // Waits until the log contains `needle`; false after timeout_ns.
  bool wait_for_log(const std::string& needle, int64_t timeout_ns) const {
    const int64_t give_up = monotonic_now_ns() + timeout_ns;
    while (log().find(needle) == std::string::npos) {
      if (monotonic_now_ns() >= give_up) return false;
      usleep(10000);
    }
    return true;
  }

 private:
  pid_t pid_ = 0;
  bool exited_ = false;
  std::filesystem::path log_;
};

// facecapd started with extra environment, its output in a log file.
class DaemonProcess : public ChildProcess {
 public:
  DaemonProcess(const std::vector<std::string>& args, const std::vector<std::string>& env, const std::filesystem::path& log)
      : ChildProcess("daemon/facecapd", args, env, log) {}
};

// Collects sd_notify messages and waits for particular ones.
struct NotifyRecorder {
  daemon::NotifyListener listener;
  std::vector<std::string> messages;

  bool wait_for(const std::string& needle, int64_t timeout_ns, std::size_t from = 0) {
    const int64_t give_up = monotonic_now_ns() + timeout_ns;
    for (;;) {
      for (std::size_t i = from; i < messages.size(); ++i)
        if (messages[i].find(needle) != std::string::npos) return true;
      const int64_t left = give_up - monotonic_now_ns();
      if (left <= 0) return false;
      if (auto m = listener.receive(std::min<int64_t>(left, 50 * kNsPerMs))) messages.push_back(*m);
    }
  }
  void drain() {
    while (auto m = listener.receive(0)) messages.push_back(*m);
  }
  // Waits for `process` to exit, taking its messages meanwhile (on a full notify socket its
  // sd_notify would block): its exit status, or -1 after timeout_ns.
  int wait_exit(ChildProcess& process, int64_t timeout_ns) {
    const int64_t give_up = monotonic_now_ns() + timeout_ns;
    for (;;) {
      drain();
      if (const int status = process.wait_exit(10 * kNsPerMs); status != -1) return status;
      if (monotonic_now_ns() >= give_up) return -1;
    }
  }
  std::size_t count(const std::string& needle) const {
    std::size_t n = 0;
    for (const auto& m : messages) n += m.find(needle) != std::string::npos ? 1 : 0;
    return n;
  }
  std::size_t index_of(const std::string& needle) const {
    for (std::size_t i = 0; i < messages.size(); ++i)
      if (messages[i].find(needle) != std::string::npos) return i;
    return messages.size();
  }
};

}  // namespace facecap::test
