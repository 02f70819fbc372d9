#pragma once
// The SIMD lane vocabulary of the collider's BVH (solver/collide/bvh.hpp), in GCC's
// vector extensions: element-wise arithmetic and comparisons on fixed-width lanes,
// compiled for the build's baseline CPU (SSE4.2). The per-frame kernels that gain from
// wider registers live in solver/kernels/, compiled per instruction set. Everything here
// is real-time safe.
#include <cstdint>
#include <cstring>

#if defined(__SSE__)
#include <immintrin.h>
#endif

namespace facecap::simd {

// 16 floats, one AVX-512 register: a block's slots of one component, a BVH leaf's boxes,
// a batch of triangle pairs. Comparisons give MaskX16 lanes of all ones or zero.
using FloatX16 = float __attribute__((vector_size(64)));
using MaskX16 = int32_t __attribute__((vector_size(64)));
// 4 floats: a four-wide BVH node's child boxes.
using FloatX4 = float __attribute__((vector_size(16)));
using MaskX4 = int32_t __attribute__((vector_size(16)));
// 4 doubles: x, y, z and a pad lane of one vertex. Aligned to 8 only: Eigen may align
// the storage it points into to 16.
using DoubleX4 = double __attribute__((vector_size(32), aligned(8)));

inline constexpr int kFloatX16Lanes = 16;

// Bit i set where lane i of m is set.
inline uint32_t lane_bits(const MaskX16& m) noexcept {
#if defined(__AVX512F__)
  const __m512i lanes = reinterpret_cast<__m512i>(m);
  return uint32_t(_mm512_test_epi32_mask(lanes, lanes));
#elif defined(__SSE2__)
  __m128 quarter[4];
  std::memcpy(quarter, &m, sizeof quarter);
  return uint32_t(_mm_movemask_ps(quarter[0])) | uint32_t(_mm_movemask_ps(quarter[1])) << 4 |
         uint32_t(_mm_movemask_ps(quarter[2])) << 8 | uint32_t(_mm_movemask_ps(quarter[3])) << 12;
#else
  uint32_t bits = 0;
  for (int i = 0; i < kFloatX16Lanes; ++i) bits |= uint32_t(m[i] != 0) << i;
  return bits;
#endif
}

inline uint32_t lane_bits(MaskX4 m) noexcept {
#if defined(__SSE__)
  return uint32_t(_mm_movemask_ps(reinterpret_cast<__m128>(m)));
#else
  uint32_t bits = 0;
  for (int i = 0; i < 4; ++i) bits |= uint32_t(m[i] != 0) << i;
  return bits;
#endif
}

// Unaligned load and store of 16 lanes (V = FloatX16) or of one (V = float), so that
// one kernel body serves a whole vector of triangles and a single leftover one.
template <class V>
V load(const float* p) noexcept {
  V v;
  std::memcpy(&v, p, sizeof v);
  return v;
}
template <class V>
void store(float* p, V v) noexcept {
  std::memcpy(p, &v, sizeof v);
}

inline FloatX16 min(const FloatX16& a, const FloatX16& b) noexcept { return a < b ? a : b; }
inline FloatX16 max(const FloatX16& a, const FloatX16& b) noexcept { return a > b ? a : b; }

}  // namespace facecap::simd
