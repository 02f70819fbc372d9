#pragma once
// Hands an object built aside on one thread (the supervisor: a rebuilt solve pipeline) to
// a real-time thread, which adopts it between two frames, and hands the object it replaced
// back to be destroyed off the real-time thread. Owners hold unique_ptrs at both ends; in
// between the pointer travels through two atomics, so neither side ever waits or frees
// memory on the other's behalf.
#include <atomic>
#include <memory>

namespace facecap::rt {

template <typename T>
class Handoff {
 public:
  Handoff() = default;
  ~Handoff() {
    collect();
    delete offered_.exchange(nullptr, std::memory_order_acq_rel);
  }
  Handoff(const Handoff&) = delete;
  Handoff& operator=(const Handoff&) = delete;

  // Producer: offers `next` for adoption. An earlier offer not adopted yet is destroyed
  // here, as is anything the consumer retired. Not RT-safe (frees).
  void offer(std::unique_ptr<T> next) {
    collect();
    std::unique_ptr<T> superseded(offered_.exchange(next.release(), std::memory_order_acq_rel));
  }

  // Consumer: when an offer waits, moves it into `current` and retires the object it
  // replaces; returns whether it did. Waits for the producer to collect the previous
  // retiree first, so nothing is ever freed here. RT-safe.
  bool adopt(std::unique_ptr<T>& current) noexcept {
    if (!offered_.load(std::memory_order_relaxed)) return false;
    if (retired_.load(std::memory_order_acquire)) return false;
    T* next = offered_.exchange(nullptr, std::memory_order_acq_rel);
    if (!next) return false;
    retired_.store(current.release(), std::memory_order_release);
    current.reset(next);
    return true;
  }

  // Producer: destroys what the consumer retired. Not RT-safe (frees).
  void collect() { take_retired(); }
  // Producer: what the consumer retired, handed back rather than destroyed (empty when
  // nothing was). Not RT-safe.
  std::unique_ptr<T> take_retired() { return std::unique_ptr<T>(retired_.exchange(nullptr, std::memory_order_acq_rel)); }

  // Whether an offer is waiting to be adopted. Any thread.
  bool pending() const noexcept { return offered_.load(std::memory_order_acquire) != nullptr; }

 private:
  std::atomic<T*> offered_{nullptr};
  std::atomic<T*> retired_{nullptr};
};

}  // namespace facecap::rt
