#include "outputs/net/udp_sender.hpp"

#include <cstring>

#include <net/if.h>
#include <netinet/in.h>

#include <fmt/format.h>

#include "core/error.hpp"
#include "core/log.hpp"
#include "core/time.hpp"

namespace facecap::outputs {

namespace asio = boost::asio;
using asio::ip::udp;

UdpSender::UdpSender(asio::io_context& io, const UdpDestination& d, std::string output)
    : socket_(io), output_(std::move(output)) {
  boost::system::error_code ec;
  const asio::ip::address address = asio::ip::make_address(d.address, ec);
  if (ec) throw Error(fmt::format("\"{}\" is not a numeric IPv4 or IPv6 address", d.address));
  const udp::endpoint endpoint(address, d.port);
  auto fail = [&](std::string_view what) {
    throw Error(fmt::format("UDP to {}:{}: {}: {}", d.address, d.port, what, ec.message()));
  };
  socket_.open(endpoint.protocol(), ec);
  if (ec) fail("cannot open a socket");
  if (d.send_buffer_bytes > 0) socket_.set_option(asio::socket_base::send_buffer_size(d.send_buffer_bytes), ec);
  description_ = fmt::format("{}:{}", d.address, d.port);
  if (address.is_multicast()) {
    socket_.set_option(asio::ip::multicast::hops(d.multicast_ttl), ec);
    if (ec) fail("cannot set the multicast TTL");
    if (!d.multicast_interface.empty()) {
      const unsigned index = if_nametoindex(d.multicast_interface.c_str());
      if (index == 0) throw Error(fmt::format("UDP to {}: no network interface \"{}\"", description_, d.multicast_interface));
      int rc = 0;
      if (address.is_v4()) {
        ip_mreqn request{};
        request.imr_ifindex = int(index);
        rc = setsockopt(socket_.native_handle(), IPPROTO_IP, IP_MULTICAST_IF, &request, sizeof request);
      } else {
        rc = setsockopt(socket_.native_handle(), IPPROTO_IPV6, IPV6_MULTICAST_IF, &index, sizeof index);
      }
      if (rc != 0) throw Error(fmt::format("UDP to {}: cannot send multicast on {}: {}", description_, d.multicast_interface, std::strerror(errno)));
    }
    description_ = fmt::format("multicast {} (ttl {}{}{})", description_, d.multicast_ttl,
                               d.multicast_interface.empty() ? "" : ", ", d.multicast_interface);
  }
  // Connected: the kernel routes once, and reports a closed port on this machine
  // (ECONNREFUSED) on a later send instead of dropping silently.
  socket_.connect(endpoint, ec);
  if (ec) fail("cannot connect");
  socket_.non_blocking(true, ec);
  if (ec) fail("cannot make the socket non-blocking");
}

bool UdpSender::send(std::span<const asio::const_buffer> parts) noexcept {
  boost::system::error_code ec;
  const std::size_t sent = socket_.send(parts, 0, ec);
  if (!ec) {
    datagrams_.store(datagrams_.load(std::memory_order_relaxed) + 1, std::memory_order_relaxed);
    bytes_.store(bytes_.load(std::memory_order_relaxed) + sent, std::memory_order_relaxed);
    return true;
  }
  const uint64_t errors = errors_.load(std::memory_order_relaxed) + 1;
  errors_.store(errors, std::memory_order_relaxed);
  const int64_t now = monotonic_now_ns();
  if (now - last_log_ns_ >= kNsPerSecond) {
    spdlog::warn("output {}: sending to {}: {} ({} errors so far)", output_, description_, ec.message(), errors);
    last_log_ns_ = now;
  }
  return false;
}

void UdpSender::close() noexcept {
  boost::system::error_code ignored;
  socket_.close(ignored);
}

}  // namespace facecap::outputs
