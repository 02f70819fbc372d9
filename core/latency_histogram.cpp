#include "core/latency_histogram.hpp"

namespace facecap {

std::size_t LatencyHistogram::bucket_of(int64_t ns) noexcept {
  const int64_t us = ns < 0 ? 0 : ns / 1000;
  if (us < 1000) return std::size_t(us);
  if (us < 10'000) return std::size_t(1000 + (us - 1000) / 10);
  if (us < 100'000) return std::size_t(1900 + (us - 10'000) / 100);
  if (us < 1'000'000) return std::size_t(2800 + (us - 100'000) / 1000);
  return kBucketCount - 1;
}

int64_t LatencyHistogram::upper_edge_ns(std::size_t b) noexcept {
  int64_t us = 0;
  if (b < 1000) us = int64_t(b) + 1;
  else if (b < 1900) us = 1000 + (int64_t(b) - 1000 + 1) * 10;
  else if (b < 2800) us = 10'000 + (int64_t(b) - 1900 + 1) * 100;
  else if (b < 3700) us = 100'000 + (int64_t(b) - 2800 + 1) * 1000;
  else us = 1'000'000;
  return us * 1000;
}

LatencyHistogram::Snapshot LatencyHistogram::snapshot() const noexcept {
  Snapshot s;
  for (std::size_t i = 0; i < kBucketCount; ++i) s.counts[i] = counts_[i].load(std::memory_order_relaxed);
  return s;
}

uint64_t LatencyHistogram::Snapshot::total() const noexcept {
  uint64_t n = 0;
  for (const uint64_t c : counts) n += c;
  return n;
}

int64_t LatencyHistogram::Snapshot::quantile_ns(double q) const noexcept {
  const uint64_t n = total();
  if (n == 0) return 0;
  // The smallest bucket whose cumulative count reaches ceil(q * n).
  uint64_t rank = uint64_t(q * double(n));
  if (double(rank) < q * double(n)) ++rank;
  if (rank == 0) rank = 1;
  uint64_t seen = 0;
  for (std::size_t i = 0; i < kBucketCount; ++i) {
    seen += counts[i];
    if (seen >= rank) return upper_edge_ns(i);
  }
  return upper_edge_ns(kBucketCount - 1);
}

LatencyHistogram::Snapshot LatencyHistogram::Snapshot::since(const Snapshot& earlier) const noexcept {
  Snapshot d;
  for (std::size_t i = 0; i < kBucketCount; ++i) d.counts[i] = counts[i] - earlier.counts[i];
  return d;
}

}  // namespace facecap
