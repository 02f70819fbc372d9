#pragma once
// sd_notify(3) for facecapd: READY=1, RELOADING=1, STOPPING=1, STATUS= and the watchdog.
// Quietly does nothing when not started by systemd (no NOTIFY_SOCKET). Not RT-safe.
#include <cstdint>
#include <string>

namespace facecap::daemon {

class SystemdNotifier {
 public:
  SystemdNotifier();  // reads NOTIFY_SOCKET, WATCHDOG_USEC and WATCHDOG_PID

  bool enabled() const noexcept { return enabled_; }
  // Half of WatchdogSec=, as systemd recommends; 0 when there is no watchdog.
  int64_t watchdog_interval_ns() const noexcept { return watchdog_interval_ns_; }

  void ready(const std::string& status) const;
  void reloading() const;
  void stopping() const;
  void status(const std::string& status) const;
  void watchdog() const;

 private:
  void send(const std::string& message) const;
  bool enabled_ = false;
  int64_t watchdog_interval_ns_ = 0;
};

}  // namespace facecap::daemon
