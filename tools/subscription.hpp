#pragma once
// Reading facecapd's shared memory or UDP stream and printing live figures once a second:
// the body of `facecap subscribe`, which `facecap daemon-demo` reuses.
#include <cstdint>
#include <functional>
#include <string>

#include "client/facecap_client.h"

namespace facecap::tools {

struct SubscriptionOptions {
  std::string shm_name;        // one of these two
  std::string udp_address;     // "ADDRESS:PORT" (facecap_client_open_udp)
  std::string udp_interface;   // for a multicast group; empty: the system's choice
  double seconds = 0.0;        // 0: until the writer stops or Ctrl-C
  double open_timeout_s = 5.0; // keep retrying while facecapd starts
  bool json = false;           // one JSON object per second instead of text
  // Optional: sees every frame read, and adds to each printed line.
  std::function<void(const facecap_frame&)> on_frame;
  std::function<std::string()> line_suffix;
};

struct SubscriptionSummary {
  uint64_t frames = 0;
  uint64_t dropped = 0;
  uint64_t incomplete = 0;     // UDP: frames given up for a missing datagram
  double seconds = 0.0;
  int64_t latency_p50_ns = 0;  // publish -> read
  int64_t latency_p99_ns = 0;
};

// Prints a line per second; returns what it saw. Throws Error when the segment cannot
// be opened within the timeout, or the UDP address cannot be received on.
SubscriptionSummary run_subscription(const SubscriptionOptions& options);

}  // namespace facecap::tools
