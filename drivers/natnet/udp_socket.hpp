#pragma once
// IPv4 UDP sockets as NatNet uses them (plain POSIX: one socket per port, poll() on a
// receive thread): bind with address reuse so that several receivers share a multicast
// port, join a group on a chosen interface, send multicast out of one interface,
// broadcast for discovery. The NatNet driver and `facecap natnet-serve` share it.
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>

namespace facecap::drivers::natnet {

// An IPv4 address and port, in host byte order.
struct Endpoint {
  uint32_t address = 0;
  uint16_t port = 0;
  std::string to_string() const;          // "10.0.0.5:1510"
  std::string address_string() const;     // "10.0.0.5"
  bool operator==(const Endpoint&) const = default;
};

// "10.0.0.5" in host byte order; throws Error saying what `what` is when the text is not
// a dotted IPv4 address.
uint32_t parse_ipv4(std::string_view text, std::string_view what);
std::string ipv4_string(uint32_t address);

// The local interface to send from and join multicast groups on.
struct LocalInterface {
  std::string name;      // as configured ("" for the system's choice)
  int index = 0;         // 0: let the kernel choose
  uint32_t address = 0;  // 0 (INADDR_ANY): none in particular
};
// From an IPv4 address of this host ("192.168.0.100") or an interface name ("eth1", "lo");
// "" is the system's choice. Throws Error naming it when neither.
LocalInterface resolve_interface(std::string_view text);

// What receive() got.
struct Datagram {
  std::size_t size = 0;    // bytes in the buffer
  bool truncated = false;  // the datagram was larger than the buffer (its end was cut)
  Endpoint from;
};

class UdpSocket {
 public:
  // Binds to address:port (port 0: any free port). `reuse` sets SO_REUSEADDR, for ports
  // that several receivers share (NatNet's multicast data port). Throws Error naming
  // `what` and the address. Non-blocking.
  UdpSocket(uint32_t address, uint16_t port, bool reuse, std::string what);
  ~UdpSocket();
  UdpSocket(UdpSocket&& other) noexcept;
  UdpSocket& operator=(UdpSocket&& other) noexcept;
  UdpSocket(const UdpSocket&) = delete;
  UdpSocket& operator=(const UdpSocket&) = delete;

  int fd() const noexcept { return fd_; }
  Endpoint local() const;

  // Each throws Error naming the socket and the errno.
  void join_multicast(uint32_t group, const LocalInterface& on);
  void set_multicast_sender(const LocalInterface& via, int ttl);  // loops back to local receivers too
  void enable_broadcast();
  void set_receive_buffer(int bytes);

  // One datagram; false (errno set) when the kernel refused it. Never throws.
  bool send_to(std::span<const char> bytes, const Endpoint& to) noexcept;
  // One waiting datagram into `buffer`, nullopt when none is waiting. Never throws.
  std::optional<Datagram> receive(std::span<char> buffer) noexcept;

 private:
  int fd_ = -1;
  std::string what_;
};

// Waits up to `timeout_ns` (to the microsecond) for either socket (b may be null) to have a datagram; returns a
// bit per readable socket (1: a, 2: b), 0 on timeout or EINTR. Never throws.
int wait_readable(const UdpSocket& a, const UdpSocket* b, int64_t timeout_ns) noexcept;

}  // namespace facecap::drivers::natnet
