#pragma once
// One UDP socket of a network output, connected to its destination (unicast or a
// multicast group) and used on facecapd's I/O thread only. Sends never block: a datagram
// the kernel cannot take at once is an error like one it refuses (no route, ECONNREFUSED
// from a closed port on this machine, ENOBUFS). Errors are counted, never fatal, and
// logged at most once a second.
#include <atomic>
#include <cstdint>
#include <span>
#include <string>

#include <boost/asio/buffer.hpp>
#include <boost/asio/io_context.hpp>
#include <boost/asio/ip/multicast.hpp>
#include <boost/asio/ip/udp.hpp>

namespace facecap::outputs {

struct UdpDestination {
  std::string address;              // numeric IPv4 or IPv6, unicast or multicast
  uint16_t port = 0;
  int multicast_ttl = 1;
  std::string multicast_interface;  // by name; empty: the system's choice
  int send_buffer_bytes = 0;        // 0: the system's default
};

class UdpSender {
 public:
  // Opens and connects the socket. `output` names the sink in log lines. Not RT-safe;
  // throws Error naming what failed.
  UdpSender(boost::asio::io_context& io, const UdpDestination& destination, std::string output);

  // One datagram from its parts (scatter-gather). True when the kernel took it. I/O thread.
  bool send(std::span<const boost::asio::const_buffer> parts) noexcept;
  bool send(std::span<const char> datagram) noexcept {
    const boost::asio::const_buffer part(datagram.data(), datagram.size());
    return send(std::span<const boost::asio::const_buffer>(&part, 1));
  }
  // I/O thread. Idempotent.
  void close() noexcept;

  // Any thread.
  uint64_t errors() const noexcept { return errors_.load(std::memory_order_relaxed); }
  uint64_t datagrams_sent() const noexcept { return datagrams_.load(std::memory_order_relaxed); }
  uint64_t bytes_sent() const noexcept { return bytes_.load(std::memory_order_relaxed); }
  // "127.0.0.1:39540", "multicast 239.255.70.67:39540 (ttl 1, eth0)".
  const std::string& describe() const noexcept { return description_; }

 private:
  boost::asio::ip::udp::socket socket_;
  std::string output_;
  std::string description_;
  std::atomic<uint64_t> errors_{0}, datagrams_{0}, bytes_{0};
  int64_t last_log_ns_ = 0;
};

}  // namespace facecap::outputs
