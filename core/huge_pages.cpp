#include "core/huge_pages.hpp"

#include <cstdint>
#include <sys/mman.h>

namespace facecap {
namespace {

std::size_t mapped_bytes(std::size_t bytes) noexcept { return (bytes + kHugePageBytes - 1) & ~(kHugePageBytes - 1); }

constexpr std::align_val_t kAlignment{64};

}  // namespace

void* allocate_huge(std::size_t bytes) {
  if (bytes < kHugeAllocationBytes) return ::operator new(bytes, kAlignment);
  const std::size_t size = mapped_bytes(bytes);
  // Map one huge page more than needed and trim both ends to a 2 MiB boundary.
  void* raw = mmap(nullptr, size + kHugePageBytes, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
  if (raw == MAP_FAILED) throw std::bad_alloc();
  const auto start = reinterpret_cast<std::uintptr_t>(raw);
  const std::uintptr_t aligned = (start + kHugePageBytes - 1) & ~std::uintptr_t(kHugePageBytes - 1);
  if (aligned > start) munmap(raw, aligned - start);
  const std::uintptr_t end = start + size + kHugePageBytes;
  if (end > aligned + size) munmap(reinterpret_cast<void*>(aligned + size), end - (aligned + size));
  // Advice only: a kernel without transparent huge pages keeps 4 KiB pages.
  madvise(reinterpret_cast<void*>(aligned), size, MADV_HUGEPAGE);
  return reinterpret_cast<void*>(aligned);
}

void free_huge(void* p, std::size_t bytes) noexcept {
  if (!p) return;
  if (bytes < kHugeAllocationBytes) {
    ::operator delete(p, kAlignment);
    return;
  }
  munmap(p, mapped_bytes(bytes));
}

}  // namespace facecap
