#pragma once
// Time is int64 nanoseconds on CLOCK_MONOTONIC everywhere; names end in _ns.
#include <cerrno>
#include <cstdint>
#include <ctime>

namespace facecap {

inline constexpr int64_t kNsPerSecond = 1'000'000'000;
inline constexpr int64_t kNsPerMs = 1'000'000;
inline constexpr int64_t kNsPerUs = 1'000;

// Real-time safe.
inline int64_t monotonic_now_ns() noexcept {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return int64_t(ts.tv_sec) * kNsPerSecond + ts.tv_nsec;
}

// Sleeps until deadline_ns on CLOCK_MONOTONIC, through signals. Real-time safe.
inline void sleep_until(int64_t deadline_ns) noexcept {
  timespec ts{time_t(deadline_ns / kNsPerSecond), long(deadline_ns % kNsPerSecond)};
  while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {}
}

// SMPTE-style timecode as carried by capture sources (Live Link Face, C3D, NatNet).
// rate_hz is the timecode base (e.g. 60 for Live Link Face); subframe keeps the
// fractional part some sources add (HH:MM:SS:FF.fff).
struct Timecode {
  uint8_t hours = 0;
  uint8_t minutes = 0;
  uint8_t seconds = 0;
  uint8_t frames = 0;
  float subframe = 0.0f;
  uint16_t rate_hz = 0;  // 0: no timecode present
  bool valid() const noexcept { return rate_hz != 0; }
  bool operator==(const Timecode&) const = default;
};

}  // namespace facecap
