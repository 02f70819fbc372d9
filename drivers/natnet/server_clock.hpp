#pragma once
// The NatNet server's high-resolution clock on our CLOCK_MONOTONIC, from
// NAT_ECHOREQUEST / NAT_ECHORESPONSE pairs as NTP does it: the server's stamp is taken to
// fall midway through the round trip, and of the recent echoes the one with the shortest
// round trip (the least queueing) gives the offset. Frames' camera mid-exposure stamps
// then become local times, so that exposure -> received is measured across machines.
#include <array>
#include <cstdint>

#include "core/time.hpp"

namespace facecap::drivers::natnet {

class ServerClock {
 public:
  // Ticks per second of the server's stamps (NAT_SERVERINFO); 0 forgets everything (a
  // server without one cannot be followed).
  void set_rate(uint64_t ticks_per_second) noexcept {
    if (ticks_per_second != ticks_per_second_) *this = ServerClock{};
    ticks_per_second_ = ticks_per_second;
  }

  // An echo sent at sent_ns (our clock), stamped server_ticks by the server, back at
  // received_ns. RT-safe.
  void add_echo(int64_t sent_ns, uint64_t server_ticks, int64_t received_ns) noexcept {
    if (ticks_per_second_ == 0 || received_ns < sent_ns) return;
    Sample& s = samples_[next_++ % samples_.size()];
    s.round_trip_ns = received_ns - sent_ns;
    s.offset_ns = sent_ns + s.round_trip_ns / 2 - ticks_to_ns(server_ticks);
    s.valid = true;
    const Sample* best = nullptr;
    for (const Sample& c : samples_)
      if (c.valid && (!best || c.round_trip_ns < best->round_trip_ns)) best = &c;
    offset_ns_ = best->offset_ns;
    round_trip_ns_ = best->round_trip_ns;
    synchronised_ = true;
  }

  bool synchronised() const noexcept { return synchronised_; }
  int64_t round_trip_ns() const noexcept { return round_trip_ns_; }
  // The local CLOCK_MONOTONIC time of a server stamp; 0 until synchronised. RT-safe.
  int64_t to_local_ns(uint64_t server_ticks) const noexcept {
    return synchronised_ ? ticks_to_ns(server_ticks) + offset_ns_ : 0;
  }
  // A duration in server ticks as nanoseconds. RT-safe.
  int64_t ticks_to_ns(uint64_t ticks) const noexcept {
    if (ticks_per_second_ == 0) return 0;
    return int64_t(static_cast<unsigned __int128>(ticks) * kNsPerSecond / ticks_per_second_);
  }

 private:
  struct Sample {
    int64_t offset_ns = 0;
    int64_t round_trip_ns = 0;
    bool valid = false;
  };
  uint64_t ticks_per_second_ = 0;
  std::array<Sample, 8> samples_{};  // the last 8 echoes (one a second: 8 s of drift at most)
  std::size_t next_ = 0;
  int64_t offset_ns_ = 0;
  int64_t round_trip_ns_ = 0;
  bool synchronised_ = false;
};

}  // namespace facecap::drivers::natnet
