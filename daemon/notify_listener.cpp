#include "daemon/notify_listener.hpp"

#include <atomic>
#include <cerrno>
#include <cstring>

#include <fmt/format.h>
#include <poll.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include "core/error.hpp"

namespace facecap::daemon {

NotifyListener::NotifyListener() {
  static std::atomic<int> counter{0};
  address_ = fmt::format("@facecap-notify-{}-{}", ::getpid(), counter++);
  fd_ = ::socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  if (fd_ < 0) throw Error(fmt::format("cannot create a notify socket: {}", std::strerror(errno)));
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  // Abstract namespace: a leading NUL instead of '@', no file to clean up.
  std::memcpy(addr.sun_path + 1, address_.data() + 1, address_.size() - 1);
  const auto length = socklen_t(offsetof(sockaddr_un, sun_path) + address_.size());
  if (::bind(fd_, reinterpret_cast<const sockaddr*>(&addr), length) != 0) {
    const int saved = errno;
    ::close(fd_);
    throw Error(fmt::format("cannot bind the notify socket {}: {}", address_, std::strerror(saved)));
  }
}

NotifyListener::~NotifyListener() {
  if (fd_ >= 0) ::close(fd_);
}

std::optional<std::string> NotifyListener::receive(int64_t timeout_ns) {
  pollfd p{fd_, POLLIN, 0};
  const int ready = ::poll(&p, 1, int(timeout_ns / 1'000'000));
  if (ready <= 0) return std::nullopt;
  char buffer[4096];
  const ssize_t n = ::recv(fd_, buffer, sizeof buffer, 0);
  if (n < 0) return std::nullopt;
  return std::string(buffer, std::size_t(n));
}

}  // namespace facecap::daemon
