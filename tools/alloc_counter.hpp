#pragma once
// Counts heap allocations made by any code in the facecap process (our own, libstdc++,
// Eigen, CHOLMOD, ...): alloc_counter.cpp replaces malloc, calloc, realloc and the
// aligned allocators in the facecap executable, forwarding to glibc's __libc_*
// functions. Counting is off until enabled, so only the code between enable and disable
// (the bench wraps each solve() in it) is counted. Every thread is counted.
#include <cstdint>

namespace facecap::tools {

void enable_allocation_counting() noexcept;
void disable_allocation_counting() noexcept;
// Allocations (malloc, calloc, realloc, memalign family) counted so far.
uint64_t counted_allocations() noexcept;

// Whether the replacement is really in use: makes one counted allocation and checks
// that it was seen. False when the process links the counter without interposing.
bool allocation_counter_works() noexcept;

}  // namespace facecap::tools
