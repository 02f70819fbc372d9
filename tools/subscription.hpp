#pragma once
// Reading facecapd's shared memory and printing live figures once a second: the body of
// `facecap subscribe`, which `facecap demo` reuses.
#include <cstdint>
#include <string>

namespace facecap::tools {

struct SubscriptionOptions {
  std::string shm_name;
  double seconds = 0.0;        // 0: until the writer stops or Ctrl-C
  double open_timeout_s = 5.0; // keep retrying while facecapd starts
  bool json = false;           // one JSON object per second instead of text
};

struct SubscriptionSummary {
  uint64_t frames = 0;
  uint64_t dropped = 0;
  double seconds = 0.0;
  int64_t latency_p50_ns = 0;  // publish -> read
  int64_t latency_p99_ns = 0;
};

// Prints a line per second; returns what it saw. Throws Error when the segment cannot
// be opened within the timeout.
SubscriptionSummary run_subscription(const SubscriptionOptions& options);

}  // namespace facecap::tools
