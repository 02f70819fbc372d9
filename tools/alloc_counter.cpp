// malloc replacement for the facecap executable (glibc's documented way: define malloc,
// free, calloc, realloc and the aligned allocators; other libraries' calls bind to
// these). Each forwards to glibc's own implementation and, while counting is enabled,
// bumps a relaxed atomic counter: nothing here allocates, locks or logs.
#include "tools/alloc_counter.hpp"

#include <atomic>
#include <cerrno>
#include <cstddef>
#include <new>

extern "C" {
void* __libc_malloc(std::size_t size);
void* __libc_calloc(std::size_t count, std::size_t size);
void* __libc_realloc(void* pointer, std::size_t size);
void* __libc_memalign(std::size_t alignment, std::size_t size);
void* __libc_valloc(std::size_t size);
void* __libc_pvalloc(std::size_t size);
void __libc_free(void* pointer);
}

namespace {

std::atomic<bool> counting{false};
std::atomic<uint64_t> allocations{0};

inline void count() noexcept {
  if (counting.load(std::memory_order_relaxed)) allocations.fetch_add(1, std::memory_order_relaxed);
}

}  // namespace

extern "C" {

void* malloc(std::size_t size) {
  count();
  return __libc_malloc(size);
}

void* calloc(std::size_t count_, std::size_t size) {
  count();
  return __libc_calloc(count_, size);
}

void* realloc(void* pointer, std::size_t size) {
  count();
  return __libc_realloc(pointer, size);
}

void free(void* pointer) { __libc_free(pointer); }

void* memalign(std::size_t alignment, std::size_t size) {
  count();
  return __libc_memalign(alignment, size);
}

void* aligned_alloc(std::size_t alignment, std::size_t size) {
  count();
  return __libc_memalign(alignment, size);
}

int posix_memalign(void** out, std::size_t alignment, std::size_t size) {
  if (alignment % sizeof(void*) != 0 || (alignment & (alignment - 1)) != 0) return EINVAL;
  count();
  void* p = __libc_memalign(alignment, size);
  if (!p && size != 0) return ENOMEM;
  *out = p;
  return 0;
}

void* valloc(std::size_t size) {
  count();
  return __libc_valloc(size);
}

void* pvalloc(std::size_t size) {
  count();
  return __libc_pvalloc(size);
}

}  // extern "C"

namespace facecap::tools {

void enable_allocation_counting() noexcept { counting.store(true, std::memory_order_relaxed); }
void disable_allocation_counting() noexcept { counting.store(false, std::memory_order_relaxed); }
uint64_t counted_allocations() noexcept { return allocations.load(std::memory_order_relaxed); }

bool allocation_counter_works() noexcept {
  const uint64_t before = counted_allocations();
  enable_allocation_counting();
  // libstdc++'s operator new calls malloc from another library: seeing it counted shows
  // the interposition works. Through a volatile pointer, so the pair cannot be elided.
  void* (*volatile allocate)(std::size_t) = static_cast<void* (*)(std::size_t)>(&::operator new);
  void* p = allocate(64);
  disable_allocation_counting();
  ::operator delete(p);
  return counted_allocations() > before;
}

}  // namespace facecap::tools
