#pragma once
// Storage for the large read-only arrays the solver streams every frame (blend terms,
// the factor, pin columns). Allocations of 1 MiB or more are mapped on their own, in
// whole 2 MiB pages, and advised to the kernel's transparent huge pages before first touch:
// walking megabytes in 4 KiB pages costs a TLB miss per page, which under
// virtualisation is a two-level page walk. Smaller ones, and kernels without THP, get
// ordinary memory. Allocation is not real-time (it maps memory); reading is free.
#include <cstddef>
#include <new>
#include <vector>

namespace facecap {

inline constexpr std::size_t kHugePageBytes = std::size_t(2) << 20;
// Bytes from which allocate_huge() maps memory of its own.
inline constexpr std::size_t kHugeAllocationBytes = std::size_t(1) << 20;

// 64-byte aligned; throws std::bad_alloc. free_huge() needs the same byte count.
void* allocate_huge(std::size_t bytes);
void free_huge(void* p, std::size_t bytes) noexcept;

template <class T>
struct HugePageAllocator {
  using value_type = T;
  HugePageAllocator() noexcept = default;
  template <class U>
  HugePageAllocator(const HugePageAllocator<U>&) noexcept {}
  T* allocate(std::size_t n) { return static_cast<T*>(allocate_huge(n * sizeof(T))); }
  void deallocate(T* p, std::size_t n) noexcept { free_huge(p, n * sizeof(T)); }
  template <class U>
  friend bool operator==(const HugePageAllocator&, const HugePageAllocator<U>&) noexcept { return true; }
};

template <class T>
using HugePageVector = std::vector<T, HugePageAllocator<T>>;

}  // namespace facecap
