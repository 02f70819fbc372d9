#pragma once
// The receiving end of sd_notify(3), for running facecapd under test or from `facecap
// demo` the way systemd does: a datagram socket whose address goes into NOTIFY_SOCKET.
#include <cstdint>
#include <optional>
#include <string>

namespace facecap::daemon {

class NotifyListener {
 public:
  // Binds a fresh abstract-namespace socket. Throws Error.
  NotifyListener();
  ~NotifyListener();
  NotifyListener(const NotifyListener&) = delete;
  NotifyListener& operator=(const NotifyListener&) = delete;

  // The value for NOTIFY_SOCKET ("@facecap-notify-...").
  const std::string& address() const noexcept { return address_; }
  // The next message (one or more "KEY=value" lines), or nullopt after timeout_ns.
  std::optional<std::string> receive(int64_t timeout_ns);

 private:
  int fd_ = -1;
  std::string address_;
};

}  // namespace facecap::daemon
