#pragma once
// A latest-value mailbox: one producer thread hands its newest value to one consumer
// thread without locks or allocation (triple buffering). The producer never waits; a
// value the consumer did not take before the next one arrived is overwritten and counted.
#include <array>
#include <atomic>
#include <cstdint>

namespace facecap::rt {

template <typename T>
class LatestMailbox {
 public:
  // Every buffer starts as a copy of `prototype`, so values sized once at configure time
  // (reserved vectors, Eigen matrices) are reused and never reallocated.
  explicit LatestMailbox(const T& prototype = T{}) : buffers_{prototype, prototype, prototype} {}

  // Producer side: fill the buffer returned by write_buffer(), then publish(). RT-safe.
  T& write_buffer() noexcept { return buffers_[write_index_]; }
  void publish() noexcept {
    const uint32_t previous = middle_.exchange(write_index_ | kFresh, std::memory_order_acq_rel);
    if (previous & kFresh) overwritten_.fetch_add(1, std::memory_order_relaxed);
    write_index_ = previous & kIndexMask;
    published_.fetch_add(1, std::memory_order_relaxed);
  }

  // Consumer side: the newest published value not yet taken, or nullptr. The pointer
  // stays valid until the next take(). RT-safe.
  const T* take() noexcept {
    if (!(middle_.load(std::memory_order_relaxed) & kFresh)) return nullptr;
    const uint32_t previous = middle_.exchange(read_index_, std::memory_order_acq_rel);
    read_index_ = previous & kIndexMask;
    return &buffers_[read_index_];
  }

  uint64_t published() const noexcept { return published_.load(std::memory_order_relaxed); }
  uint64_t overwritten() const noexcept { return overwritten_.load(std::memory_order_relaxed); }

 private:
  static constexpr uint32_t kFresh = 4;
  static constexpr uint32_t kIndexMask = 3;
  std::array<T, 3> buffers_;
  uint32_t write_index_ = 0;              // owned by the producer
  uint32_t read_index_ = 1;               // owned by the consumer
  std::atomic<uint32_t> middle_{2};       // the buffer in between, plus the fresh bit
  std::atomic<uint64_t> published_{0};
  std::atomic<uint64_t> overwritten_{0};
};

}  // namespace facecap::rt
