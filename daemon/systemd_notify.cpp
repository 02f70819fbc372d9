#include "daemon/systemd_notify.hpp"

#include <cstdlib>

#include <systemd/sd-daemon.h>

#include "core/log.hpp"

namespace facecap::daemon {

SystemdNotifier::SystemdNotifier() {
  const char* socket = std::getenv("NOTIFY_SOCKET");
  enabled_ = socket && *socket;
  uint64_t usec = 0;
  if (enabled_ && sd_watchdog_enabled(0, &usec) > 0 && usec > 0) watchdog_interval_ns_ = int64_t(usec) * 1000 / 2;
}

void SystemdNotifier::send(const std::string& message) const {
  if (!enabled_) return;
  if (const int rc = sd_notify(0, message.c_str()); rc < 0)
    spdlog::warn("sd_notify failed ({}): {}", -rc, message.substr(0, message.find('\n')));
}

void SystemdNotifier::ready(const std::string& status) const { send("READY=1\nSTATUS=" + status); }
void SystemdNotifier::reloading() const { send("RELOADING=1"); }
void SystemdNotifier::stopping() const { send("STOPPING=1\nSTATUS=stopping"); }
void SystemdNotifier::status(const std::string& status) const { send("STATUS=" + status); }
void SystemdNotifier::watchdog() const { send("WATCHDOG=1"); }

}  // namespace facecap::daemon
