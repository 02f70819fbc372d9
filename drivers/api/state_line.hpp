#pragma once
// A source's state as one short line of text for an operator ("usb 1209:0001 SN1 lost 2.1 s
// ago, waiting for it to return"), shown in STATUS= and the log. The source's own thread
// writes it when its state changes; any thread reads it, including the solve thread through
// health(), so both sides are lock-free and allocation-free: a seqlock over relaxed atomic
// words, with real fences (a reader retries while a write is under way).
#include <array>
#include <atomic>
#include <cstdint>
#include <cstring>
#include <string_view>

namespace facecap::drivers {

// The line as a value: fixed capacity, so that copying it never allocates.
struct StateLine {
  static constexpr std::size_t kCapacity = 159;
  std::array<char, kCapacity + 1> text{};

  std::string_view view() const noexcept { return {text.data(), strnlen(text.data(), text.size())}; }
  bool empty() const noexcept { return text[0] == '\0'; }
};

class SharedStateLine {
 public:
  // Longer text is cut at the capacity. One writer at a time. RT-safe.
  void set(std::string_view line) noexcept {
    std::array<uint64_t, kWords> words{};
    std::memcpy(words.data(), line.data(), line.size() < StateLine::kCapacity ? line.size() : StateLine::kCapacity);
    const uint64_t seq = sequence_.load(std::memory_order_relaxed);
    sequence_.store(seq + 1, std::memory_order_relaxed);  // odd: a write is under way
    std::atomic_thread_fence(std::memory_order_release);
    for (std::size_t i = 0; i < kWords; ++i) words_[i].store(words[i], std::memory_order_relaxed);
    sequence_.store(seq + 2, std::memory_order_release);
  }

  // The last line set (empty when none, or when a writer kept it changing through every
  // retry). Any thread. RT-safe.
  StateLine get() const noexcept {
    std::array<uint64_t, kWords> words{};
    for (int attempt = 0; attempt < kMaxAttempts; ++attempt) {
      const uint64_t before = sequence_.load(std::memory_order_acquire);
      if (before & 1) continue;
      for (std::size_t i = 0; i < kWords; ++i) words[i] = words_[i].load(std::memory_order_relaxed);
      std::atomic_thread_fence(std::memory_order_acquire);
      if (sequence_.load(std::memory_order_relaxed) != before) continue;
      StateLine line;
      std::memcpy(line.text.data(), words.data(), StateLine::kCapacity);
      return line;
    }
    return {};
  }

 private:
  static constexpr std::size_t kWords = (StateLine::kCapacity + 1) / sizeof(uint64_t);
  static_assert(kWords * sizeof(uint64_t) == StateLine::kCapacity + 1);
  static constexpr int kMaxAttempts = 64;
  std::atomic<uint64_t> sequence_{0};
  std::array<std::atomic<uint64_t>, kWords> words_{};
};

}  // namespace facecap::drivers
