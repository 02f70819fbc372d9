#pragma once
// A fixed-size latency histogram one thread records into (no allocation, no lock) and
// others snapshot. Buckets are 1 us wide below 1 ms, 10 us below 10 ms, 100 us below
// 100 ms and 1 ms below 1 s: about 1% resolution everywhere that matters.
#include <array>
#include <atomic>
#include <cstdint>

namespace facecap {

class LatencyHistogram {
 public:
  static constexpr std::size_t kBucketCount = 1000 + 900 + 900 + 900 + 1;  // last: >= 1 s

  struct Snapshot {
    std::array<uint64_t, kBucketCount> counts{};
    uint64_t total() const noexcept;
    // The latency at or below which a fraction q (0..1) of samples fall (bucket upper edge); 0 when empty.
    int64_t quantile_ns(double q) const noexcept;
    Snapshot since(const Snapshot& earlier) const noexcept;  // counts added after `earlier`
  };

  // Single writer. RT-safe.
  void record(int64_t latency_ns) noexcept {
    auto& bucket = counts_[bucket_of(latency_ns)];
    bucket.store(bucket.load(std::memory_order_relaxed) + 1, std::memory_order_relaxed);
  }
  // Any thread; a concurrent record() may or may not be included. Not RT-safe (large copy).
  Snapshot snapshot() const noexcept;

  static std::size_t bucket_of(int64_t ns) noexcept;
  static int64_t upper_edge_ns(std::size_t bucket) noexcept;

 private:
  std::array<std::atomic<uint64_t>, kBucketCount> counts_{};
};

}  // namespace facecap
