#pragma once
// Counts heap allocations (malloc, calloc, realloc, aligned variants; C++ new goes
// through malloc) made by this thread while a CountAllocations scope is alive. Link
// tests/alloc_counter.cpp into a test executable to interpose the allocator.
#include <cstdint>

namespace facecap::test {

class CountAllocations {
 public:
  CountAllocations();
  ~CountAllocations();
  int64_t count() const;
};

}  // namespace facecap::test
