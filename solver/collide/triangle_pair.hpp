#pragma once
#include <compare>
#include <cstdint>

namespace facecap {

// Two triangles (indices into the rig's 3 x T triangle matrix), first < second.
struct TrianglePair {
  int32_t first = -1;
  int32_t second = -1;
  friend bool operator==(const TrianglePair&, const TrianglePair&) = default;
  friend auto operator<=>(const TrianglePair&, const TrianglePair&) = default;
};

}  // namespace facecap
