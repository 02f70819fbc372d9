#include "drivers/natnet/udp_socket.hpp"

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <utility>

#include <arpa/inet.h>
#include <fcntl.h>
#include <fmt/format.h>
#include <ifaddrs.h>
#include <net/if.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include "core/error.hpp"

namespace facecap::drivers::natnet {
namespace {

sockaddr_in to_sockaddr(uint32_t address, uint16_t port) {
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(address);
  a.sin_port = htons(port);
  return a;
}

// The IPv4 address of a named interface, 0 when it has none.
uint32_t interface_address(const std::string& name) {
  ifaddrs* list = nullptr;
  if (getifaddrs(&list) != 0) return 0;
  uint32_t found = 0;
  for (const ifaddrs* i = list; i; i = i->ifa_next) {
    if (i->ifa_addr && i->ifa_addr->sa_family == AF_INET && name == i->ifa_name) {
      found = ntohl(reinterpret_cast<const sockaddr_in*>(i->ifa_addr)->sin_addr.s_addr);
      break;
    }
  }
  freeifaddrs(list);
  return found;
}

}  // namespace

std::string ipv4_string(uint32_t address) {
  return fmt::format("{}.{}.{}.{}", address >> 24, (address >> 16) & 0xff, (address >> 8) & 0xff, address & 0xff);
}

std::string Endpoint::address_string() const { return ipv4_string(address); }
std::string Endpoint::to_string() const { return fmt::format("{}:{}", ipv4_string(address), port); }

uint32_t parse_ipv4(std::string_view text, std::string_view what) {
  in_addr a{};
  const std::string s(text);
  if (inet_pton(AF_INET, s.c_str(), &a) != 1)
    throw Error(fmt::format("{} \"{}\" is not an IPv4 address (like 10.0.0.5)", what, text));
  return ntohl(a.s_addr);
}

LocalInterface resolve_interface(std::string_view text) {
  LocalInterface out;
  out.name = std::string(text);
  if (text.empty()) return out;
  in_addr a{};
  if (inet_pton(AF_INET, out.name.c_str(), &a) == 1) {
    out.address = ntohl(a.s_addr);
    return out;
  }
  out.index = int(if_nametoindex(out.name.c_str()));
  if (out.index == 0)
    throw Error(fmt::format("local interface \"{}\" is neither an IPv4 address nor a network interface of this host",
                            text));
  out.address = interface_address(out.name);
  return out;
}

UdpSocket::UdpSocket(uint32_t address, uint16_t port, bool reuse, std::string what) : what_(std::move(what)) {
  fd_ = ::socket(AF_INET, SOCK_DGRAM | SOCK_NONBLOCK | SOCK_CLOEXEC, IPPROTO_UDP);
  if (fd_ < 0) throw Error(fmt::format("{}: cannot create a UDP socket: {}", what_, std::strerror(errno)));
  const int one = 1;
  if (reuse) ::setsockopt(fd_, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
  const sockaddr_in a = to_sockaddr(address, port);
  if (::bind(fd_, reinterpret_cast<const sockaddr*>(&a), sizeof a) != 0) {
    const int e = errno;
    ::close(fd_);
    fd_ = -1;
    throw Error(fmt::format("{}: cannot bind UDP {}:{}: {}", what_, ipv4_string(address), port, std::strerror(e)));
  }
}

UdpSocket::~UdpSocket() {
  if (fd_ >= 0) ::close(fd_);
}

UdpSocket::UdpSocket(UdpSocket&& other) noexcept : fd_(std::exchange(other.fd_, -1)), what_(std::move(other.what_)) {}

UdpSocket& UdpSocket::operator=(UdpSocket&& other) noexcept {
  if (this != &other) {
    if (fd_ >= 0) ::close(fd_);
    fd_ = std::exchange(other.fd_, -1);
    what_ = std::move(other.what_);
  }
  return *this;
}

Endpoint UdpSocket::local() const {
  sockaddr_in a{};
  socklen_t n = sizeof a;
  ::getsockname(fd_, reinterpret_cast<sockaddr*>(&a), &n);
  return {ntohl(a.sin_addr.s_addr), ntohs(a.sin_port)};
}

void UdpSocket::join_multicast(uint32_t group, const LocalInterface& on) {
  ip_mreqn request{};
  request.imr_multiaddr.s_addr = htonl(group);
  request.imr_address.s_addr = htonl(on.address);
  request.imr_ifindex = on.index;
  if (::setsockopt(fd_, IPPROTO_IP, IP_ADD_MEMBERSHIP, &request, sizeof request) != 0) {
    throw Error(fmt::format("{}: cannot join multicast group {} on {}: {}", what_, ipv4_string(group),
                            on.name.empty() ? "the default interface" : on.name, std::strerror(errno)));
  }
}

void UdpSocket::set_multicast_sender(const LocalInterface& via, int ttl) {
  ip_mreqn request{};
  request.imr_address.s_addr = htonl(via.address);
  request.imr_ifindex = via.index;
  const unsigned char loop = 1, hops = (unsigned char)ttl;
  if (::setsockopt(fd_, IPPROTO_IP, IP_MULTICAST_IF, &request, sizeof request) != 0 ||
      ::setsockopt(fd_, IPPROTO_IP, IP_MULTICAST_LOOP, &loop, sizeof loop) != 0 ||
      ::setsockopt(fd_, IPPROTO_IP, IP_MULTICAST_TTL, &hops, sizeof hops) != 0) {
    throw Error(fmt::format("{}: cannot send multicast via {}: {}", what_,
                            via.name.empty() ? "the default interface" : via.name, std::strerror(errno)));
  }
}

void UdpSocket::enable_broadcast() {
  const int one = 1;
  if (::setsockopt(fd_, SOL_SOCKET, SO_BROADCAST, &one, sizeof one) != 0)
    throw Error(fmt::format("{}: cannot broadcast: {}", what_, std::strerror(errno)));
}

void UdpSocket::set_receive_buffer(int bytes) {
  // The kernel caps it at net.core.rmem_max; a smaller buffer only drops more in a burst.
  ::setsockopt(fd_, SOL_SOCKET, SO_RCVBUF, &bytes, sizeof bytes);
}

bool UdpSocket::send_to(std::span<const char> bytes, const Endpoint& to) noexcept {
  const sockaddr_in a = to_sockaddr(to.address, to.port);
  return ::sendto(fd_, bytes.data(), bytes.size(), 0, reinterpret_cast<const sockaddr*>(&a), sizeof a) ==
         ssize_t(bytes.size());
}

std::optional<Datagram> UdpSocket::receive(std::span<char> buffer) noexcept {
  sockaddr_in from{};
  iovec io{buffer.data(), buffer.size()};
  msghdr message{};
  message.msg_name = &from;
  message.msg_namelen = sizeof from;
  message.msg_iov = &io;
  message.msg_iovlen = 1;
  const ssize_t n = ::recvmsg(fd_, &message, 0);
  if (n < 0) return std::nullopt;
  return Datagram{std::size_t(n), (message.msg_flags & MSG_TRUNC) != 0,
                  {ntohl(from.sin_addr.s_addr), ntohs(from.sin_port)}};
}

int wait_readable(const UdpSocket& a, const UdpSocket* b, int64_t timeout_ns) noexcept {
  pollfd fds[2] = {{a.fd(), POLLIN, 0}, {b ? b->fd() : -1, POLLIN, 0}};
  const int64_t ns = std::max<int64_t>(0, timeout_ns);
  const timespec timeout{time_t(ns / 1'000'000'000), long(ns % 1'000'000'000)};  // ppoll: to the microsecond
  if (::ppoll(fds, b ? 2 : 1, &timeout, nullptr) <= 0) return 0;
  return ((fds[0].revents & POLLIN) ? 1 : 0) | ((b && (fds[1].revents & POLLIN)) ? 2 : 0);
}

}  // namespace facecap::drivers::natnet
