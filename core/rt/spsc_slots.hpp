#pragma once
// A bounded single-producer single-consumer queue of pre-constructed slots that are
// filled in place: the producer copies into storage sized at configure time (no
// allocation, no lock) and drops (and counts) when the consumer has fallen behind.
#include <atomic>
#include <cstdint>
#include <vector>

namespace facecap::rt {

template <typename T>
class SpscSlots {
 public:
  // capacity slots, each a copy of prototype. Not RT-safe.
  SpscSlots(std::size_t capacity, const T& prototype) : slots_(capacity, prototype) {}

  // Producer: a free slot to fill, or nullptr when full (the caller counts a drop). RT-safe.
  T* begin_push() noexcept {
    const uint64_t head = head_.load(std::memory_order_relaxed);
    if (head - tail_.load(std::memory_order_acquire) >= slots_.size()) return nullptr;
    return &slots_[head % slots_.size()];
  }
  // Producer: makes the slot from begin_push() visible to the consumer. RT-safe.
  void commit_push() noexcept { head_.store(head_.load(std::memory_order_relaxed) + 1, std::memory_order_release); }

  // Consumer: the oldest filled slot, or nullptr when empty.
  T* front() noexcept {
    const uint64_t tail = tail_.load(std::memory_order_relaxed);
    if (tail == head_.load(std::memory_order_acquire)) return nullptr;
    return &slots_[tail % slots_.size()];
  }
  // Consumer: hands the slot from front() back to the producer.
  void pop() noexcept { tail_.store(tail_.load(std::memory_order_relaxed) + 1, std::memory_order_release); }

  std::size_t capacity() const noexcept { return slots_.size(); }

 private:
  std::vector<T> slots_;
  alignas(64) std::atomic<uint64_t> head_{0};  // slots ever pushed
  alignas(64) std::atomic<uint64_t> tail_{0};  // slots ever popped
};

}  // namespace facecap::rt
